//! A generic Modbus RTU server (slave) model, to test the generic layer against our own
//! server as well as third-party ones.
//!
//! It serves functions 1–6, 15 and 16 on the four tables of a [`SlaveMap`] (from a small
//! text file, or every address existing and zeroed), and refuses as a Modbus server does:
//! exception 1 for any other function, 3 for a count out of range, a byte count that does
//! not match the count, or a coil value other than 0xFF00/0x0000, 2 for an address that
//! does not exist (or a block past 0xFFFF). A frame with a bad CRC or for another unit
//! gets silence; a broadcast (unit 0) write is applied and not answered, a broadcast read
//! ignored.

pub mod map;

use std::time::{Duration, Instant};

use wire::Transmit;
use wire::device::Model;

pub use map::{MapError, MapProblem, SlaveMap, Table};

use crate::rtu::{
    DecodeError, EXCEPTION_BIT, ExceptionCode, FunctionCode, PackedBits, RegisterValues, Request,
    RequestAdu, RequestCodec, RequestPdu, Response, ResponseAdu, UnitId, WriteCoil, WriteRegister,
};

/// How long after a request the server's answer leaves, unless set otherwise: 2 ms.
pub const DEFAULT_REPLY_DELAY: Duration = Duration::from_millis(2);

/// What the server has done, for tests and the simulator's log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SlaveCounters {
    /// Requests answered normally.
    pub answered: u64,
    /// Requests answered with an exception.
    pub refused: u64,
    /// Broadcast writes applied.
    pub broadcasts: u64,
    /// Frames ignored: bad CRC, garbage, another unit, broadcast reads.
    pub ignored: u64,
}

/// A generic Modbus server.
#[derive(Debug, Clone)]
pub struct Slave {
    map: SlaveMap,
    reply_delay: Duration,
    counters: SlaveCounters,
}

impl Slave {
    /// A server with the unit and tables of `map`.
    pub fn new(map: SlaveMap) -> Self {
        Self {
            map,
            reply_delay: DEFAULT_REPLY_DELAY,
            counters: SlaveCounters::default(),
        }
    }

    /// A server on `unit` where every address of every table exists and holds 0.
    pub fn all_writable(unit: UnitId) -> Self {
        Self::new(SlaveMap::all_writable(unit))
    }

    /// The same server answering after `delay`.
    pub fn with_reply_delay(mut self, delay: Duration) -> Self {
        self.reply_delay = delay;
        self
    }

    /// The unit number it answers to.
    pub fn unit(&self) -> UnitId {
        self.map.unit
    }

    /// The map, with the current values.
    pub fn map(&self) -> &SlaveMap {
        &self.map
    }

    /// What it has done so far.
    pub fn counters(&self) -> SlaveCounters {
        self.counters
    }

    /// The value at `address` of `table` (bits as 0 or 1), if the address exists.
    pub fn get(&self, table: Table, address: u16) -> Option<u16> {
        self.map.get(table, address)
    }

    /// Sets the value at `address` of `table` (bits: any non-zero value is 1), as the
    /// device's own process would, read-only tables included. False if the address does
    /// not exist.
    pub fn set(&mut self, table: Table, address: u16, value: u16) -> bool {
        let value = if table.holds_bits() {
            u16::from(value != 0)
        } else {
            value
        };
        self.map.tables[table.index()].set(address, value)
    }

    /// The answer to a request addressed to this unit, or `None` for silence (a function
    /// byte with the exception bit set has no valid answer).
    pub fn answer(&mut self, pdu: &RequestPdu) -> Option<Response> {
        let function = pdu.function_byte();
        if function & EXCEPTION_BIT != 0 {
            return None;
        }
        let result = pdu.to_request().and_then(|request| self.execute(&request));
        Some(
            result.unwrap_or_else(|code| {
                Response::exception(FunctionCode::of_exception(function), code)
            }),
        )
    }

