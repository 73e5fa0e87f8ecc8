//! One request, one answer: whether a decoded response answers the request in flight.
//!
//! A response is accepted only if its unit, function and count (for reads) or echo (for
//! writes) match the request; an exception response for the request's function is the
//! device's answer, not a mismatch. A client that gets a [`Mismatch`] keeps waiting (the
//! frame was meant for someone else, or is a late answer to an earlier request) or
//! retries; it does not hand the frame to its caller.

use std::fmt;

use super::request::{Addressed, Request, packed_len};
use super::response::{Response, ResponseAdu};
use super::value::{Exception, FunctionCode};

/// What the device answered to a request.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Answer {
    /// The bits read (functions 1 and 2), exactly as many as asked.
    Bits(Vec<bool>),
    /// The registers read (functions 3 and 4), exactly as many as asked.
    Registers(Vec<u16>),
    /// The write was done (functions 5, 6, 15 and 16; the echo matched).
    Written,
    /// The device refused the request.
    Exception(Exception),
}

impl fmt::Display for Answer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bits(bits) => {
                let text: Vec<&str> = bits.iter().map(|&b| if b { "1" } else { "0" }).collect();
                write!(f, "{}", text.join(" "))
            }
            Self::Registers(values) => {
                let text: Vec<String> = values.iter().map(u16::to_string).collect();
                write!(f, "{}", text.join(" "))
            }
            Self::Written => write!(f, "written"),
            Self::Exception(e) => write!(f, "{e}"),
        }
    }
}

/// Which field of a write's echo differs from the request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EchoField {
    /// The first address.
    Address,
    /// The value written (functions 5 and 6).
    Value,
    /// The number of items written (functions 15 and 16).
    Count,
}

impl fmt::Display for EchoField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Address => "address",
            Self::Value => "value",
            Self::Count => "count",
        })
    }
}

/// Why a well-formed response does not answer the request in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Mismatch {
    /// Another unit answered.
    #[error("the answer comes from unit {actual}, but unit {expected} was asked")]
    UnitId {
        /// The unit asked.
        expected: u8,
        /// The unit in the answer.
        actual: u8,
    },
    /// The answer is for another function.
    #[error("the answer is for function {actual}, but the request was function {expected}")]
    Function {
        /// The request's function.
        expected: FunctionCode,
        /// The answer's function.
        actual: FunctionCode,
    },
    /// A read returned another number of registers or bytes of bits than asked.
    #[error("the answer carries {actual} {what}, but the request asked for {expected}")]
    Count {
        /// "registers" or "bytes of bits".
        what: &'static str,
        /// How many the request implies.
        expected: usize,
        /// How many came.
        actual: usize,
    },
    /// A write's echo differs from the request.
    #[error("the echo's {field} is {actual}, but the request's was {expected}")]
    Echo {
        /// The field that differs.
        field: EchoField,
        /// The request's value.
        expected: u16,
        /// The echo's value.
        actual: u16,
    },
}

