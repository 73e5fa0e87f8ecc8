//! Register lists in CSV (`registers_csv = "meter.csv"`), as vendors publish them:
//!
//! ```text
//! name,title,table,address,type,order,scale,offset,unit,writable_min,writable_max
//! voltage_l1,Voltage L1-N,input,0x0000,float32,CDAB,,,V,,
//! ```
//!
//! Columns in any order, `name` and `address` required, the others optional
//! (`deadband` and `deadband_percent` too); an empty cell takes the default; addresses are
//! decimal or `0x` hex; lines starting with `#` are comments. Each row becomes the same
//! [`RawRegister`] a `[[line.device.register]]` table does and is checked by the same code,
//! so the rules and words are the same; an error names the file, the row (its line in
//! the file, the header being row 1) and the column.
//!
//! The checks locate errors by a byte range in the TOML; here the range's start is the
//! number of the cell instead ([`CsvRegisters::error`] turns it back into row and column).

use std::ops::Range;
use std::path::{Path, PathBuf};

use jbus::data::{DataType, Order};
use toml::Spanned;

use serde::Deserialize;

use crate::config::ConfigError;
use crate::driver::modbus::{RegisterConfig, RegisterTable};
use crate::point::Deadband;

/// The columns a register list may have.
pub const COLUMNS: [&str; 13] = [
    "name",
    "title",
    "table",
    "address",
    "type",
    "order",
    "scale",
    "offset",
    "unit",
    "writable_min",
    "writable_max",
    "deadband",
    "deadband_percent",
];

/// The rows of a register list, and where each of their cells is.
pub(super) struct CsvRegisters {
    /// One per row.
    pub rows: Vec<RawRegister>,
    path: PathBuf,
    /// Per cell number (the start of a row field's span): its row and column.
    cells: Vec<(u64, &'static str)>,
}

impl CsvRegisters {
    /// Reads the rows of `text`, the contents of `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let mut table = Self {
            rows: Vec::new(),
            path: path.to_owned(),
            cells: Vec::new(),
        };
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let header = reader
            .headers()
            .map_err(|e| table.failed(row_of(&e), e.to_string()))?
            .clone();
        let mut columns: Vec<(usize, &'static str)> = Vec::new();
        for (index, title) in header.iter().enumerate() {
            let title = title.to_ascii_lowercase();
            let Some(known) = COLUMNS.iter().find(|c| **c == title) else {
                return Err(table.failed(
                    1,
                    format!(
                        "column {title:?} is not one cellbus knows; columns: {}",
                        COLUMNS.join(", ")
                    ),
                ));
            };
            if columns.iter().any(|(_, c)| c == known) {
                return Err(table.failed(1, format!("column {known:?} is there twice")));
            }
            columns.push((index, known));
        }
        for required in ["name", "address"] {
            if !columns.iter().any(|(_, c)| *c == required) {
                return Err(table.failed(
                    1,
                    format!(
                        "no column {required:?}: the header needs at least name and address (columns: {})",
                        COLUMNS.join(", ")
                    ),
                ));
            }
        }
        for record in reader.records() {
            let record = record.map_err(|e| table.failed(row_of(&e), e.to_string()))?;
            let row = record.position().map_or(0, csv::Position::line);
            let row_register = table.row(row, &record, &columns)?;
            table.rows.push(row_register);
        }
        Ok(table)
    }

    /// The error for a check that failed at `span` (a cell number).
    pub fn error(&self, span: Range<usize>, message: String) -> ConfigError {
        match self.cells.get(span.start) {
            Some(&(row, column)) => self.failed(row, format!("column {column:?}: {message}")),
            None => self.failed(0, message),
        }
    }

    fn failed(&self, row: u64, message: String) -> ConfigError {
        ConfigError::Csv {
            path: self.path.clone(),
            row,
            message,
        }
    }

