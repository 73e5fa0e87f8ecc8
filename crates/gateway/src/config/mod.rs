//! The cell's configuration (TOML): lines, the devices on them, and how often to poll.
//!
//! ```toml
//! token = "change-me"                   # optional; CELLBUS_TOKEN and --token win over it
//! read_token = "look-only"              # optional; then every API route needs it (or the
//!                                       # write token); CELLBUS_READ_TOKEN wins over it
//!
//! [[line]]
//! name = "rework"                       # unique; a-z, 0-9, _ and -
//! endpoint = "serial:///dev/ttyUSB0?baud=19200&framing=8E1"
//! reopen_after_timeouts = 3             # every device timed out this often in a row:
//!                                       # close and reopen the line (0: never)
//!
//! [[line.device]]
//! id = "jbc1"                           # unique in the cell; used in URLs and point ids
//! name = "Rework station 1"             # words for people (default: the id)
//! protocol = "jbc"
//! address = 1                           # what the kind accepts (its check_address)
//! timeout = "500ms"                     # per reply (the kind's default if left out)
//! retries = 2                           # after a failed attempt (the kind's default)
//! period = "2s"                         # for every poll group not listed in [poll]
//! poll = { live = "1s", info = "5m" }   # per poll group
//! deadband = 0.5                        # or deadband_percent: numeric points' default
//! ```
//!
//! A kind's own keys (a Modbus device's registers, a Panasonic machine's `event_port`) are
//! described in its module under `driver`, an interface's table under `northbound`.
//!
//! The interfaces' tables (`[mqtt]`, `[opcua]`) and the keys only one device kind takes
//! are read by their owners, beside their code, through
//! [`Plugins`]: this module names no protocol and no interface, and builds no driver.
//! Their common ground (errors, [`Table`], [`Settings`]) is [`table`].
//!
//! Every table refuses fields it does not know. A file that does not parse or does not make
//! sense is refused whole, with the file, line and column and what is wrong
//! ([`ConfigError`]). [`EXAMPLE_CONFIG`] is a commented example for a real cell.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use link::Endpoint;
use serde::Deserialize;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::driver::{DeviceContext, DriverConfig, Kind};
use crate::point::{Deadband, DeviceId};

pub mod table;
#[cfg(test)]
mod tests;

pub use table::{ConfigError, MAX_CONFIG, Scratch, Settings, Table, bounded, duration};
use table::{locate, plain_toml_message, read_text};

/// An example configuration for a real cell (`cellbus config example` prints it); the
/// same file is `crates/gateway/examples/cell.toml`.
pub const EXAMPLE_CONFIG: &str = include_str!("../../examples/cell.toml");

/// Shortest poll period accepted.
pub const MIN_PERIOD: Duration = Duration::from_millis(50);
/// Longest poll period accepted.
pub const MAX_PERIOD: Duration = Duration::from_secs(24 * 3600);
/// Longest reply timeout accepted.
pub const MAX_TIMEOUT: Duration = Duration::from_secs(60);
/// Most retries accepted.
pub const MAX_RETRIES: u8 = 10;
/// A line is closed and reopened when every device on it has timed out this many times in
/// a row (a serial server's session or an adapter can hang while the devices are fine).
pub const DEFAULT_REOPEN_AFTER_TIMEOUTS: u32 = 3;
/// Largest `reopen_after_timeouts` accepted.
pub const MAX_REOPEN_AFTER_TIMEOUTS: u32 = 1000;

/// A checked configuration (the default: no file, no lines).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CellConfig {
    /// The file it came from, if any (the demo cell has none).
    pub source: Option<PathBuf>,
    /// The token writes need, if the file sets one.
    pub token: Option<String>,
    /// The token every API route needs, if the file sets one.
    pub read_token: Option<String>,
    /// The lines, in file order.
    pub lines: Vec<LineConfig>,
    /// What the interfaces read from their tables (`[mqtt]`, `[opcua]`), by table name.
    pub interfaces: BTreeMap<&'static str, Settings>,
    /// The shifts (`[[shift]]`) in the cell's `time_zone`.
    pub shifts: crate::production::Shifts,
    /// The limit alarms (`[[alarm]]`).
    pub alarms: Vec<crate::alarm::config::AlarmConfig>,
}

impl CellConfig {
    /// The settings an interface read from its table, if the file has the table.
    pub fn interface<T: std::any::Any>(&self, table: &str) -> Option<&T> {
        self.interfaces.get(table).and_then(Settings::get)
    }

