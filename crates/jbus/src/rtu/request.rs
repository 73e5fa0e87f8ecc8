//! Requests: typed ([`Request`], valid by construction, what a client sends) and as they
//! stand on the wire ([`RequestPdu`], any numbers, what a server receives).
//!
//! A client builds a [`Request`] and addresses it to a [`UnitId`] ([`Addressed`]) or, for a
//! write, to every unit ([`Broadcast`]). A server decodes a [`RequestAdu`] whatever its
//! counts say, then checks it as a Modbus server does with [`RequestPdu::to_request`], which
//! names the exception to answer (1, 2 or 3) when the request is not valid.

use std::fmt;

use super::value::{
    BROADCAST_UNIT, ExceptionCode, FunctionCode, InvalidValue, ReadBitCount, ReadRegisterCount,
    UnitId, WriteBitCount, WriteRegisterCount, check_block,
};

/// The value of a coil switched on, as function 5 carries it.
pub const COIL_ON: u16 = 0xFF00;
/// The value of a coil switched off, as function 5 carries it.
pub const COIL_OFF: u16 = 0x0000;

/// A read of consecutive coils or discrete inputs (functions 1 and 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ReadBits {
    address: u16,
    count: ReadBitCount,
}

impl ReadBits {
    /// `count` bits from `address`; the last one must not lie past 0xFFFF.
    pub fn new(address: u16, count: ReadBitCount) -> Result<Self, InvalidValue> {
        check_block("bits", address, count.get().into())?;
        Ok(Self { address, count })
    }

    /// The first address.
    pub const fn address(&self) -> u16 {
        self.address
    }

    /// How many bits.
    pub const fn count(&self) -> ReadBitCount {
        self.count
    }
}

/// A read of consecutive holding or input registers (functions 3 and 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ReadRegisters {
    address: u16,
    count: ReadRegisterCount,
}

impl ReadRegisters {
    /// `count` registers from `address`; the last one must not lie past 0xFFFF.
    pub fn new(address: u16, count: ReadRegisterCount) -> Result<Self, InvalidValue> {
        check_block("registers", address, count.get().into())?;
        Ok(Self { address, count })
    }

    /// The first address.
    pub const fn address(&self) -> u16 {
        self.address
    }

    /// How many registers.
    pub const fn count(&self) -> ReadRegisterCount {
        self.count
    }
}

/// A write of one coil (function 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WriteCoil {
    /// The coil's address.
    pub address: u16,
    /// On or off.
    pub value: bool,
}

/// A write of one holding register (function 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct WriteRegister {
    /// The register's address.
    pub address: u16,
    /// The value.
    pub value: u16,
}

/// A write of consecutive coils (function 15): 1–1968 of them, not past 0xFFFF.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct WriteCoils {
    address: u16,
    values: Vec<bool>,
}

impl WriteCoils {
    /// The coils from `address` on take `values`.
    pub fn new(address: u16, values: Vec<bool>) -> Result<Self, InvalidValue> {
        WriteBitCount::from_len(values.len())?;
        check_block("coils", address, values.len())?;
        Ok(Self { address, values })
    }

    /// The first address.
    pub const fn address(&self) -> u16 {
        self.address
    }

    /// The values, first address first.
    pub fn values(&self) -> &[bool] {
        &self.values
    }

    /// How many coils.
    pub fn count(&self) -> WriteBitCount {
        WriteBitCount::from_len(self.values.len()).expect("checked when the write was built")
    }
}

/// A write of consecutive holding registers (function 16): 1–123, not past 0xFFFF.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct WriteRegisters {
    address: u16,
    values: Vec<u16>,
}

impl WriteRegisters {
    /// The registers from `address` on take `values`.
    pub fn new(address: u16, values: Vec<u16>) -> Result<Self, InvalidValue> {
        WriteRegisterCount::from_len(values.len())?;
        check_block("registers", address, values.len())?;
        Ok(Self { address, values })
    }

    /// The first address.
    pub const fn address(&self) -> u16 {
        self.address
    }

    /// The values, first address first.
    pub fn values(&self) -> &[u16] {
        &self.values
    }