    /// Applies a broadcast request: a valid write is done; anything else is ignored.
    /// True if something was written.
    pub fn apply_broadcast(&mut self, pdu: &RequestPdu) -> bool {
        match pdu.to_request() {
            Ok(request) if !request.is_read() => self.execute(&request).is_ok(),
            _ => false,
        }
    }

    fn execute(&mut self, request: &Request) -> Result<Response, ExceptionCode> {
        match request {
            Request::ReadCoils(r) | Request::ReadDiscreteInputs(r) => {
                let table = if matches!(request, Request::ReadCoils(_)) {
                    Table::Coils
                } else {
                    Table::DiscreteInputs
                };
                let bits: Vec<bool> = self
                    .read(table, r.address(), r.count().get())?
                    .into_iter()
                    .map(|v| v != 0)
                    .collect();
                let packed = PackedBits::from_bits(&bits)
                    .map_err(|_| ExceptionCode::SERVER_DEVICE_FAILURE)?;
                Ok(if table == Table::Coils {
                    Response::ReadCoils(packed)
                } else {
                    Response::ReadDiscreteInputs(packed)
                })
            }
            Request::ReadHoldingRegisters(r) | Request::ReadInputRegisters(r) => {
                let holding = matches!(request, Request::ReadHoldingRegisters(_));
                let table = if holding {
                    Table::HoldingRegisters
                } else {
                    Table::InputRegisters
                };
                let values = RegisterValues::new(self.read(table, r.address(), r.count().get())?)
                    .map_err(|_| ExceptionCode::SERVER_DEVICE_FAILURE)?;
                Ok(if holding {
                    Response::ReadHoldingRegisters(values)
                } else {
                    Response::ReadInputRegisters(values)
                })
            }
            &Request::WriteSingleCoil(WriteCoil { address, value }) => {
                self.write(Table::Coils, address, &[u16::from(value)])?;
                Ok(Response::WriteSingleCoil(WriteCoil { address, value }))
            }
            &Request::WriteSingleRegister(WriteRegister { address, value }) => {
                self.write(Table::HoldingRegisters, address, &[value])?;
                Ok(Response::WriteSingleRegister(WriteRegister {
                    address,
                    value,
                }))
            }
            Request::WriteMultipleCoils(w) => {
                let values: Vec<u16> = w.values().iter().map(|&b| u16::from(b)).collect();
                self.write(Table::Coils, w.address(), &values)?;
                Ok(Response::WriteMultipleCoils {
                    address: w.address(),
                    count: w.count().get(),
                })
            }
            Request::WriteMultipleRegisters(w) => {
                self.write(Table::HoldingRegisters, w.address(), w.values())?;
                Ok(Response::WriteMultipleRegisters {
                    address: w.address(),
                    count: w.count().get(),
                })
            }
        }
    }

    fn read(&self, table: Table, address: u16, count: u16) -> Result<Vec<u16>, ExceptionCode> {
        let data = &self.map.tables[table.index()];
        if !data.block_exists(address, count.into()) {
            return Err(ExceptionCode::ILLEGAL_DATA_ADDRESS);
        }
        (0..count)
            .map(|i| {
                address
                    .checked_add(i)
                    .and_then(|a| data.get(a))
                    .ok_or(ExceptionCode::ILLEGAL_DATA_ADDRESS)
            })
            .collect()
    }

    /// Writes all of `values` from `address`, or nothing if one address does not exist.
    fn write(&mut self, table: Table, address: u16, values: &[u16]) -> Result<(), ExceptionCode> {
        let data = &mut self.map.tables[table.index()];
        if !data.block_exists(address, values.len()) {
            return Err(ExceptionCode::ILLEGAL_DATA_ADDRESS);
        }
        for (a, &value) in (address..=u16::MAX).zip(values) {
            data.set(a, value);
        }
        Ok(())
    }
}

impl Model for Slave {
    type Codec = RequestCodec;