    /// What the file allows but is likely a mistake, one sentence each, naming the device,
    /// as each device kind sees its devices ([`crate::driver::DeviceKind::warnings`]):
    /// Modbus registers that share a register.
    pub fn warnings(&self) -> Vec<String> {
        let mut kinds: Vec<(Kind, Vec<&DriverConfig>)> = Vec::new();
        for device in self.lines.iter().flat_map(|line| &line.devices) {
            let driver = &device.driver;
            match kinds.iter_mut().find(|(kind, _)| *kind == driver.protocol) {
                Some((_, devices)) => devices.push(driver),
                None => kinds.push((driver.protocol, vec![driver])),
            }
        }
        kinds
            .into_iter()
            .flat_map(|(kind, devices)| kind.warnings(&devices))
            .collect()
    }

    /// The serial ports the file names that are not there now, one sentence each: an
    /// adapter unplugged, or a path mistyped. `serve` starts anyway and keeps trying to
    /// open them, so `cellbus config check` warns (a USB adapter may be plugged in later).
    pub fn absent_ports(&self) -> Vec<String> {
        self.lines
            .iter()
            .filter_map(|line| match &line.endpoint {
                Endpoint::Serial { path, .. } if !Path::new(path).exists() => Some(format!(
                    "line {}: serial port {path} is not there now (`ls /dev/serial/by-id` lists the adapters plugged in); `cellbus serve` will keep trying to open it",
                    line.name
                )),
                _ => None,
            })
            .collect()
    }
}

/// Reads one top-level table of the file that belongs to an interface (`[mqtt]`), beside
/// the interface's code.
pub trait TableReader: Sync {
    /// The table's name (`mqtt`).
    fn table(&self) -> &'static str;

    /// Reads and checks the table.
    fn read(&self, table: &Table<'_>) -> Result<Settings, ConfigError>;

    /// The environment variables what it read names and `serve` will read (a password's
    /// `password_env`), each with its key: [`check_config`] refuses a file whose variables
    /// are not set where it runs.
    fn environment(&self, _settings: &Settings) -> Vec<(&'static str, String)> {
        Vec::new()
    }

    /// What it read, in a few words for `cellbus config check`'s summary
    /// (`sparkplug to mqtt://broker:1883 as cellbus/line1`).
    fn summary(&self, _settings: &Settings) -> String {
        String::new()
    }
}

/// What a file may name: the device kinds (`protocol = "…"`) and the interfaces' tables.
/// `crate::plugins::builtin` lists the gateway's own; a build adds the interfaces of other
/// crates, and a test may add a kind of its own.
#[derive(Clone, Default)]
pub struct Plugins {
    kinds: Vec<Kind>,
    tables: Vec<&'static dyn TableReader>,
    /// Tables of interfaces this build was made without, each with why a file naming it
    /// is refused.
    left_out: Vec<(&'static str, &'static str)>,
}

impl Plugins {
    /// With the device kind `kind`.
    pub fn with_kind(mut self, kind: Kind) -> Self {
        self.kinds.push(kind);
        self
    }

    /// With the interface table `reader` reads.
    pub fn with_table(mut self, reader: &'static dyn TableReader) -> Self {
        self.tables.push(reader);
        self
    }

    /// With the table `table` of an interface this build was made without: a file that
    /// names it is refused where the table is, with `why` ("this build has no OPC UA
    /// interface …") instead of the words for a table nobody knows.
    pub fn with_table_left_out(mut self, table: &'static str, why: &'static str) -> Self {
        self.left_out.push((table, why));
        self
    }

    /// The kind named `name` in the config.
    pub fn kind(&self, name: &str) -> Option<Kind> {
        self.kinds.iter().copied().find(|k| k.name() == name)
    }

    /// Every kind, in the order they were added.
    pub fn kinds(&self) -> &[Kind] {
        &self.kinds
    }