    /// How many registers.
    pub fn count(&self) -> WriteRegisterCount {
        WriteRegisterCount::from_len(self.values.len()).expect("checked when the write was built")
    }
}

/// A Modbus request, one variant per function; valid by construction.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Request {
    /// Function 1.
    ReadCoils(ReadBits),
    /// Function 2.
    ReadDiscreteInputs(ReadBits),
    /// Function 3.
    ReadHoldingRegisters(ReadRegisters),
    /// Function 4.
    ReadInputRegisters(ReadRegisters),
    /// Function 5.
    WriteSingleCoil(WriteCoil),
    /// Function 6.
    WriteSingleRegister(WriteRegister),
    /// Function 15.
    WriteMultipleCoils(WriteCoils),
    /// Function 16.
    WriteMultipleRegisters(WriteRegisters),
}

impl Request {
    /// Function 1: `count` coils from `address`.
    pub fn read_coils(address: u16, count: u16) -> Result<Self, InvalidValue> {
        Ok(Self::ReadCoils(ReadBits::new(
            address,
            ReadBitCount::new(count)?,
        )?))
    }

    /// Function 2: `count` discrete inputs from `address`.
    pub fn read_discrete_inputs(address: u16, count: u16) -> Result<Self, InvalidValue> {
        Ok(Self::ReadDiscreteInputs(ReadBits::new(
            address,
            ReadBitCount::new(count)?,
        )?))
    }

    /// Function 3: `count` holding registers from `address`.
    pub fn read_holding_registers(address: u16, count: u16) -> Result<Self, InvalidValue> {
        Ok(Self::ReadHoldingRegisters(ReadRegisters::new(
            address,
            ReadRegisterCount::new(count)?,
        )?))
    }

    /// Function 4: `count` input registers from `address`.
    pub fn read_input_registers(address: u16, count: u16) -> Result<Self, InvalidValue> {
        Ok(Self::ReadInputRegisters(ReadRegisters::new(
            address,
            ReadRegisterCount::new(count)?,
        )?))
    }

    /// Function 5: one coil.
    pub fn write_single_coil(address: u16, value: bool) -> Self {
        Self::WriteSingleCoil(WriteCoil { address, value })
    }

    /// Function 6: one holding register.
    pub fn write_single_register(address: u16, value: u16) -> Self {
        Self::WriteSingleRegister(WriteRegister { address, value })
    }

    /// Function 15: coils from `address` on.
    pub fn write_multiple_coils(address: u16, values: Vec<bool>) -> Result<Self, InvalidValue> {
        Ok(Self::WriteMultipleCoils(WriteCoils::new(address, values)?))
    }

    /// Function 16: holding registers from `address` on.
    pub fn write_multiple_registers(address: u16, values: Vec<u16>) -> Result<Self, InvalidValue> {
        Ok(Self::WriteMultipleRegisters(WriteRegisters::new(
            address, values,
        )?))
    }

    /// The function code.
    pub fn function(&self) -> FunctionCode {
        match self {
            Self::ReadCoils(_) => FunctionCode::READ_COILS,
            Self::ReadDiscreteInputs(_) => FunctionCode::READ_DISCRETE_INPUTS,
            Self::ReadHoldingRegisters(_) => FunctionCode::READ_HOLDING_REGISTERS,
            Self::ReadInputRegisters(_) => FunctionCode::READ_INPUT_REGISTERS,
            Self::WriteSingleCoil(_) => FunctionCode::WRITE_SINGLE_COIL,
            Self::WriteSingleRegister(_) => FunctionCode::WRITE_SINGLE_REGISTER,
            Self::WriteMultipleCoils(_) => FunctionCode::WRITE_MULTIPLE_COILS,
            Self::WriteMultipleRegisters(_) => FunctionCode::WRITE_MULTIPLE_REGISTERS,
        }
    }

    /// The first address the request touches.
    pub fn address(&self) -> u16 {
        match self {
            Self::ReadCoils(r) | Self::ReadDiscreteInputs(r) => r.address,
            Self::ReadHoldingRegisters(r) | Self::ReadInputRegisters(r) => r.address,
            Self::WriteSingleCoil(w) => w.address,
            Self::WriteSingleRegister(w) => w.address,
            Self::WriteMultipleCoils(w) => w.address,
            Self::WriteMultipleRegisters(w) => w.address,
        }
    }

