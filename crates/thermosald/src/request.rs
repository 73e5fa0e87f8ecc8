//! Typed requests: one per message number of the spec.
//!
//! thermosald-isc-rs485.txt, "Message transmission codes": 10 set logic address, 11 write
//! machine data, 12 write settings data, 13 not used, 14 clear faults, 15 automatic
//! balancing, 16 write data on EEPROM, 17 read data from EEPROM, 18 write commissioning
//! (service) data, 51/52/53/58 read machine / settings / run-time / start-up (service)
//! data, 99 master reset.
//!
//! # What each message carries
//!
//! The spec fixes the layout but not every message's data; this crate sends:
//!
//! | request | count | data of the query | the regulator answers |
//! |---|---|---|---|
//! | read, whole table | `99` | none | the table, all items in index order |
//! | read, one item | index | none | that item |
//! | write, whole table | `99` | the table | the echo |
//! | write, one item | index | the item | the echo |
//! | set address (10) | `00` | the new address (data item 0, as the spec says) | the echo |
//! | command (14, 15, 16, 17, 99) | `00` | `000` | the echo |
//!
//! For example, `%012Q150180` + LF sets the sealing temperature (settings item 15) of the
//! regulator at address 0 to 180 °C, and `%$10Q000003` + LF gives address 3 to whichever
//! regulator is powered. [`Request::parse`] (the regulator's side) accepts commands and
//! read queries with any count and data, and does not check write values against the
//! items' ranges: a regulator decides what it stores, and its echo shows it.

use std::fmt;

use crate::frame::{
    Address, AddressError, Count, Direction, Frame, MessageNumber, RawValue, Target,
};
use crate::tables::{Item, LookupError, Table, ValueError};

/// Message 13, which the spec lists as NOT USED.
pub const UNUSED_MESSAGE: u8 = 13;

/// A message number the regulator knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Message {
    /// 10: write the logic address (sent to `$` during commissioning).
    SetAddress,
    /// 11: write machine data.
    WriteMachine,
    /// 12: write settings data.
    WriteSettings,
    /// 14: clear faults.
    ClearFaults,
    /// 15: automatic balancing (calibration).
    Balance,
    /// 16: write data on EEPROM (save).
    SaveEeprom,
    /// 17: read data from EEPROM (load).
    LoadEeprom,
    /// 18: write commissioning (service) data.
    WriteService,
    /// 51: read machine data.
    ReadMachine,
    /// 52: read settings data.
    ReadSettings,
    /// 53: read run-time data.
    ReadRuntime,
    /// 58: read start-up (service) data.
    ReadService,
    /// 99: master reset (factory data, no address, calibration request).
    MasterReset,
}

impl Message {
    /// Every message, by number.
    pub const ALL: [Message; 13] = [
        Message::SetAddress,
        Message::WriteMachine,
        Message::WriteSettings,
        Message::ClearFaults,
        Message::Balance,
        Message::SaveEeprom,
        Message::LoadEeprom,
        Message::WriteService,
        Message::ReadMachine,
        Message::ReadSettings,
        Message::ReadRuntime,
        Message::ReadService,
        Message::MasterReset,
    ];

    /// The two-digit number on the wire.
    pub const fn number(self) -> MessageNumber {
        MessageNumber::known(match self {
            Message::SetAddress => 10,
            Message::WriteMachine => 11,
            Message::WriteSettings => 12,
            Message::ClearFaults => 14,
            Message::Balance => 15,
            Message::SaveEeprom => 16,
            Message::LoadEeprom => 17,
            Message::WriteService => 18,
            Message::ReadMachine => 51,
            Message::ReadSettings => 52,
            Message::ReadRuntime => 53,
            Message::ReadService => 58,
            Message::MasterReset => 99,
        })
    }

    /// The message with this number; 13 (not used) and numbers the spec does not list are
    /// refused.
    pub fn from_number(number: MessageNumber) -> Result<Message, RequestError> {
        if number.get() == UNUSED_MESSAGE {
            return Err(RequestError::UnusedMessage {
                number: UNUSED_MESSAGE,
            });
        }
        Message::ALL
            .into_iter()
            .find(|m| m.number() == number)
            .ok_or(RequestError::UnknownMessage {
                number: number.get(),
            })
    }