    fn protocol_of(&self, text: &Spanned<String>) -> Result<Kind, String> {
        self.kind(text.get_ref()).ok_or_else(|| {
            format!(
                "protocol {:?} is not one the gateway speaks; known: {}",
                text.get_ref(),
                self.kinds
                    .iter()
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
    }

    /// Each interface table of `config`, with what it says in a few words
    /// ([`TableReader::summary`]), in table order.
    pub fn interfaces_of(&self, config: &CellConfig) -> Vec<(&'static str, String)> {
        config
            .interfaces
            .iter()
            .map(|(table, settings)| {
                let words = self
                    .reader(table)
                    .map(|r| r.summary(settings))
                    .unwrap_or_default();
                (*table, words)
            })
            .collect()
    }

    fn reader(&self, table: &str) -> Option<&'static dyn TableReader> {
        self.tables.iter().copied().find(|r| r.table() == table)
    }

    /// Why the table `table` is refused, if this build was made without its interface.
    fn left_out(&self, table: &str) -> Option<&'static str> {
        self.left_out
            .iter()
            .find(|(name, _)| *name == table)
            .map(|(_, why)| *why)
    }
}

impl fmt::Debug for Plugins {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Plugins")
            .field("kinds", &self.kinds)
            .field(
                "tables",
                &self.tables.iter().map(|t| t.table()).collect::<Vec<_>>(),
            )
            .field(
                "left_out",
                &self.left_out.iter().map(|(t, _)| t).collect::<Vec<_>>(),
            )
            .finish()
    }
}

/// One physical line (a serial port, a serial server's TCP port).
#[derive(Debug, Clone, PartialEq)]
pub struct LineConfig {
    /// Its name (`bench-a`), unique.
    pub name: String,
    /// Where it is.
    pub endpoint: Endpoint,
    /// The devices on it, polled in turn.
    pub devices: Vec<DeviceConfig>,
    /// Close and reopen the line when every device on it has timed out this many times in
    /// a row (0: never).
    pub reopen_after_timeouts: u32,
}

impl LineConfig {
    /// Whether the line's device keeps its own connections
    /// ([`DeviceKind::owns_connections`](crate::driver::DeviceKind::owns_connections)): the
    /// line itself then carries nothing.
    pub fn owns_connections(&self) -> bool {
        self.devices
            .first()
            .is_some_and(|d| d.driver.protocol.owns_connections().is_some())
    }
}

/// One device on a line.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceConfig {
    /// What its driver needs.
    pub driver: DriverConfig,
    /// Words for people (`Rework station 1`).
    pub name: String,
    /// Period for every group not named in `groups`.
    pub period: Option<Duration>,
    /// Periods of named poll groups.
    pub groups: BTreeMap<String, Duration>,
    /// Deadband of its numeric points that name none of their own (`deadband` or
    /// `deadband_percent` in the device table).
    pub deadband: Option<Deadband>,
    /// Its `[line.device.production]` settings, for a kind that produces.
    pub production: Option<crate::production::ProductionSettings>,
}

impl DeviceConfig {
    /// The device `driver` describes, called `name`, polled at its groups' default periods,
    /// without a deadband.
    pub fn new(driver: DriverConfig, name: impl Into<String>) -> Self {
        Self {
            driver,
            name: name.into(),
            period: None,
            groups: BTreeMap::new(),
            deadband: None,
            production: None,
        }
    }

    /// How often `group` (its driver's default period) is read: the config's period for it
    /// by name, else the device's `period`, else the default.
    pub fn period_of(&self, group: &crate::driver::PollGroup) -> Duration {
        self.groups
            .get(&group.name)
            .copied()
            .or(self.period)
            .unwrap_or(group.period)
    }
}

/// What is wrong with `token` as a bearer token, if anything: clients send it in an HTTP
/// header, which carries visible ASCII only (a token with `ä` or a space could be set but
/// never sent). The words name the character's position, never the character: a token is
/// a secret.
pub fn token_fault(token: &str) -> Option<String> {
    let at = token.chars().position(|c| !c.is_ascii_graphic())?;
    Some(format!(
        "character {} is not visible ASCII; a token is sent in an HTTP header, so use \
         letters, digits and punctuation only, no spaces",
        at + 1
    ))
}

/// Why a read token equal to the write token is refused.
pub const SAME_TOKENS: &str = "the read token is the write token, so everyone who may \
     read could also write; give readers a token of their own, or no read token";

/// Device ids the gateway's own objects use: the OPC UA node ids of the `Cell` folder and
/// the `Gateway` object, and the source of the gateway's own events.
pub const RESERVED_DEVICE_IDS: [&str; 2] = ["cell", "gateway"];