    /// The request as the wire carries it.
    pub fn to_pdu(&self) -> RequestPdu {
        match self {
            Self::ReadCoils(r) => RequestPdu::ReadCoils {
                address: r.address,
                count: r.count.get(),
            },
            Self::ReadDiscreteInputs(r) => RequestPdu::ReadDiscreteInputs {
                address: r.address,
                count: r.count.get(),
            },
            Self::ReadHoldingRegisters(r) => RequestPdu::ReadHoldingRegisters {
                address: r.address,
                count: r.count.get(),
            },
            Self::ReadInputRegisters(r) => RequestPdu::ReadInputRegisters {
                address: r.address,
                count: r.count.get(),
            },
            Self::WriteSingleCoil(w) => RequestPdu::WriteSingleCoil {
                address: w.address,
                value: if w.value { COIL_ON } else { COIL_OFF },
            },
            Self::WriteSingleRegister(w) => RequestPdu::WriteSingleRegister {
                address: w.address,
                value: w.value,
            },
            Self::WriteMultipleCoils(w) => RequestPdu::WriteMultipleCoils {
                address: w.address,
                count: w.count().get(),
                data: ByteField::new(pack_bits(&w.values))
                    .expect("at most 1968 coils pack into 246 bytes"),
            },
            Self::WriteMultipleRegisters(w) => RequestPdu::WriteMultipleRegisters {
                address: w.address,
                count: w.count().get(),
                data: ByteField::new(w.values.iter().flat_map(|v| v.to_be_bytes()).collect())
                    .expect("at most 123 registers take 246 bytes"),
            },
        }
    }

    /// Whether the request only reads.
    pub fn is_read(&self) -> bool {
        matches!(
            self,
            Self::ReadCoils(_)
                | Self::ReadDiscreteInputs(_)
                | Self::ReadHoldingRegisters(_)
                | Self::ReadInputRegisters(_)
        )
    }
}

impl From<Write> for Request {
    fn from(write: Write) -> Self {
        match write {
            Write::SingleCoil(w) => Self::WriteSingleCoil(w),
            Write::SingleRegister(w) => Self::WriteSingleRegister(w),
            Write::MultipleCoils(w) => Self::WriteMultipleCoils(w),
            Write::MultipleRegisters(w) => Self::WriteMultipleRegisters(w),
        }
    }
}

/// `count` and a plural noun, made singular for one: `1 coil`, `2 coils`.
pub(crate) fn counted(count: impl Into<usize>, plural: &str) -> String {
    match count.into() {
        1 => format!("1 {}", plural.strip_suffix('s').unwrap_or(plural)),
        n => format!("{n} {plural}"),
    }
}

impl fmt::Display for Request {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ReadCoils(r) => write!(
                f,
                "read {} from {}",
                counted(r.count.get(), "coils"),
                Addr(r.address)
            ),
            Self::ReadDiscreteInputs(r) => write!(
                f,
                "read {} from {}",
                counted(r.count.get(), "discrete inputs"),
                Addr(r.address)
            ),
            Self::ReadHoldingRegisters(r) => write!(
                f,
                "read {} from {}",
                counted(r.count.get(), "holding registers"),
                Addr(r.address)
            ),
            Self::ReadInputRegisters(r) => write!(
                f,
                "read {} from {}",
                counted(r.count.get(), "input registers"),
                Addr(r.address)
            ),
            Self::WriteSingleCoil(w) => w.show(f, "write"),
            Self::WriteSingleRegister(w) => w.show(f, "write"),
            Self::WriteMultipleCoils(w) => {
                show_span(f, "write", w.values.len(), "coils", w.address)
            }
            Self::WriteMultipleRegisters(w) => {
                show_span(f, "write", w.values.len(), "registers", w.address)
            }
        }
    }
}

/// `VERB N THINGS from ADDR`: a write of several coils or registers, or its answer.
pub(crate) fn show_span(
    f: &mut fmt::Formatter<'_>,
    verb: &str,
    count: usize,
    plural: &str,
    address: u16,
) -> fmt::Result {
    write!(
        f,
        "{verb} {} from {}",
        counted(count, plural),
        Addr(address)
    )
}