    /// What the message does, as the spec names it.
    pub const fn description(self) -> &'static str {
        match self {
            Message::SetAddress => "write logic address",
            Message::WriteMachine => "write machine data",
            Message::WriteSettings => "write settings data",
            Message::ClearFaults => "clear faults",
            Message::Balance => "automatic balancing",
            Message::SaveEeprom => "write data on EEPROM",
            Message::LoadEeprom => "read data from EEPROM",
            Message::WriteService => "write commissioning data",
            Message::ReadMachine => "read machine data",
            Message::ReadSettings => "read settings data",
            Message::ReadRuntime => "read run-time data",
            Message::ReadService => "read start-up data",
            Message::MasterReset => "master reset",
        }
    }

    /// What kind of exchange the message is.
    pub const fn kind(self) -> MessageKind {
        match self {
            Message::SetAddress => MessageKind::SetAddress,
            Message::WriteMachine => MessageKind::Write(Table::Machine),
            Message::WriteSettings => MessageKind::Write(Table::Settings),
            Message::WriteService => MessageKind::Write(Table::Service),
            Message::ReadMachine => MessageKind::Read(Table::Machine),
            Message::ReadSettings => MessageKind::Read(Table::Settings),
            Message::ReadRuntime => MessageKind::Read(Table::Runtime),
            Message::ReadService => MessageKind::Read(Table::Service),
            Message::ClearFaults => MessageKind::Command(Command::ClearFaults),
            Message::Balance => MessageKind::Command(Command::Balance),
            Message::SaveEeprom => MessageKind::Command(Command::SaveEeprom),
            Message::LoadEeprom => MessageKind::Command(Command::LoadEeprom),
            Message::MasterReset => MessageKind::Command(Command::MasterReset),
        }
    }
}

impl fmt::Display for Message {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.number(), self.description())
    }
}

/// What a message does with the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MessageKind {
    /// Reads a table; the answer carries the data.
    Read(Table),
    /// Writes a table; the answer is an echo.
    Write(Table),
    /// Writes the logic address; the answer is an echo.
    SetAddress,
    /// A command; the answer is an echo.
    Command(Command),
}

/// A message that makes the regulator act; it is echoed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// 14: clear latched faults whose cause is gone.
    ClearFaults,
    /// 15: automatic balancing: measure the band at the balancing temperature (settings
    /// item 13). Diagnostic 36 shows while it runs.
    Balance,
    /// 16: save working data to EEPROM.
    SaveEeprom,
    /// 17: load working data from EEPROM.
    LoadEeprom,
    /// 99: master reset: factory data, no address, diagnostic 35 until balancing.
    MasterReset,
}

impl Command {
    /// The command's message.
    pub const fn message(self) -> Message {
        match self {
            Command::ClearFaults => Message::ClearFaults,
            Command::Balance => Message::Balance,
            Command::SaveEeprom => Message::SaveEeprom,
            Command::LoadEeprom => Message::LoadEeprom,
            Command::MasterReset => Message::MasterReset,
        }
    }
}

/// Which items a read or write covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Selection {
    /// The whole table (count `99`).
    All,
    /// One item (count = its index).
    Item(&'static Item),
}

impl Selection {
    /// The count field for this selection.
    pub fn count(self) -> Count {
        match self {
            Selection::All => Count::All,
            // Tables have at most 25 items, far below the 99 that means "all".
            Selection::Item(item) => Count::item(item.index()).expect("table indexes are below 99"),
        }
    }
}

/// A read of a table or one of its items (51, 52, 53, 58).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Read {
    table: Table,
    selection: Selection,
}

impl Read {
    /// Reads the whole table.
    pub const fn all(table: Table) -> Self {
        Self {
            table,
            selection: Selection::All,
        }
    }

    /// Reads one item.
    pub const fn item(item: &'static Item) -> Self {
        Self {
            table: item.table(),
            selection: Selection::Item(item),
        }
    }

    /// Reads the item at `index` of `table`.
    pub fn index(table: Table, index: u8) -> Result<Self, RequestError> {
        Ok(Self::item(table.item(index)?))
    }

    /// The table read.
    pub const fn table(&self) -> Table {
        self.table
    }