/// Reads and checks the configuration at `path`, whose device kinds and interface tables
/// are those of `plugins`.
///
/// Beyond [`parse_config`], it checks what `serve` will need from where it runs: every
/// environment variable the file names is set (`config check` then means `serve` will
/// start, when both run with the same environment, as a service unit's `ExecStartPre`
/// does).
pub fn check_config(path: &Path, plugins: &Plugins) -> Result<CellConfig, ConfigError> {
    let text = read_text(path)?;
    let config = parse_config(&text, path, plugins)?;
    let mut errors = Vec::new();
    for (table, settings) in &config.interfaces {
        let Some(reader) = plugins.reader(table) else {
            continue;
        };
        for (key, var) in reader.environment(settings) {
            if std::env::var_os(&var).is_some_and(|v| !v.is_empty()) {
                continue;
            }
            // Where the file names it: the variable's name, quoted, else the table.
            let span = text
                .find(&format!("\"{var}\""))
                .or_else(|| text.find(&format!("[{table}")))
                .map_or(0..0, |at| at..at + var.len());
            errors.push(locate(
                &text,
                path,
                span,
                format!(
                    "{key} names the environment variable {var}, which is not set here; `cellbus serve` reads it at start: set it (a service unit's EnvironmentFile), or remove {key}"
                ),
            ));
        }
    }
    match ConfigError::all(errors) {
        Some(error) => Err(error),
        None => Ok(config),
    }
}

/// The keys of the file's top level that are the cell's own.
const CELL_KEYS: [&str; 6] = ["token", "read_token", "time_zone", "shift", "line", "alarm"];

/// The keys every `[[line.device]]` takes, whatever its kind.
const DEVICE_KEYS: [&str; 12] = [
    "id",
    "name",
    "protocol",
    "address",
    "timeout",
    "retries",
    "period",
    "poll",
    "deadband",
    "deadband_percent",
    "states",
    "production",
];

/// Checks configuration text; `path` names it in errors.
pub fn parse_config(text: &str, path: &Path, plugins: &Plugins) -> Result<CellConfig, ConfigError> {
    let at = |span: Range<usize>, message: String| locate(text, path, span, message);
    let toml_error =
        |e: toml::de::Error| at(e.span().unwrap_or(0..0), plain_toml_message(e.message()));
    // Parsed once into toml's own tree, every key with its place: the cell's keys are read
    // from it into its serde types; the tables the cell does not read itself go to their
    // owners (an interface, a device kind) from here.
    let document = DeTable::parse(text).map_err(toml_error)?;
    let whole = document.span();
    let mut tree = document.into_inner();
    let raw = RawConfig::deserialize(toml::de::Deserializer::from(Spanned::new(
        whole,
        tree.clone(),
    )))
    .map_err(toml_error)?;
    // Every mistake of the file in one run: each line, device, token and interface table
    // is checked on its own, and what one gets wrong does not hide the next (a device's
    // own checks stop at its first mistake).
    let mut errors = Vec::new();
    let mut interface_tables = Vec::new();
    for (key, value) in std::mem::take(&mut tree) {
        if CELL_KEYS.contains(&key.get_ref().as_ref()) {
            tree.insert(key, value);
            continue;
        }
        let Some(reader) = plugins.reader(key.get_ref()) else {
            if let Some(why) = plugins.left_out(key.get_ref()) {
                errors.push(at(key.span(), why.to_owned()));
                continue;
            }
            let expected: Vec<&str> = CELL_KEYS
                .into_iter()
                .chain(plugins.tables.iter().map(|t| t.table()))
                .collect();
            errors.push(at(key.span(), unknown_field(key.get_ref(), &expected)));
            continue;
        };
        interface_tables.push((reader, value));
    }
    let mut device_tables = device_tables(tree, plugins, &at, &mut errors);
    if raw.line.is_empty() {
        errors.push(at(
            0..0,
            "no [[line]]: a cell needs at least one line with a device on it (see `cellbus config example`)"
                .into(),
        ));
    }
    let mut lines = Vec::new();
    let mut seen = Seen::default();
    for line in raw.line {
        let count = line.device.len();
        let own: Vec<_> = device_tables.by_ref().take(count).collect();
        if let Some(line) = check_line(
            line,
            own,
            (text, path),
            plugins,
            &mut seen,
            &at,
            &mut errors,
        ) {
            lines.push(line);
        }
    }
    for (key, token) in [("token", &raw.token), ("read_token", &raw.read_token)] {
        if let Some(token) = token
            && token.get_ref().trim().is_empty()
        {
            errors.push(at(
                token.span(),
                format!("{key} is empty; remove it or set a secret"),
            ));
        } else if let Some(token) = token
            && let Some(fault) = token_fault(token.get_ref().trim())
        {
            errors.push(at(token.span(), format!("{key} cannot be used: {fault}")));
        }
    }
    if let (Some(token), Some(read_token)) = (&raw.token, &raw.read_token)
        && token.get_ref().trim() == read_token.get_ref().trim()
    {
        errors.push(at(
            read_token.span(),
            format!("read_token cannot be used: {SAME_TOKENS}"),
        ));
    }
    let mut interfaces = BTreeMap::new();
    for (reader, value) in interface_tables {
        match reader.read(&Table::new(text, path, value)) {
            Ok(settings) => {
                interfaces.insert(reader.table(), settings);
            }
            Err(e) => errors.push(e),
        }
    }
    let shifts = crate::production::config::read_shifts(
        raw.time_zone.as_ref(),
        &raw.shift,
        &at,
        &mut errors,
    );
    let device_ids: HashSet<&str> = lines
        .iter()
        .flat_map(|l: &LineConfig| &l.devices)
        .map(|d| d.driver.id.as_str())
        .collect();
    for device in lines.iter().flat_map(|l| &l.devices) {
        if let Some(good) = device
            .production
            .as_ref()
            .and_then(|p| p.good_boards.as_ref())
            && !device_ids.contains(good.device())
        {
            errors.push(at(
                0..0,
                format!(
                    "device {}: good_boards names {good}, but the cell has no device {:?}",
                    device.driver.id,
                    good.device()
                ),
            ));
        }
    }
    let points_of = |device: &str| {
        lines
            .iter()
            .flat_map(|l: &LineConfig| &l.devices)
            .find(|d| d.driver.id.as_str() == device)
            .map(|d| d.driver.build().map(|driver| driver.points()))
    };
    let alarms = crate::alarm::config::read_alarms(raw.alarm, &points_of, &at, &mut errors);
    if let Some(error) = ConfigError::all(errors) {
        return Err(error);
    }
    Ok(CellConfig {
        shifts,
        alarms,
        source: Some(path.to_owned()),
        token: raw.token.map(Spanned::into_inner),
        read_token: raw.read_token.map(Spanned::into_inner),
        lines,
        interfaces,
    })
}