impl WriteCoil {
    /// `VERB coil ADDR on|off`: the request, or its answer.
    pub(crate) fn show(&self, f: &mut fmt::Formatter<'_>, verb: &str) -> fmt::Result {
        let state = if self.value { "on" } else { "off" };
        write!(f, "{verb} coil {} {state}", Addr(self.address))
    }
}

impl WriteRegister {
    /// `VERB register ADDR = VALUE`: the request, or its answer.
    pub(crate) fn show(&self, f: &mut fmt::Formatter<'_>, verb: &str) -> fmt::Result {
        write!(f, "{verb} register {} = {}", Addr(self.address), self.value)
    }
}

/// An address shown in decimal and hex.
pub(crate) struct Addr(pub u16);

impl fmt::Display for Addr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (0x{:04X})", self.0, self.0)
    }
}

/// A write, the only kind of request that may be broadcast.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Write {
    /// Function 5.
    SingleCoil(WriteCoil),
    /// Function 6.
    SingleRegister(WriteRegister),
    /// Function 15.
    MultipleCoils(WriteCoils),
    /// Function 16.
    MultipleRegisters(WriteRegisters),
}

/// A request to one unit: what a client sends and then waits to see answered.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Addressed {
    /// The unit asked.
    pub unit: UnitId,
    /// What it is asked.
    pub request: Request,
}

impl Addressed {
    /// `request` for `unit`.
    pub fn new(unit: UnitId, request: Request) -> Self {
        Self { unit, request }
    }

    /// The frame to send.
    pub fn to_adu(&self) -> RequestAdu {
        RequestAdu {
            unit: self.unit.get(),
            pdu: self.request.to_pdu(),
        }
    }
}

impl fmt::Display for Addressed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unit {}: {}", self.unit, self.request)
    }
}

/// A write to every unit on the line (unit 0). No unit answers a broadcast, so a client
/// sends it and waits only for the line's turnaround delay; a read cannot be broadcast.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Broadcast(pub Write);

impl Broadcast {
    /// The frame to send.
    pub fn to_adu(&self) -> RequestAdu {
        RequestAdu {
            unit: BROADCAST_UNIT,
            pdu: Request::from(self.0.clone()).to_pdu(),
        }
    }
}

/// At most 255 bytes: the data of a write-multiple request, whose length the frame
/// carries in one byte.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub struct ByteField(Vec<u8>);

impl ByteField {
    /// The longest field.
    pub const MAX: usize = 255;

    /// `bytes`, if there are at most 255.
    pub fn new(bytes: Vec<u8>) -> Result<Self, InvalidValue> {
        if bytes.len() > Self::MAX {
            return Err(InvalidValue::out_of_range(
                "byte count",
                bytes.len(),
                0,
                255,
            ));
        }
        Ok(Self(bytes))
    }

    /// The bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }

    /// The byte count as the frame carries it.
    pub fn byte_count(&self) -> u8 {
        u8::try_from(self.0.len()).expect("a byte field holds at most 255 bytes")
    }
}

/// A request with a function code this crate does not frame as one of its eight: kept
/// whole so a server can refuse it with exception 1.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct OtherFunction {
    function: u8,
    data: Vec<u8>,
}

impl OtherFunction {
    /// The most data bytes a request of another function can carry: function 23
    /// (read/write multiple registers) writing 255 bytes has 264.
    pub const MAX_DATA: usize = 264;

    /// A request for `function` with `data`; `function` must not be one of the eight
    /// functions [`RequestPdu`] has a variant for.
    pub fn new(function: u8, data: Vec<u8>) -> Result<Self, InvalidValue> {
        if is_framed_function(function) {
            return Err(InvalidValue::OutOfRange {
                what: "function code of an unsupported request (one of 1-6, 15, 16)",
                value: function.into(),
                min: 0,
                max: 255,
            });
        }
        if data.len() > Self::MAX_DATA {
            return Err(InvalidValue::out_of_range(
                "data length",
                data.len(),
                0,
                Self::MAX_DATA as u32,
            ));
        }
        Ok(Self { function, data })
    }