    /// Whole table or one item.
    pub const fn selection(&self) -> Selection {
        self.selection
    }

    /// The items the answer carries, in order.
    pub fn items(&self) -> &'static [Item] {
        match self.selection {
            Selection::All => self.table.items(),
            Selection::Item(item) => std::slice::from_ref(item),
        }
    }
}

/// A write of a table or one of its items (11, 12, 18).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Write {
    message: Message,
    table: Table,
    selection: Selection,
    data: Vec<RawValue>,
}

impl Write {
    /// Writes `value` (in the item's unit: `180.0` °C, `12.5`) to a writable item;
    /// refused before the wire if the item is read-only or the value does not fit.
    pub fn value(item: &'static Item, value: f64) -> Result<Self, RequestError> {
        let raw = item.to_raw(value)?;
        Self::item(item, raw)
    }

    /// Writes the raw digits `raw` to a writable item; refused if the item is read-only or
    /// `raw` is outside its range.
    pub fn item(item: &'static Item, raw: RawValue) -> Result<Self, RequestError> {
        let message = check_writable_table(item.table())?;
        if !item.writable() {
            return Err(RequestError::ReadOnlyItem {
                table: item.table(),
                item: item.name(),
                index: item.index(),
            });
        }
        check_raw(item, raw)?;
        Ok(Self {
            message,
            table: item.table(),
            selection: Selection::Item(item),
            data: vec![raw],
        })
    }

    /// Writes a whole table: one raw value per item, in index order. Writable items must be
    /// in range; the values of read-only items are sent as given and the regulator keeps
    /// its own (so read the table, change it, write it back).
    pub fn whole(table: Table, values: Vec<RawValue>) -> Result<Self, RequestError> {
        let message = check_writable_table(table)?;
        if values.len() != table.len() {
            return Err(RequestError::ItemCount {
                message,
                expected: table.len(),
                actual: values.len(),
            });
        }
        for (item, raw) in table.items().iter().zip(&values) {
            if item.writable() {
                check_raw(item, *raw)?;
            }
        }
        Ok(Self {
            message,
            table,
            selection: Selection::All,
            data: values,
        })
    }

    /// The table written.
    pub const fn table(&self) -> Table {
        self.table
    }

    /// Whole table or one item.
    pub const fn selection(&self) -> Selection {
        self.selection
    }

    /// The raw values written, in item order.
    pub fn data(&self) -> &[RawValue] {
        &self.data
    }

    /// The items written with their values.
    pub fn values(&self) -> impl Iterator<Item = (&'static Item, RawValue)> + '_ {
        let items: &'static [Item] = match self.selection {
            Selection::All => self.table.items(),
            Selection::Item(item) => std::slice::from_ref(item),
        };
        items.iter().zip(self.data.iter().copied())
    }

    /// The message that carries the write (11, 12 or 18).
    pub const fn message(&self) -> Message {
        self.message
    }
}

/// A request from the master: one per message number of the spec.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Request {
    /// 10: write the logic address.
    SetAddress(Address),
    /// 51, 52, 53, 58: read data.
    Read(Read),
    /// 11, 12, 18: write data.
    Write(Write),
    /// 14, 15, 16, 17, 99: a command.
    Command(Command),
}

impl Request {
    /// The request's message.
    pub fn message(&self) -> Message {
        match self {
            Request::SetAddress(_) => Message::SetAddress,
            Request::Read(read) => read.table.read_message(),
            Request::Write(write) => write.message(),
            Request::Command(command) => command.message(),
        }
    }

    /// The query frame for `target` (see the module table for what each carries). Address
    /// assignment goes to [`Target::Assign`] during commissioning; the crate also lets it
    /// go to a regulator's current address to change it.
    pub fn to_frame(&self, target: Target) -> Frame {
        let (count, data) = match self {
            Request::SetAddress(new) => (Count::Item(FIRST), vec![raw_of(new.get())]),
            Request::Read(read) => (read.selection.count(), Vec::new()),
            Request::Write(write) => (write.selection.count(), write.data.clone()),
            Request::Command(_) => (Count::Item(FIRST), vec![RawValue::ZERO]),
        };
        Frame::new(
            target,
            self.message().number(),
            Direction::Query,
            count,
            data,
        )
        .expect("a request carries at most one table, and no table exceeds MAX_DATA_ITEMS")
    }

