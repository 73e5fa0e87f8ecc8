//! Responses: what a server sends and a client decodes. Every value here is valid Modbus
//! (a read returns 1–125 registers or 1–250 bytes of bits; an exception has a code 1–255),
//! so whether it answers a given request is the only question left ([`check_response`]).
//!
//! [`check_response`]: super::check_response

use std::fmt;

use super::request::{WriteCoil, WriteRegister, pack_bits, show_span, unpack_bits};
use super::value::{Exception, ExceptionCode, FunctionCode, InvalidValue};

/// The bits a read of coils or discrete inputs returns, 8 per byte, first bit in the
/// lowest bit of the first byte: 1–250 bytes (up to 2000 bits).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct PackedBits(Vec<u8>);

impl PackedBits {
    /// The most bytes (2000 bits).
    pub const MAX_BYTES: usize = 250;

    /// Bytes as the wire carries them.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self, InvalidValue> {
        if bytes.is_empty() || bytes.len() > Self::MAX_BYTES {
            return Err(InvalidValue::out_of_range(
                "byte count of bits",
                bytes.len(),
                1,
                Self::MAX_BYTES as u32,
            ));
        }
        Ok(Self(bytes))
    }

    /// Packs 1–2000 bits.
    pub fn from_bits(bits: &[bool]) -> Result<Self, InvalidValue> {
        if bits.is_empty() || bits.len() > 8 * Self::MAX_BYTES {
            return Err(InvalidValue::out_of_range("bit count", bits.len(), 1, 2000));
        }
        Ok(Self(pack_bits(bits)))
    }

    /// The bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }

    /// The first `count` bits (the response does not say how many of the last byte's
    /// bits count: the request does).
    pub fn bits(&self, count: usize) -> Vec<bool> {
        unpack_bits(&self.0, count)
    }

    /// The byte count as the frame carries it.
    pub fn byte_count(&self) -> u8 {
        u8::try_from(self.0.len()).expect("at most 250 bytes")
    }
}

/// The registers a read returns: 1–125 of them.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RegisterValues(Vec<u16>);

impl RegisterValues {
    /// The most registers one response carries.
    pub const MAX: usize = 125;

    /// 1–125 register values.
    pub fn new(values: Vec<u16>) -> Result<Self, InvalidValue> {
        if values.is_empty() || values.len() > Self::MAX {
            return Err(InvalidValue::out_of_range(
                "register count",
                values.len(),
                1,
                Self::MAX as u32,
            ));
        }
        Ok(Self(values))
    }

    /// The values, first address first.
    pub fn values(&self) -> &[u16] {
        &self.0
    }

    /// The values, owned.
    pub fn into_values(self) -> Vec<u16> {
        self.0
    }

    /// The byte count as the frame carries it.
    pub fn byte_count(&self) -> u8 {
        u8::try_from(2 * self.0.len()).expect("at most 125 registers take 250 bytes")
    }
}

/// A response, one variant per function, or an exception.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Response {
    /// Function 1: coil values.
    ReadCoils(PackedBits),
    /// Function 2: discrete input values.
    ReadDiscreteInputs(PackedBits),
    /// Function 3: holding register values.
    ReadHoldingRegisters(RegisterValues),
    /// Function 4: input register values.
    ReadInputRegisters(RegisterValues),
    /// Function 5: the echo of the write.
    WriteSingleCoil(WriteCoil),
    /// Function 6: the echo of the write.
    WriteSingleRegister(WriteRegister),
    /// Function 15: the first address and the number of coils written.
    WriteMultipleCoils {
        /// First address written.
        address: u16,
        /// Number of coils written.
        count: u16,
    },
    /// Function 16: the first address and the number of registers written.
    WriteMultipleRegisters {
        /// First address written.
        address: u16,
        /// Number of registers written.
        count: u16,
    },
    /// The device refused the request.
    Exception(Exception),
}

impl Response {
    /// The function the response answers (for an exception: the refused function).
    pub fn function(&self) -> FunctionCode {
        match self {
            Self::ReadCoils(_) => FunctionCode::READ_COILS,
            Self::ReadDiscreteInputs(_) => FunctionCode::READ_DISCRETE_INPUTS,
            Self::ReadHoldingRegisters(_) => FunctionCode::READ_HOLDING_REGISTERS,
            Self::ReadInputRegisters(_) => FunctionCode::READ_INPUT_REGISTERS,
            Self::WriteSingleCoil(_) => FunctionCode::WRITE_SINGLE_COIL,
            Self::WriteSingleRegister(_) => FunctionCode::WRITE_SINGLE_REGISTER,
            Self::WriteMultipleCoils { .. } => FunctionCode::WRITE_MULTIPLE_COILS,
            Self::WriteMultipleRegisters { .. } => FunctionCode::WRITE_MULTIPLE_REGISTERS,
            Self::Exception(e) => e.function,
        }
    }

    /// An exception response refusing `function` with `code`.
    pub fn exception(function: FunctionCode, code: ExceptionCode) -> Self {
        Self::Exception(Exception { function, code })
    }
}

impl fmt::Display for Response {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ReadCoils(bits) => write!(f, "coils: {} bytes {:02X?}", bits.0.len(), bits.0),
            Self::ReadDiscreteInputs(bits) => {
                write!(f, "discrete inputs: {} bytes {:02X?}", bits.0.len(), bits.0)
            }
            Self::ReadHoldingRegisters(r) => write!(f, "holding registers: {:?}", r.0),
            Self::ReadInputRegisters(r) => write!(f, "input registers: {:?}", r.0),
            Self::WriteSingleCoil(w) => w.show(f, "wrote"),
            Self::WriteSingleRegister(w) => w.show(f, "wrote"),
            Self::WriteMultipleCoils { address, count } => {
                show_span(f, "wrote", (*count).into(), "coils", *address)
            }
            Self::WriteMultipleRegisters { address, count } => {
                show_span(f, "wrote", (*count).into(), "registers", *address)
            }
            Self::Exception(e) => write!(f, "{e}"),
        }
    }
}

/// A response frame: the answering unit's number and the response.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ResponseAdu {
    /// The unit number the device put in its answer.
    pub unit: u8,
    /// The response.
    pub response: Response,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_bits_hold_1_to_250_bytes() {
        assert!(PackedBits::from_bytes(vec![]).is_err());
        assert!(PackedBits::from_bytes(vec![0; 250]).is_ok());
        assert!(PackedBits::from_bytes(vec![0; 251]).is_err());
        assert_eq!(
            PackedBits::from_bits(&[true; 9]).map(|b| b.byte_count()),
            Ok(2)
        );
        assert!(PackedBits::from_bits(&[true; 2001]).is_err());
    }

    #[test]
    fn register_values_hold_1_to_125_registers() {
        assert!(RegisterValues::new(vec![]).is_err());
        assert_eq!(
            RegisterValues::new(vec![7; 125]).map(|r| r.byte_count()),
            Ok(250)
        );
        assert!(RegisterValues::new(vec![7; 126]).is_err());
    }
}