    /// The function byte as it came (may even have the exception bit set).
    pub fn function(&self) -> u8 {
        self.function
    }

    /// The bytes between the function code and the CRC.
    pub fn data(&self) -> &[u8] {
        &self.data
    }
}

pub(crate) fn is_framed_function(code: u8) -> bool {
    matches!(code, 1..=6 | 15 | 16)
}

/// A request as the wire carries it: numbers as they came, so a server can answer an
/// out-of-range count with exception 3 rather than silence.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum RequestPdu {
    /// Function 1.
    ReadCoils {
        /// First address.
        address: u16,
        /// Number of coils (valid: 1–2000).
        count: u16,
    },
    /// Function 2.
    ReadDiscreteInputs {
        /// First address.
        address: u16,
        /// Number of inputs (valid: 1–2000).
        count: u16,
    },
    /// Function 3.
    ReadHoldingRegisters {
        /// First address.
        address: u16,
        /// Number of registers (valid: 1–125).
        count: u16,
    },
    /// Function 4.
    ReadInputRegisters {
        /// First address.
        address: u16,
        /// Number of registers (valid: 1–125).
        count: u16,
    },
    /// Function 5.
    WriteSingleCoil {
        /// The coil.
        address: u16,
        /// [`COIL_ON`] or [`COIL_OFF`] when valid.
        value: u16,
    },
    /// Function 6.
    WriteSingleRegister {
        /// The register.
        address: u16,
        /// The value.
        value: u16,
    },
    /// Function 15.
    WriteMultipleCoils {
        /// First address.
        address: u16,
        /// Number of coils (valid: 1–1968).
        count: u16,
        /// Coil values, 8 per byte, first coil in bit 0 (valid: `ceil(count / 8)` bytes).
        data: ByteField,
    },
    /// Function 16.
    WriteMultipleRegisters {
        /// First address.
        address: u16,
        /// Number of registers (valid: 1–123).
        count: u16,
        /// Register values, high byte first (valid: `2 * count` bytes).
        data: ByteField,
    },
    /// Any other function.
    Other(OtherFunction),
}

impl RequestPdu {
    /// The function byte.
    pub fn function_byte(&self) -> u8 {
        match self {
            Self::ReadCoils { .. } => FunctionCode::READ_COILS.get(),
            Self::ReadDiscreteInputs { .. } => FunctionCode::READ_DISCRETE_INPUTS.get(),
            Self::ReadHoldingRegisters { .. } => FunctionCode::READ_HOLDING_REGISTERS.get(),
            Self::ReadInputRegisters { .. } => FunctionCode::READ_INPUT_REGISTERS.get(),
            Self::WriteSingleCoil { .. } => FunctionCode::WRITE_SINGLE_COIL.get(),
            Self::WriteSingleRegister { .. } => FunctionCode::WRITE_SINGLE_REGISTER.get(),
            Self::WriteMultipleCoils { .. } => FunctionCode::WRITE_MULTIPLE_COILS.get(),
            Self::WriteMultipleRegisters { .. } => FunctionCode::WRITE_MULTIPLE_REGISTERS.get(),
            Self::Other(other) => other.function,
        }
    }

    /// The first address, for the eight framed functions.
    pub fn address(&self) -> Option<u16> {
        match *self {
            Self::ReadCoils { address, .. }
            | Self::ReadDiscreteInputs { address, .. }
            | Self::ReadHoldingRegisters { address, .. }
            | Self::ReadInputRegisters { address, .. }
            | Self::WriteSingleCoil { address, .. }
            | Self::WriteSingleRegister { address, .. }
            | Self::WriteMultipleCoils { address, .. }
            | Self::WriteMultipleRegisters { address, .. } => Some(address),
            Self::Other(_) => None,
        }
    }