/// What the lines checked so far hold: names, serial ports and device ids are each the
/// file's once.
#[derive(Default)]
struct Seen {
    line_names: HashSet<String>,
    /// The serial port each line holds, with the line's name: one port carries one line.
    ports: HashMap<String, String>,
    device_ids: HashSet<String>,
    scratch: Scratch,
}

/// One line and its devices (`own`: each device's place and kind keys); its mistakes go to
/// `errors`. `None` when the line itself is wrong (its devices are then not checked: their
/// defaults depend on it); a wrong device is left out and the others checked.
fn check_line(
    line: RawLine,
    own: Vec<(Range<usize>, DeTable<'_>)>,
    (text, path): (&str, &Path),
    plugins: &Plugins,
    seen: &mut Seen,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
    errors: &mut Vec<ConfigError>,
) -> Option<LineConfig> {
    let fail = |errors: &mut Vec<ConfigError>, span: Range<usize>, message: String| {
        errors.push(at(span, message));
        None
    };
    let name = line.name.get_ref();
    if let Err(e) = DeviceId::new(name) {
        return fail(
            errors,
            line.name.span(),
            format!("line name {name:?} is not valid: {}", e.rule),
        );
    }
    if !seen.line_names.insert(name.clone()) {
        return fail(
            errors,
            line.name.span(),
            format!("line name {name:?} is used twice"),
        );
    }
    let Some(first) = line.device.first() else {
        return fail(
            errors,
            line.name.span(),
            format!("line {name:?} has no devices; add a [[line.device]] under it"),
        );
    };
    let protocol = match plugins.protocol_of(&first.protocol) {
        Ok(protocol) => protocol,
        Err(m) => return fail(errors, first.protocol.span(), m),
    };
    let endpoint = match Endpoint::parse(line.endpoint.get_ref(), protocol.default_serial()) {
        Ok(endpoint) => endpoint,
        Err(e) => return fail(errors, line.endpoint.span(), e.to_string()),
    };
    if let Endpoint::Tcp { port: 0, .. } = endpoint {
        return fail(
            errors,
            line.endpoint.span(),
            "port 0 is not a port a device listens on; give the serial server's or the device's port".into(),
        );
    }
    if let Endpoint::Serial { path, .. } = &endpoint
        && let Some(first) = seen.ports.insert(path.clone(), name.clone())
    {
        return fail(
            errors,
            line.endpoint.span(),
            format!(
                "line {name:?} is on serial port {path}, as line {first:?} is: two lines on \
                 one port would interleave their requests; put the devices of both on one line"
            ),
        );
    }
    if endpoint.is_mbap() && !protocol.speaks_modbus() {
        // The generic Modbus kind (it plans its reads) first, then the devices that
        // speak Modbus with a map of their own.
        let mut modbus: Vec<Kind> = plugins
            .kinds
            .iter()
            .copied()
            .filter(|k| k.speaks_modbus())
            .collect();
        modbus.sort_by_key(|k| !k.plans_reads());
        let modbus: Vec<&str> = modbus.iter().map(|k| k.name()).collect();
        return fail(
            errors,
            line.endpoint.span(),
            format!(
                "modbus-tcp:// is for Modbus devices ({}); a {protocol} line is serial:// or tcp://",
                modbus.join(", ")
            ),
        );
    }
    if let Some(how) = protocol.owns_connections()
        && !matches!(endpoint, Endpoint::Tcp { .. })
    {
        return fail(
            errors,
            line.endpoint.span(),
            format!("a {protocol} machine is reached over TCP: write {how}"),
        );
    }
    let reopen_after_timeouts = match &line.reopen_after_timeouts {
        None => DEFAULT_REOPEN_AFTER_TIMEOUTS,
        Some(k) => match u32::try_from(*k.get_ref())
            .ok()
            .filter(|k| *k <= MAX_REOPEN_AFTER_TIMEOUTS)
        {
            Some(k) => k,
            None => {
                return fail(
                    errors,
                    k.span(),
                    format!(
                        "reopen_after_timeouts {} is out of range: 0 (never) to {MAX_REOPEN_AFTER_TIMEOUTS}",
                        k.get_ref()
                    ),
                );
            }
        },
    };
    let device_count = line.device.len();
    let mut devices = Vec::new();
    let mut addresses = HashSet::new();
    let mut own = own.into_iter();
    for device in line.device {
        let own = own.next().unwrap_or_default();
        let this = match plugins.protocol_of(&device.protocol) {
            Ok(this) => this,
            Err(m) => {
                errors.push(at(device.protocol.span(), m));
                continue;
            }
        };
        if this != protocol && !(this.speaks_modbus() && protocol.speaks_modbus()) {
            errors.push(at(
                device.protocol.span(),
                format!(
                    "line {name:?} carries {protocol} devices; a {this} device needs a line of its own"
                ),
            ));
            continue;
        }
        let id_span = device.id.span();
        // Counted before the device's own checks, so a wrong device's id is still taken.
        if !seen.device_ids.insert(device.id.get_ref().clone()) {
            errors.push(at(
                id_span,
                format!("device id {:?} is used twice", device.id.get_ref()),
            ));
            continue;
        }
        let address_span = device
            .address
            .as_ref()
            .map_or(id_span.clone(), Spanned::span);
        let device = match check_device(
            device,
            this,
            &endpoint,
            (text, path),
            own,
            plugins,
            &mut seen.scratch,
            at,
        ) {
            Ok(device) => device,
            Err(e) => {
                errors.push(e);
                continue;
            }
        };
        if let Some(address) = device.driver.address
            && !addresses.insert(address)
        {
            errors.push(at(
                address_span,
                format!(
                    "address {address} is used twice on line {name:?}: both devices would answer the same requests"
                ),
            ));
            continue;
        }
        devices.push(device);
    }
    if protocol.owns_connections().is_some() && device_count > 1 {
        let second = devices.get(1).map_or(String::new(), |d| {
            format!(" (device {:?})", d.driver.id.as_str())
        });
        return fail(
            errors,
            line.name.span(),
            format!(
                "line {name:?} has {device_count} {protocol} machines: each machine is its own TCP server and needs a [[line]] of its own{second}"
            ),
        );
    }
    Some(LineConfig {
        name: name.clone(),
        endpoint,
        devices,
        reopen_after_timeouts,
    })
}

/// serde's words for a key a table does not take.
fn unknown_field(key: &str, expected: &[&str]) -> String {
    let expected: Vec<String> = expected.iter().map(|k| format!("`{k}`")).collect();
    format!(
        "unknown field `{key}`, expected one of {}",
        expected.join(", ")
    )
}

/// The keys of each `[[line.device]]` that are not [`DEVICE_KEYS`], in file order (the
/// order `toml` reads the devices in); a key no kind takes is refused here, where serde
/// would have refused it.
fn device_tables<'a>(
    tree: DeTable<'a>,
    plugins: &Plugins,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
    errors: &mut Vec<ConfigError>,
) -> std::vec::IntoIter<(Range<usize>, DeTable<'a>)> {
    let mut found = Vec::new();
    let tables = |value: Spanned<DeValue<'a>>| -> Vec<Spanned<DeValue<'a>>> {
        match value.into_inner() {
            DeValue::Array(items) => items.into_iter().collect(),
            _ => Vec::new(),
        }
    };
    for (key, lines) in tree {
        if key.get_ref() != "line" {
            continue;
        }
        for line in tables(lines) {
            let DeValue::Table(line) = line.into_inner() else {
                continue;
            };
            for (key, devices) in line {
                if key.get_ref() != "device" {
                    continue;
                }
                for device in tables(devices) {
                    let span = device.span();
                    let DeValue::Table(device) = device.into_inner() else {
                        continue;
                    };
                    let mut own = DeTable::default();
                    for (key, value) in device {
                        let name = key.get_ref().as_ref();
                        if DEVICE_KEYS.contains(&name) {
                            continue;
                        }
                        if !plugins.kinds.iter().any(|k| k.keys().contains(&name)) {
                            let mut expected = DEVICE_KEYS.to_vec();
                            for key in plugins.kinds.iter().flat_map(|k| k.keys()) {
                                if !expected.contains(key) {
                                    expected.push(key);
                                }
                            }
                            errors.push(at(key.span(), unknown_field(name, &expected)));
                            continue;
                        }
                        own.insert(key, value);
                    }
                    found.push((span, own));
                }
            }
        }
    }
    found.into_iter()
}