    /// The request a query frame carries (the regulator's side). Refused: a response, an
    /// unused or unknown message number, `$` with anything but message 10, an item index
    /// beyond the table, a write with the wrong number of data items, an address above 7.
    pub fn parse(frame: &Frame) -> Result<Request, RequestError> {
        let message = Message::from_number(frame.message())?;
        if frame.direction() != Direction::Query {
            return Err(RequestError::NotAQuery { message });
        }
        if frame.target() == Target::Assign && message != Message::SetAddress {
            return Err(RequestError::AssignOnlySetsAddress { message });
        }
        let selection = |table: Table| -> Result<Selection, LookupError> {
            Ok(match frame.count() {
                Count::All => Selection::All,
                Count::Item(index) => Selection::Item(table.item(index.get())?),
            })
        };
        Ok(match message.kind() {
            MessageKind::SetAddress => {
                let raw = frame.data().first().ok_or(RequestError::ItemCount {
                    message,
                    expected: 1,
                    actual: 0,
                })?;
                let address = u8::try_from(raw.get())
                    .ok()
                    .and_then(|v| Address::new(v).ok());
                Request::SetAddress(address.ok_or(AddressError::OutOfRange {
                    value: raw.get().into(),
                    min: Address::MIN,
                    max: Address::MAX,
                })?)
            }
            MessageKind::Read(table) => Request::Read(Read {
                table,
                selection: selection(table)?,
            }),
            MessageKind::Write(table) => {
                let selection = selection(table)?;
                let expected = match selection {
                    Selection::All => table.len(),
                    Selection::Item(_) => 1,
                };
                if frame.data().len() != expected {
                    return Err(RequestError::ItemCount {
                        message,
                        expected,
                        actual: frame.data().len(),
                    });
                }
                Request::Write(Write {
                    message,
                    table,
                    selection,
                    data: frame.data().to_vec(),
                })
            }
            MessageKind::Command(command) => Request::Command(command),
        })
    }
}

impl From<Read> for Request {
    fn from(read: Read) -> Self {
        Request::Read(read)
    }
}

impl From<Write> for Request {
    fn from(write: Write) -> Self {
        Request::Write(write)
    }
}

impl From<Command> for Request {
    fn from(command: Command) -> Self {
        Request::Command(command)
    }
}

/// A message in words, for annotated dumps and logs: whom it is for, what it asks or
/// answers, and its data as named, scaled items, e.g. `address 0, message 52 (read settings
/// data), response, item 15: Set sealing temperature = 180 °C`. Messages the spec does not
/// know, and data that do not fit the message, are described as such, never refused.
pub fn describe(frame: &Frame) -> String {
    use std::fmt::Write as _;

    let mut text = String::new();
    let direction = match frame.direction() {
        Direction::Query => "question",
        Direction::Reply => "response",
    };
    let message = Message::from_number(frame.message());
    let _ = match &message {
        Ok(m) => write!(text, "{}, message {m}, {direction}", frame.target()),
        Err(RequestError::UnusedMessage { .. }) => {
            write!(
                text,
                "{}, message {} (not used), {direction}",
                frame.target(),
                frame.message()
            )
        }
        Err(_) => write!(
            text,
            "{}, message {} (unknown), {direction}",
            frame.target(),
            frame.message()
        ),
    };
    let Ok(message) = message else {
        return describe_raw(text, frame);
    };
    let table = match message.kind() {
        MessageKind::Read(table) | MessageKind::Write(table) => table,
        MessageKind::SetAddress => {
            let _ = match frame.data().first() {
                Some(raw) => write!(text, ", new address {}", raw.get()),
                None => write!(text, ", no address given"),
            };
            return text;
        }
        MessageKind::Command(_) => return text,
    };
    let items: &'static [Item] = match frame.count() {
        Count::All => {
            text.push_str(", whole table");
            table.items()
        }
        Count::Item(index) => match table.item(index.get()) {
            Ok(item) => {
                let _ = write!(text, ", item {}", item.index());
                std::slice::from_ref(item)
            }
            Err(_) => {
                let _ = write!(text, ", item {} (beyond the {table} table)", index.get());
                return describe_raw(text, frame);
            }
        },
    };
    if frame.data().is_empty() {
        if let [item] = items {
            let _ = write!(text, " ({})", item.name());
        }
        return text;
    }
    if frame.data().len() != items.len() {
        let _ = write!(
            text,
            ", {} data item(s) where {} belong",
            frame.data().len(),
            items.len()
        );
        return describe_raw(text, frame);
    }
    for (i, (item, raw)) in items.iter().zip(frame.data()).enumerate() {
        text.push_str(if i == 0 { ": " } else { "; " });
        let reading = item.reading(*raw);
        let _ = write!(text, "{} = {reading}", item.name());
        if item.table() == Table::Runtime && item.index() == crate::tables::runtime::FAULT {
            let _ = write!(text, " ({})", crate::diagnostic::describe(raw.get()));
        }
    }
    text
}