    /// Checks the request as a Modbus server does, in the standard's order: an unknown
    /// function is exception 1; a count out of range, a byte count that does not match the
    /// count or a coil value other than 0xFF00/0x0000 is exception 3; a block running past
    /// 0xFFFF is exception 2. Whether the addresses exist is the device's business.
    pub fn to_request(&self) -> Result<Request, ExceptionCode> {
        const VALUE: ExceptionCode = ExceptionCode::ILLEGAL_DATA_VALUE;
        let address_error = |_| ExceptionCode::ILLEGAL_DATA_ADDRESS;
        Ok(match self {
            &Self::ReadCoils { address, count } => Request::ReadCoils(
                ReadBits::new(address, ReadBitCount::new(count).map_err(|_| VALUE)?)
                    .map_err(address_error)?,
            ),
            &Self::ReadDiscreteInputs { address, count } => Request::ReadDiscreteInputs(
                ReadBits::new(address, ReadBitCount::new(count).map_err(|_| VALUE)?)
                    .map_err(address_error)?,
            ),
            &Self::ReadHoldingRegisters { address, count } => Request::ReadHoldingRegisters(
                ReadRegisters::new(address, ReadRegisterCount::new(count).map_err(|_| VALUE)?)
                    .map_err(address_error)?,
            ),
            &Self::ReadInputRegisters { address, count } => Request::ReadInputRegisters(
                ReadRegisters::new(address, ReadRegisterCount::new(count).map_err(|_| VALUE)?)
                    .map_err(address_error)?,
            ),
            &Self::WriteSingleCoil { address, value } => Request::WriteSingleCoil(WriteCoil {
                address,
                value: match value {
                    COIL_ON => true,
                    COIL_OFF => false,
                    _ => return Err(VALUE),
                },
            }),
            &Self::WriteSingleRegister { address, value } => {
                Request::WriteSingleRegister(WriteRegister { address, value })
            }
            Self::WriteMultipleCoils {
                address,
                count,
                data,
            } => {
                let count = WriteBitCount::new(*count).map_err(|_| VALUE)?;
                if data.as_bytes().len() != packed_len(count.get().into()) {
                    return Err(VALUE);
                }
                let values = unpack_bits(data.as_bytes(), count.get().into());
                Request::WriteMultipleCoils(
                    WriteCoils::new(*address, values).map_err(address_error)?,
                )
            }
            Self::WriteMultipleRegisters {
                address,
                count,
                data,
            } => {
                let count = WriteRegisterCount::new(*count).map_err(|_| VALUE)?;
                if data.as_bytes().len() != 2 * usize::from(count.get()) {
                    return Err(VALUE);
                }
                let values = data
                    .as_bytes()
                    .chunks_exact(2)
                    .map(|b| u16::from_be_bytes([b[0], b[1]]))
                    .collect();
                Request::WriteMultipleRegisters(
                    WriteRegisters::new(*address, values).map_err(address_error)?,
                )
            }
            Self::Other(_) => return Err(ExceptionCode::ILLEGAL_FUNCTION),
        })
    }
}

/// A request frame: unit number (0 = broadcast) and request, as the wire carries them.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RequestAdu {
    /// The unit number: 0 for a broadcast, 1–247 (JBUS: 1–255) for one unit.
    pub unit: u8,
    /// The request.
    pub pdu: RequestPdu,
}

impl RequestAdu {
    /// Whether the frame is a broadcast (unit 0), which no unit answers.
    pub fn is_broadcast(&self) -> bool {
        self.unit == BROADCAST_UNIT
    }
}

/// Bytes needed for `count` bits, 8 per byte.
pub fn packed_len(count: usize) -> usize {
    count.div_ceil(8)
}

/// Packs bits 8 per byte, the first in the lowest bit of the first byte, as functions 1,
/// 2 and 15 carry them; unused high bits of the last byte are 0.
pub fn pack_bits(bits: &[bool]) -> Vec<u8> {
    bits.chunks(8)
        .map(|chunk| {
            chunk
                .iter()
                .enumerate()
                .fold(0u8, |byte, (i, &on)| byte | (u8::from(on) << i))
        })
        .collect()
}

/// The first `count` bits of `bytes` (fewer if `bytes` holds fewer).
pub fn unpack_bits(bytes: &[u8], count: usize) -> Vec<bool> {
    bytes
        .iter()
        .flat_map(|&byte| (0..8).map(move |i| byte & (1 << i) != 0))
        .take(count)
        .collect()
}

#[cfg(test)]
mod tests;