    fn codec(&self) -> RequestCodec {
        RequestCodec
    }

    fn handle(&mut self, input: Result<RequestAdu, DecodeError>, _now: Instant) -> Vec<Transmit> {
        let Ok(adu) = input else {
            self.counters.ignored += 1;
            return Vec::new();
        };
        if adu.is_broadcast() {
            if self.apply_broadcast(&adu.pdu) {
                self.counters.broadcasts += 1;
            } else {
                self.counters.ignored += 1;
            }
            return Vec::new();
        }
        if adu.unit != self.unit().get() {
            self.counters.ignored += 1;
            return Vec::new();
        }
        let Some(response) = self.answer(&adu.pdu) else {
            self.counters.ignored += 1;
            return Vec::new();
        };
        if matches!(response, Response::Exception(_)) {
            self.counters.refused += 1;
        } else {
            self.counters.answered += 1;
        }
        reply(adu.unit, response, self.reply_delay)
    }
}

/// A device model's one transmission: `response` from `unit`, sent `delay` after the
/// request.
pub(crate) fn reply(unit: u8, response: Response, delay: Duration) -> Vec<Transmit> {
    vec![Transmit::after(
        delay,
        ResponseAdu { unit, response }.to_bytes(),
    )]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtu::codec::{append_crc, decode_response};
    use crate::rtu::{Addressed, Answer, Broadcast, Exception, Write, check_response};
    use wire::Codec;

    const MAP: &str = "unit 9\n\
                       holding 0 = 10 11 12 13\n\
                       input 0x100 = 500 501\n\
                       coil 20 = 1 0 1 1 0 0 1 1 1 0\n\
                       discrete 0 = 0 1 1\n";

    fn slave() -> Slave {
        Slave::new(SlaveMap::parse(MAP).expect("test map"))
    }

    fn unit9() -> UnitId {
        UnitId::new(9).expect("9")
    }

    fn frame_to(slave: &mut Slave, bytes: &[u8]) -> Vec<Transmit> {
        let input = match RequestCodec.decode(bytes) {
            Ok(Some((adu, _))) => Ok(adu),
            Ok(None) => panic!("incomplete {bytes:02X?}"),
            Err(e) => Err(e),
        };
        slave.handle(input, Instant::now())
    }

    fn call(slave: &mut Slave, request: Request) -> Answer {
        let addressed = Addressed::new(unit9(), request);
        let mut out = frame_to(slave, &addressed.to_adu().to_bytes());
        assert_eq!(out.len(), 1, "one answer to {addressed}");
        let tx = out.remove(0);
        assert_eq!(tx.delay, DEFAULT_REPLY_DELAY);
        let (response, _) = decode_response(&tx.bytes)
            .expect("valid frame")
            .expect("whole frame");
        check_response(&addressed, &response).expect("the answer matches the request")
    }

    fn refused(code: ExceptionCode, function: FunctionCode) -> Answer {
        Answer::Exception(Exception { function, code })
    }

    #[test]
    fn reads_every_table() {
        let mut s = slave();
        assert_eq!(
            call(
                &mut s,
                Request::read_holding_registers(1, 3).expect("valid")
            ),
            Answer::Registers(vec![11, 12, 13])
        );
        assert_eq!(
            call(
                &mut s,
                Request::read_input_registers(0x100, 2).expect("valid")
            ),
            Answer::Registers(vec![500, 501])
        );
        assert_eq!(
            call(&mut s, Request::read_coils(20, 10).expect("valid")),
            Answer::Bits(vec![
                true, false, true, true, false, false, true, true, true, false
            ])
        );
        assert_eq!(
            call(&mut s, Request::read_discrete_inputs(0, 3).expect("valid")),
            Answer::Bits(vec![false, true, true])
        );
    }

    #[test]
    fn writes_change_what_reads_return() {
        let mut s = slave();
        assert_eq!(
            call(&mut s, Request::write_single_register(2, 0xBEEF)),
            Answer::Written
        );
        assert_eq!(
            call(
                &mut s,
                Request::write_multiple_registers(0, vec![7, 8]).expect("valid")
            ),
            Answer::Written
        );
        assert_eq!(
            call(
                &mut s,
                Request::read_holding_registers(0, 4).expect("valid")
            ),
            Answer::Registers(vec![7, 8, 0xBEEF, 13])
        );
        assert_eq!(
            call(&mut s, Request::write_single_coil(21, true)),
            Answer::Written
        );
        assert_eq!(
            call(
                &mut s,
                Request::write_multiple_coils(27, vec![false, false, true]).expect("valid")
            ),
            Answer::Written
        );
        assert_eq!(
            call(&mut s, Request::read_coils(20, 10).expect("valid")),
            Answer::Bits(vec![
                true, true, true, true, false, false, true, false, false, true
            ])
        );
        assert_eq!(s.counters().answered, 6);
    }

    #[test]
    fn unmapped_addresses_get_exception_2_and_nothing_is_written() {
        let mut s = slave();
        let address = ExceptionCode::ILLEGAL_DATA_ADDRESS;
        assert_eq!(
            call(
                &mut s,
                Request::read_holding_registers(2, 3).expect("valid")
            ),
            refused(address, FunctionCode::READ_HOLDING_REGISTERS)
        );
        assert_eq!(
            call(&mut s, Request::read_input_registers(0, 1).expect("valid")),
            refused(address, FunctionCode::READ_INPUT_REGISTERS)
        );
        assert_eq!(
            call(&mut s, Request::read_coils(25, 6).expect("valid")),
            refused(address, FunctionCode::READ_COILS)
        );
        assert_eq!(
            call(&mut s, Request::read_discrete_inputs(3, 1).expect("valid")),
            refused(address, FunctionCode::READ_DISCRETE_INPUTS)
        );
        assert_eq!(
            call(&mut s, Request::write_single_coil(30, true)),
            refused(address, FunctionCode::WRITE_SINGLE_COIL)
        );
        assert_eq!(
            call(&mut s, Request::write_single_register(4, 1)),
            refused(address, FunctionCode::WRITE_SINGLE_REGISTER)
        );
        assert_eq!(
            call(
                &mut s,
                Request::write_multiple_registers(3, vec![1, 2]).expect("valid")
            ),
            refused(address, FunctionCode::WRITE_MULTIPLE_REGISTERS)
        );
        assert_eq!(
            s.get(Table::HoldingRegisters, 3),
            Some(13),
            "a refused write changes nothing"
        );
        assert_eq!(
            call(
                &mut s,
                Request::write_multiple_coils(28, vec![false; 3]).expect("valid")
            ),
            refused(address, FunctionCode::WRITE_MULTIPLE_COILS)
        );
        assert_eq!(s.get(Table::Coils, 28), Some(1));
        assert_eq!(s.counters().refused, 8);
    }

    /// The response `s` sends to `frame` (unit, function and data) with its CRC appended.
    fn answer_to(s: &mut Slave, frame: &[u8]) -> Response {
        let mut bytes = frame.to_vec();
        append_crc(&mut bytes, 0);
        let out = frame_to(s, &bytes);
        let (adu, _) = decode_response(&out[0].bytes)
            .expect("valid")
            .expect("whole");
        adu.response
    }

    #[test]
    fn bad_counts_and_values_get_exception_3() {
        let mut s = Slave::all_writable(unit9());
        for (frame, function) in [
            (vec![9, 3, 0, 0, 0, 0], 3),
            (vec![9, 4, 0, 0, 0, 126], 4),
            (vec![9, 1, 0, 0, 0x07, 0xD1], 1),
            (vec![9, 2, 0, 0, 0, 0], 2),
            (vec![9, 5, 0, 0, 0x12, 0x34], 5),
            (vec![9, 15, 0, 0, 0, 9, 1, 0xFF], 15),
            (vec![9, 16, 0, 0, 0, 2, 2, 0, 1], 16),
            (vec![9, 16, 0, 0, 0, 124, 0], 16),
        ] {
            assert_eq!(
                answer_to(&mut s, &frame),
                Response::exception(
                    FunctionCode::new(function).expect("fn"),
                    ExceptionCode::ILLEGAL_DATA_VALUE
                ),
                "{frame:02X?}"
            );
        }
    }

    #[test]
    fn other_functions_get_exception_1() {
        let mut s = Slave::all_writable(unit9());
        for frame in [
            vec![9, 7],
            vec![9, 8, 0, 0, 0x12, 0x34],
            vec![9, 22, 0, 1, 0, 2, 0, 3],
            vec![9, 0x41, 1, 2],
        ] {
            assert_eq!(
                answer_to(&mut s, &frame),
                Response::exception(
                    FunctionCode::new(frame[1]).expect("fn"),
                    ExceptionCode::ILLEGAL_FUNCTION
                )
            );
        }
    }

    #[test]
    fn bad_crc_and_other_units_get_silence() {
        let mut s = slave();
        let mut bytes = Addressed::new(
            unit9(),
            Request::read_holding_registers(0, 1).expect("valid"),
        )
        .to_adu()
        .to_bytes();
        bytes[2] ^= 0x80;
        assert!(frame_to(&mut s, &bytes).is_empty());
        let other = Addressed::new(
            UnitId::new(10).expect("10"),
            Request::read_holding_registers(0, 1).expect("valid"),
        );
        assert!(frame_to(&mut s, &other.to_adu().to_bytes()).is_empty());
        assert_eq!(s.counters().ignored, 2);
    }

    #[test]
    fn broadcast_writes_are_applied_without_an_answer() {
        let mut s = slave();
        let write = Broadcast(Write::MultipleRegisters(
            crate::rtu::WriteRegisters::new(0, vec![1, 2]).expect("valid"),
        ));
        assert!(frame_to(&mut s, &write.to_adu().to_bytes()).is_empty());
        assert_eq!(s.get(Table::HoldingRegisters, 1), Some(2));
        let coil = Broadcast(Write::SingleCoil(WriteCoil {
            address: 21,
            value: true,
        }));
        assert!(frame_to(&mut s, &coil.to_adu().to_bytes()).is_empty());
        assert_eq!(s.get(Table::Coils, 21), Some(1));
        let mut read = vec![0, 3, 0, 0, 0, 1];
        append_crc(&mut read, 0);
        assert!(frame_to(&mut s, &read).is_empty());
        assert_eq!(s.counters().broadcasts, 2);
        assert_eq!(s.counters().ignored, 1);
    }

    #[test]
    fn all_writable_server_reaches_the_last_address() {
        let mut s = Slave::all_writable(unit9()).with_reply_delay(Duration::ZERO);
        assert!(s.set(Table::InputRegisters, 0xFFFF, 42));
        let addressed = Addressed::new(
            unit9(),
            Request::read_input_registers(0xFFFF, 1).expect("valid"),
        );
        let out = frame_to(&mut s, &addressed.to_adu().to_bytes());
        assert_eq!(out[0].delay, Duration::ZERO);
        let (response, _) = decode_response(&out[0].bytes)
            .expect("valid")
            .expect("whole");
        assert_eq!(
            check_response(&addressed, &response),
            Ok(Answer::Registers(vec![42]))
        );
    }

    #[test]
    fn set_refuses_unmapped_addresses_and_clamps_bits() {
        let mut s = slave();
        assert!(!s.set(Table::HoldingRegisters, 100, 1));
        assert!(s.set(Table::DiscreteInputs, 0, 7));
        assert_eq!(s.get(Table::DiscreteInputs, 0), Some(1));
    }
}