/// One device: the keys every device has, checked here, and its kind's own keys (`own`,
/// where the device is in the file and its keys beyond [`DEVICE_KEYS`]), read by the kind.
#[expect(
    clippy::too_many_arguments,
    reason = "the reading's whole context, passed down once"
)]
fn check_device(
    raw: RawDevice,
    protocol: Kind,
    endpoint: &Endpoint,
    (text, path): (&str, &Path),
    own: (Range<usize>, DeTable<'_>),
    plugins: &Plugins,
    scratch: &mut Scratch,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<DeviceConfig, ConfigError> {
    let id = DeviceId::new(raw.id.get_ref()).map_err(|e| {
        at(
            raw.id.span(),
            format!("device id {:?} is not valid: {}", raw.id.get_ref(), e.rule),
        )
    })?;
    if RESERVED_DEVICE_IDS.contains(&id.as_str()) {
        return Err(at(
            raw.id.span(),
            format!(
                "device id {:?} is taken by the gateway's own objects (the OPC UA server's \
                 Cell folder and Gateway object, the gateway's events); choose another",
                id.as_str()
            ),
        ));
    }
    let address = match &raw.address {
        None => protocol.default_address(),
        Some(spanned) => match spanned.get_ref() {
            RawAddress::Number(n) => Some(*n),
            RawAddress::Text(t) if t == "none" => None,
            RawAddress::Text(t) => {
                return Err(at(
                    spanned.span(),
                    format!("address {t:?} is not a number; write a number or \"none\""),
                ));
            }
        },
    };
    if let Err(message) = protocol.check_address(address) {
        let span = raw.address.as_ref().map_or(raw.id.span(), Spanned::span);
        return Err(at(span, message));
    }
    let timeout = raw
        .timeout
        .as_ref()
        .map(|t| duration(t, Duration::from_millis(1), MAX_TIMEOUT, "timeout", at))
        .transpose()?;
    let retries = raw
        .retries
        .as_ref()
        .map(|r| match u8::try_from(*r.get_ref()) {
            Ok(n) if n <= MAX_RETRIES => Ok(n),
            _ => Err(at(
                r.span(),
                format!(
                    "retries {} is out of range: 0 to {MAX_RETRIES}",
                    r.get_ref()
                ),
            )),
        })
        .transpose()?;
    let period = raw
        .period
        .as_ref()
        .map(|p| duration(p, MIN_PERIOD, MAX_PERIOD, "period", at))
        .transpose()?;
    let deadband = check_deadband(&raw.deadband, &raw.deadband_percent, at)?;
    let (device_span, keys) = own;
    let mut mine = DeTable::default();
    for (key, value) in keys {
        if protocol.keys().contains(&key.get_ref().as_ref()) {
            mine.insert(key, value);
            continue;
        }
        let owner = plugins
            .kinds
            .iter()
            .find(|k| k.keys().contains(&key.get_ref().as_ref()))
            .expect("device_tables keeps only keys some kind takes");
        let (span, message) = owner.foreign_key(key.get_ref(), &value, protocol.name());
        return Err(at(span, message));
    }
    let context = DeviceContext {
        id_span: raw.id.span(),
        deadband,
    };
    let settings = protocol.read_keys(
        &Table::keys_of(text, path, device_span, mine),
        &context,
        scratch,
    )?;
    let states = crate::production::config::read_states(
        protocol.name(),
        protocol.machine_states(),
        raw.states.as_ref(),
        at,
    )?;
    let production = crate::production::config::read_production(
        protocol.name(),
        protocol.production().is_some(),
        raw.production.as_ref(),
        at,
    )?;
    let driver_config = DriverConfig {
        states,
        id: id.clone(),
        protocol,
        address,
        timeout,
        retries,
        endpoint: (protocol.owns_connections().is_some() || endpoint.is_mbap())
            .then(|| endpoint.clone()),
        settings,
    };
    // What depends on the whole device (a Modbus read plan).
    protocol
        .check(&driver_config)
        .map_err(|m| at(raw.id.span(), m))?;
    let known: Vec<&str> = protocol.groups().iter().map(|(name, _)| *name).collect();
    let mut groups = BTreeMap::new();
    for (group, text) in &raw.poll {
        if !known.contains(&group.as_str()) {
            return Err(at(
                text.span(),
                format!(
                    "{protocol} devices have no poll group {group:?}; groups: {}",
                    known.join(", ")
                ),
            ));
        }
        let what = format!("poll period of {group}");
        groups.insert(
            group.clone(),
            duration(text, MIN_PERIOD, MAX_PERIOD, &what, at)?,
        );
    }
    Ok(DeviceConfig {
        name: raw.name.unwrap_or_else(|| id.to_string()),
        driver: driver_config,
        period,
        groups,
        deadband,
        production,
    })
}

/// A deadband from `deadband` (absolute) or `deadband_percent`, never both.
pub fn check_deadband(
    absolute: &Option<Spanned<f64>>,
    percent: &Option<Spanned<f64>>,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<Deadband>, ConfigError> {
    match (absolute, percent) {
        (Some(_), Some(p)) => Err(at(
            p.span(),
            "deadband and deadband_percent both given: choose one".into(),
        )),
        (Some(d), None) => {
            let band = *d.get_ref();
            if band.is_finite() && band >= 0.0 {
                Ok(Some(Deadband::Absolute(band)))
            } else {
                Err(at(
                    d.span(),
                    format!("deadband {band} must be a number of at least 0 (in the point's unit)"),
                ))
            }
        }
        (None, Some(p)) => {
            let percent = *p.get_ref();
            if percent > 0.0 && percent <= 100.0 {
                Ok(Some(Deadband::Percent(percent)))
            } else {
                Err(at(
                    p.span(),
                    format!("deadband_percent {percent} is out of range: above 0, at most 100"),
                ))
            }
        }
        (None, None) => Ok(None),
    }
}

impl fmt::Display for LineConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.name, self.endpoint)
    }
}