fn describe_raw(mut text: String, frame: &Frame) -> String {
    if !frame.data().is_empty() {
        let raw: Vec<String> = frame.data().iter().map(ToString::to_string).collect();
        text.push_str(", data ");
        text.push_str(&raw.join(" "));
    }
    text
}

/// A request that cannot be built or understood.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RequestError {
    /// Message 13, which the spec lists as not used.
    #[error("message {number} is not used by Thermosald regulators")]
    UnusedMessage {
        /// The number (13).
        number: u8,
    },
    /// A message number the spec does not list.
    #[error("message {number:02} is not a Thermosald message (10-12, 14-18, 51-53, 58, 99)")]
    UnknownMessage {
        /// The number.
        number: u8,
    },
    /// A response where a question was expected.
    #[error("message {message} is a response ('R'), not a question ('Q')")]
    NotAQuery {
        /// The message.
        message: Message,
    },
    /// `$` with a message other than 10.
    #[error("address '$' is only for message 10 (write logic address), not {message}")]
    AssignOnlySetsAddress {
        /// The message.
        message: Message,
    },
    /// A write to the run-time table.
    #[error("{table} data is read-only")]
    ReadOnlyTable {
        /// The table.
        table: Table,
    },
    /// A write to an item the regulator keeps itself.
    #[error("{table} item {index} {item:?} is read-only")]
    ReadOnlyItem {
        /// The table.
        table: Table,
        /// The item's name.
        item: &'static str,
        /// The item's index.
        index: u8,
    },
    /// Raw digits outside an item's range.
    #[error("{table} item {item:?}: raw value {raw:03} is outside its range, {min:03} to {max:03}")]
    RawOutOfRange {
        /// The table.
        table: Table,
        /// The item's name.
        item: &'static str,
        /// The raw value given.
        raw: u16,
        /// The lowest raw value.
        min: u16,
        /// The highest raw value.
        max: u16,
    },
    /// The wrong number of data items.
    #[error("message {message} needs {expected} data item(s), got {actual}")]
    ItemCount {
        /// The message.
        message: Message,
        /// Items needed.
        expected: usize,
        /// Items given.
        actual: usize,
    },
    /// No such table or item.
    #[error(transparent)]
    Lookup(#[from] LookupError),
    /// A value that does not fit its item.
    #[error(transparent)]
    Value(#[from] ValueError),
    /// An address outside 0–7.
    #[error(transparent)]
    Address(#[from] AddressError),
}

/// Count `00`: data item 0.
const FIRST: crate::frame::ItemIndex = match crate::frame::ItemIndex::new(0) {
    Ok(index) => index,
    Err(_) => panic!("0 is a valid item index"),
};

fn raw_of(value: u8) -> RawValue {
    RawValue::saturating(f64::from(value))
}

fn check_writable_table(table: Table) -> Result<Message, RequestError> {
    table
        .write_message()
        .ok_or(RequestError::ReadOnlyTable { table })
}

fn check_raw(item: &'static Item, raw: RawValue) -> Result<(), RequestError> {
    if item.accepts(raw) {
        Ok(())
    } else {
        Err(RequestError::RawOutOfRange {
            table: item.table(),
            item: item.name(),
            raw: raw.get(),
            min: item.raw_min(),
            max: item.raw_max(),
        })
    }
}