/// Checks that `response` answers `request` and gives the answer.
pub fn check_response(request: &Addressed, response: &ResponseAdu) -> Result<Answer, Mismatch> {
    let expected_unit = request.unit.get();
    if response.unit != expected_unit {
        return Err(Mismatch::UnitId {
            expected: expected_unit,
            actual: response.unit,
        });
    }
    let request = &request.request;
    let (expected, actual) = (request.function(), response.response.function());
    if expected != actual {
        return Err(Mismatch::Function { expected, actual });
    }
    let echo = |field, expected: u16, actual: u16| {
        if expected == actual {
            Ok(())
        } else {
            Err(Mismatch::Echo {
                field,
                expected,
                actual,
            })
        }
    };
    match (request, &response.response) {
        (_, Response::Exception(e)) => Ok(Answer::Exception(*e)),
        (Request::ReadCoils(r), Response::ReadCoils(bits))
        | (Request::ReadDiscreteInputs(r), Response::ReadDiscreteInputs(bits)) => {
            let count = usize::from(r.count().get());
            let (expected, actual) = (packed_len(count), bits.as_bytes().len());
            if expected != actual {
                return Err(Mismatch::Count {
                    what: "bytes of bits",
                    expected,
                    actual,
                });
            }
            Ok(Answer::Bits(bits.bits(count)))
        }
        (Request::ReadHoldingRegisters(r), Response::ReadHoldingRegisters(values))
        | (Request::ReadInputRegisters(r), Response::ReadInputRegisters(values)) => {
            let (expected, actual) = (usize::from(r.count().get()), values.values().len());
            if expected != actual {
                return Err(Mismatch::Count {
                    what: "registers",
                    expected,
                    actual,
                });
            }
            Ok(Answer::Registers(values.values().to_vec()))
        }
        (Request::WriteSingleCoil(w), Response::WriteSingleCoil(e)) => {
            echo(EchoField::Address, w.address, e.address)?;
            echo(EchoField::Value, coil_word(w.value), coil_word(e.value))?;
            Ok(Answer::Written)
        }
        (Request::WriteSingleRegister(w), Response::WriteSingleRegister(e)) => {
            echo(EchoField::Address, w.address, e.address)?;
            echo(EchoField::Value, w.value, e.value)?;
            Ok(Answer::Written)
        }
        (Request::WriteMultipleCoils(w), Response::WriteMultipleCoils { address, count }) => {
            echo(EchoField::Address, w.address(), *address)?;
            echo(EchoField::Count, w.count().get(), *count)?;
            Ok(Answer::Written)
        }
        (
            Request::WriteMultipleRegisters(w),
            Response::WriteMultipleRegisters { address, count },
        ) => {
            echo(EchoField::Address, w.address(), *address)?;
            echo(EchoField::Count, w.count().get(), *count)?;
            Ok(Answer::Written)
        }
        // Same function code means same variant; this arm is not reached.
        _ => Err(Mismatch::Function { expected, actual }),
    }
}