/// The cell's own keys of the file; the other tables are checked against the plug-ins'
/// in [`parse_config`].
#[derive(Debug, Deserialize)]
struct RawConfig {
    token: Option<Spanned<String>>,
    read_token: Option<Spanned<String>>,
    time_zone: Option<Spanned<String>>,
    #[serde(default)]
    shift: Vec<crate::production::config::RawShift>,
    #[serde(default)]
    alarm: Vec<crate::alarm::config::RawAlarm>,
    #[serde(default)]
    line: Vec<RawLine>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLine {
    name: Spanned<String>,
    endpoint: Spanned<String>,
    reopen_after_timeouts: Option<Spanned<i64>>,
    #[serde(default)]
    device: Vec<RawDevice>,
}

/// The keys every device has ([`DEVICE_KEYS`]); its kind's own keys are read by the kind.
#[derive(Debug, Deserialize)]
struct RawDevice {
    id: Spanned<String>,
    name: Option<String>,
    protocol: Spanned<String>,
    address: Option<Spanned<RawAddress>>,
    timeout: Option<Spanned<String>>,
    retries: Option<Spanned<i64>>,
    period: Option<Spanned<String>>,
    #[serde(default)]
    poll: BTreeMap<String, Spanned<String>>,
    deadband: Option<Spanned<f64>>,
    deadband_percent: Option<Spanned<f64>>,
    states: Option<Spanned<BTreeMap<String, i64>>>,
    production: Option<Spanned<crate::production::config::RawProduction>>,
}

#[derive(Debug, Deserialize)]
#[serde(
    untagged,
    expecting = "the address must be a whole number (see the protocol's range) or \"none\""
)]
enum RawAddress {
    Number(i64),
    Text(String),
}