    /// A cell's value with its cell number as span; `None` when empty.
    fn cell(
        &mut self,
        row: u64,
        record: &csv::StringRecord,
        columns: &[(usize, &'static str)],
        column: &'static str,
    ) -> Option<Spanned<String>> {
        let (index, _) = columns.iter().find(|(_, c)| *c == column)?;
        let text = record.get(*index).filter(|t| !t.is_empty())?;
        let id = self.cells.len();
        self.cells.push((row, column));
        Some(Spanned::new(id..id, text.to_owned()))
    }

    fn row(
        &mut self,
        row: u64,
        record: &csv::StringRecord,
        columns: &[(usize, &'static str)],
    ) -> Result<RawRegister, ConfigError> {
        let mut cell = |column| self.cell(row, record, columns, column);
        let name = cell("name");
        let title = cell("title");
        let table = cell("table");
        let address = cell("address");
        let data_type = cell("type");
        let order = cell("order");
        let scale = cell("scale");
        let offset = cell("offset");
        let unit = cell("unit");
        let writable_min = cell("writable_min");
        let writable_max = cell("writable_max");
        let deadband = cell("deadband");
        let deadband_percent = cell("deadband_percent");
        let name = name.ok_or_else(|| {
            self.failed(
                row,
                "column \"name\": empty; every register needs a name".into(),
            )
        })?;
        let address = address.ok_or_else(|| {
            self.failed(
                row,
                "column \"address\": empty; every register needs its address".into(),
            )
        })?;
        let address = self.parsed(
            &address,
            parse_address,
            "an address: write decimal (256) or hex (0x0100)",
        )?;
        let number = |s: &Spanned<String>| self.parsed(s, |t| t.parse::<f64>().ok(), "a number");
        let scale = scale.as_ref().map(number).transpose()?;
        let offset = offset.as_ref().map(number).transpose()?;
        let deadband = deadband.as_ref().map(number).transpose()?;
        let deadband_percent = deadband_percent.as_ref().map(number).transpose()?;
        let min = writable_min.as_ref().map(number).transpose()?;
        let max = writable_max.as_ref().map(number).transpose()?;
        let writable = match (min, max) {
            (None, None) => None,
            (Some(min), Some(max)) => Some(Spanned::new(
                min.span(),
                RawWritable::Range(RawRange {
                    min: *min.get_ref(),
                    max: *max.get_ref(),
                }),
            )),
            (Some(one), None) | (None, Some(one)) => {
                return Err(self.error(
                    one.span(),
                    "writable_min and writable_max go together (0 and 1 for a coil)".into(),
                ));
            }
        };
        Ok(RawRegister {
            name,
            title: title.map(Spanned::into_inner),
            table,
            address,
            data_type,
            order,
            scale,
            offset,
            unit: unit.map(Spanned::into_inner),
            signed: None,
            writable,
            deadband,
            deadband_percent,
        })
    }

    fn parsed<T>(
        &self,
        cell: &Spanned<String>,
        parse: impl Fn(&str) -> Option<T>,
        what: &str,
    ) -> Result<Spanned<T>, ConfigError> {
        parse(cell.get_ref())
            .map(|value| Spanned::new(cell.span(), value))
            .ok_or_else(|| self.error(cell.span(), format!("{:?} is not {what}", cell.get_ref())))
    }
}

/// An address in decimal or `0x` hex (range checked later, naming the register).
fn parse_address(text: &str) -> Option<i64> {
    match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => i64::from_str_radix(hex, 16).ok(),
        None => text.parse().ok(),
    }
}

fn row_of(error: &csv::Error) -> u64 {
    error.position().map_or(0, csv::Position::line)
}

/// `registers` as `[[line.device.register]]` tables, leaving out what is the default.
pub fn to_toml(registers: &[RegisterConfig]) -> String {
    let quote = |text: &str| toml::Value::String(text.to_owned()).to_string();
    let mut out = String::new();
    for (index, r) in registers.iter().enumerate() {
        if index > 0 {
            out.push('\n');
        }
        out.push_str("[[line.device.register]]\n");
        out.push_str(&format!("name = {}\n", quote(&r.name)));
        if r.title != r.name {
            out.push_str(&format!("title = {}\n", quote(&r.title)));
        }
        if r.table != RegisterTable::Holding {
            out.push_str(&format!("table = {}\n", quote(r.table.as_str())));
        }
        out.push_str(&format!("address = 0x{:04X}\n", r.address));
        let format = r.format;
        if !r.table.holds_bits() {
            if format.data_type != DataType::Uint16 {
                out.push_str(&format!(
                    "type = {}\n",
                    quote(&format.data_type.to_string())
                ));
            }
            if format.order != Order::default() {
                out.push_str(&format!("order = {}\n", quote(&format.order.to_string())));
            }
            if format.scaling.scale() != 1.0 {
                out.push_str(&format!("scale = {}\n", float(format.scaling.scale())));
            }
            if format.scaling.offset() != 0.0 {
                out.push_str(&format!("offset = {}\n", float(format.scaling.offset())));
            }
        }
        if let Some(unit) = &r.unit {
            out.push_str(&format!("unit = {}\n", quote(unit)));
        }
        match r.writable {
            Some(_) if r.is_bool() => out.push_str("writable = true\n"),
            Some((min, max)) => out.push_str(&format!(
                "writable = {{ min = {}, max = {} }}\n",
                float(min),
                float(max)
            )),
            None => {}
        }
        match r.deadband {
            Some(Deadband::Absolute(band)) => {
                out.push_str(&format!("deadband = {}\n", float(band)));
            }
            Some(Deadband::Percent(percent)) => {
                out.push_str(&format!("deadband_percent = {}\n", float(percent)));
            }
            None => {}
        }
    }
    out
}

/// A float as TOML writes it (`1.0`, not `1`, so it reads back as a float).
fn float(value: f64) -> String {
    toml::Value::Float(value).to_string()
}

/// One register as a `[[line.device.register]]` table or a row of the CSV gives it,
/// before its checks (`super::config`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRegister {
    pub(super) name: Spanned<String>,
    pub(super) title: Option<String>,
    pub(super) table: Option<Spanned<String>>,
    pub(super) address: Spanned<i64>,
    #[serde(rename = "type")]
    pub(super) data_type: Option<Spanned<String>>,
    pub(super) order: Option<Spanned<String>>,
    pub(super) scale: Option<Spanned<f64>>,
    pub(super) offset: Option<Spanned<f64>>,
    pub(super) unit: Option<String>,
    pub(super) signed: Option<Spanned<bool>>,
    pub(super) writable: Option<Spanned<RawWritable>>,
    pub(super) deadband: Option<Spanned<f64>>,
    pub(super) deadband_percent: Option<Spanned<f64>>,
}

/// `writable = true`, or `writable = { min = …, max = … }`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub(super) enum RawWritable {
    Flag(bool),
    Range(RawRange),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawRange {
    pub(super) min: f64,
    pub(super) max: f64,
}