fn coil_word(on: bool) -> u16 {
    if on { super::COIL_ON } else { super::COIL_OFF }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtu::{ExceptionCode, PackedBits, RegisterValues, UnitId, WriteCoil, WriteRegister};

    fn ask(unit: u8, request: Request) -> Addressed {
        Addressed::new(UnitId::new(unit).expect("test unit"), request)
    }

    fn answer(unit: u8, response: Response) -> ResponseAdu {
        ResponseAdu { unit, response }
    }

    fn registers(values: &[u16]) -> Response {
        Response::ReadHoldingRegisters(RegisterValues::new(values.to_vec()).expect("test values"))
    }

    #[test]
    fn matching_read_gives_the_registers() {
        let request = ask(2, Request::read_holding_registers(0x46, 3).expect("valid"));
        assert_eq!(
            check_response(&request, &answer(2, registers(&[1, 2, 3]))),
            Ok(Answer::Registers(vec![1, 2, 3]))
        );
    }

    #[test]
    fn answer_from_another_unit_is_a_mismatch() {
        let request = ask(2, Request::read_holding_registers(0x46, 3).expect("valid"));
        assert_eq!(
            check_response(&request, &answer(3, registers(&[1, 2, 3]))),
            Err(Mismatch::UnitId {
                expected: 2,
                actual: 3
            })
        );
    }

    #[test]
    fn answer_for_another_function_is_a_mismatch() {
        let request = ask(2, Request::read_holding_registers(0x46, 3).expect("valid"));
        let input = Response::ReadInputRegisters(RegisterValues::new(vec![1, 2, 3]).expect("3"));
        assert_eq!(
            check_response(&request, &answer(2, input)),
            Err(Mismatch::Function {
                expected: FunctionCode::READ_HOLDING_REGISTERS,
                actual: FunctionCode::READ_INPUT_REGISTERS
            })
        );
    }

    #[test]
    fn read_returning_another_count_is_a_mismatch() {
        let request = ask(2, Request::read_holding_registers(0x46, 3).expect("valid"));
        assert_eq!(
            check_response(&request, &answer(2, registers(&[1, 2]))),
            Err(Mismatch::Count {
                what: "registers",
                expected: 3,
                actual: 2
            })
        );
        let coils = ask(2, Request::read_coils(0, 9).expect("valid"));
        let one_byte = Response::ReadCoils(PackedBits::from_bytes(vec![0xFF]).expect("1 byte"));
        assert_eq!(
            check_response(&coils, &answer(2, one_byte)),
            Err(Mismatch::Count {
                what: "bytes of bits",
                expected: 2,
                actual: 1
            })
        );
    }

    #[test]
    fn bits_read_are_cut_to_the_count_asked() {
        let coils = ask(1, Request::read_coils(0, 10).expect("valid"));
        let bytes = Response::ReadCoils(PackedBits::from_bytes(vec![0xCD, 0xFF]).expect("2 bytes"));
        assert_eq!(
            check_response(&coils, &answer(1, bytes)),
            Ok(Answer::Bits(vec![
                true, false, true, true, false, false, true, true, true, true
            ]))
        );
    }

    #[test]
    fn exception_for_the_requests_function_is_an_answer() {
        let request = ask(2, Request::read_holding_registers(0x12, 2).expect("valid"));
        let refusal = Response::exception(
            FunctionCode::READ_HOLDING_REGISTERS,
            ExceptionCode::ILLEGAL_DATA_ADDRESS,
        );
        assert_eq!(
            check_response(&request, &answer(2, refusal)),
            Ok(Answer::Exception(Exception {
                function: FunctionCode::READ_HOLDING_REGISTERS,
                code: ExceptionCode::ILLEGAL_DATA_ADDRESS
            }))
        );
    }

    #[test]
    fn exception_for_another_function_is_a_mismatch() {
        let request = ask(2, Request::read_holding_registers(0x12, 2).expect("valid"));
        let refusal =
            Response::exception(FunctionCode::READ_COILS, ExceptionCode::ILLEGAL_FUNCTION);
        assert!(matches!(
            check_response(&request, &answer(2, refusal)),
            Err(Mismatch::Function { .. })
        ));
    }

    #[test]
    fn write_echo_must_repeat_address_value_and_count() {
        let request = ask(1, Request::write_single_register(5, 77));
        let good = Response::WriteSingleRegister(WriteRegister {
            address: 5,
            value: 77,
        });
        assert_eq!(
            check_response(&request, &answer(1, good)),
            Ok(Answer::Written)
        );
        let bad = Response::WriteSingleRegister(WriteRegister {
            address: 5,
            value: 78,
        });
        assert_eq!(
            check_response(&request, &answer(1, bad)),
            Err(Mismatch::Echo {
                field: EchoField::Value,
                expected: 77,
                actual: 78
            })
        );
        let coil = ask(1, Request::write_single_coil(9, true));
        let wrong_address = Response::WriteSingleCoil(WriteCoil {
            address: 8,
            value: true,
        });
        assert_eq!(
            check_response(&coil, &answer(1, wrong_address)),
            Err(Mismatch::Echo {
                field: EchoField::Address,
                expected: 9,
                actual: 8
            })
        );
        let many = ask(
            1,
            Request::write_multiple_registers(100, vec![1, 2, 3]).expect("valid"),
        );
        let wrote = |count| {
            answer(
                1,
                Response::WriteMultipleRegisters {
                    address: 100,
                    count,
                },
            )
        };
        assert_eq!(check_response(&many, &wrote(3)), Ok(Answer::Written));
        assert_eq!(
            check_response(&many, &wrote(2)),
            Err(Mismatch::Echo {
                field: EchoField::Count,
                expected: 3,
                actual: 2
            })
        );
        let coils = ask(
            1,
            Request::write_multiple_coils(3, vec![true; 10]).expect("valid"),
        );
        assert_eq!(
            check_response(
                &coils,
                &answer(
                    1,
                    Response::WriteMultipleCoils {
                        address: 4,
                        count: 10
                    }
                )
            ),
            Err(Mismatch::Echo {
                field: EchoField::Address,
                expected: 3,
                actual: 4
            })
        );
    }
}
