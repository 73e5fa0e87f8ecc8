//! The `[cfx]` table: the AMQP 1.0 broker (or receiver) CFX messages go to, the address
//! there, and each machine's CFX handle.
//!
//! ```toml
//! [cfx]
//! broker = "amqp://mes.plant:5672"     # amqp://HOST[:PORT] (5672), amqps://HOST[:PORT] (5671)
//! address = "/exchange/cfx"            # where messages go (RabbitMQ 3.x: /exchange/NAME)
//! ca_file = "plant-ca.pem"             # amqps://: the broker's CA (else the system's)
//! client_cert = "cellbus.pem"          # amqps://: a certificate to show, with its key
//! client_key = "cellbus.key"
//! username = "cellbus"                 # SASL PLAIN, with the password in the environment
//! password_env = "CELLBUS_CFX_PASSWORD"
//! heartbeat = "1m"                     # 10s to 5m
//! listen = "0.0.0.0:5673"              # the endpoints' request listener (optional)
//!
//! [cfx.handles]                        # device id = its CFX handle (Vendor.Model.Serial)
//! placer1 = "Panasonic.BM221.SN12345"
//! ```
//!
//! Every device that counts production (a placement machine) is a CFX endpoint; one
//! without a handle in `[cfx.handles]` gets `cellbus.<this machine's name>.<device id>`.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::config::{ConfigError, Settings, Table, TableReader, duration};
use crate::northbound::tls::{TlsFiles, TlsKeys, check_tls};

/// The `[cfx]` table's reader.
#[derive(Debug)]
pub struct CfxTable;

/// The AMQP port when the URL names none.
pub const DEFAULT_PORT: u16 = 5672;

/// The AMQP over TLS port when an `amqps://` URL names none.
pub const DEFAULT_TLS_PORT: u16 = 5671;

/// How often each endpoint beats by default (the SDK's default).
pub const DEFAULT_HEARTBEAT: Duration = Duration::from_secs(60);

/// The `[cfx]` table, checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CfxConfig {
    /// TLS to the broker (`amqps://`): its files; `None` for `amqp://`.
    pub tls: Option<TlsFiles>,
    /// The broker's host.
    pub host: String,
    /// Its port.
    pub port: u16,
    /// The address messages go to there.
    pub address: String,
    /// The SASL PLAIN user, if the broker wants one.
    pub username: Option<String>,
    /// The environment variable holding the password (never the password itself).
    pub password_env: Option<String>,
    /// How often each endpoint beats.
    pub heartbeat: Duration,
    /// Handles by device id.
    pub handles: BTreeMap<String, cfx::Handle>,
    /// Where the endpoints listen for requests, if they do.
    pub listen: Option<std::net::SocketAddr>,
}

impl CfxConfig {
    /// `amqp://HOST:PORT` (or `amqps://`), for messages and logs.
    pub fn url(&self) -> String {
        let scheme = if self.tls.is_some() { "amqps" } else { "amqp" };
        format!("{scheme}://{}:{}", self.host, self.port)
    }
}

impl TableReader for CfxTable {
    fn table(&self) -> &'static str {
        "cfx"
    }

    fn read(&self, table: &Table<'_>) -> Result<Settings, ConfigError> {
        let raw: RawCfx = table.read()?;
        check(raw, table.path(), &|span, message| table.at(span, message)).map(Settings::new)
    }

    fn environment(&self, settings: &Settings) -> Vec<(&'static str, String)> {
        settings
            .get::<CfxConfig>()
            .and_then(|c| c.password_env.clone())
            .map(|var| ("[cfx] password_env", var))
            .into_iter()
            .collect()
    }

    fn summary(&self, settings: &Settings) -> String {
        settings
            .get::<CfxConfig>()
            .map(|c| format!("IPC-CFX to {}, address {}", c.url(), c.address))
            .unwrap_or_default()
    }
}

/// A broker URL, read by [`parse_url`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CfxUrl {
    /// `amqps://`.
    pub tls: bool,
    /// The host.
    pub host: String,
    /// The port.
    pub port: u16,
    /// The address, if the path names one.
    pub address: Option<String>,
}

/// A broker URL, `amqp://HOST[:PORT][/ADDRESS]` or `amqps://…`: the address is the path
/// (`amqp://mes:5672/cfx` → `cfx`; `amqp://mes:5672//exchange/cfx` → `/exchange/cfx`).
pub fn parse_url(text: &str) -> Result<CfxUrl, String> {
    let text = text.trim();
    let (tls, rest) = if let Some(rest) = text.strip_prefix("amqp://") {
        (false, rest)
    } else if let Some(rest) = text.strip_prefix("amqps://") {
        (true, rest)
    } else {
        return Err(format!(
            "{text:?} is not an AMQP URL; write amqp://HOST:PORT (port {DEFAULT_PORT} if left out) or amqps://HOST:PORT ({DEFAULT_TLS_PORT})"
        ));
    };
    let (authority, path) = rest.split_once('/').unwrap_or((rest, ""));
    if authority.contains('@') {
        return Err(
            "put the user in `username` and the password in the environment (`password_env`), not in the URL"
                .to_owned(),
        );
    }
    let default_port = if tls { DEFAULT_TLS_PORT } else { DEFAULT_PORT };
    let (host, port) = match authority.rsplit_once(':') {
        Some((host, port)) if !host.ends_with(']') || host.starts_with('[') => {
            let port = port
                .parse::<u16>()
                .ok()
                .filter(|p| *p != 0)
                .ok_or_else(|| format!("{text}: port {port:?} is not a port (1-65535)"))?;
            (host, port)
        }
        _ => (authority, default_port),
    };
    if host.is_empty() {
        return Err(format!("{text}: no host; write amqp://HOST:PORT"));
    }
    Ok(CfxUrl {
        tls,
        host: host.to_owned(),
        port,
        address: (!path.is_empty()).then(|| path.to_owned()),
    })
}

fn check(
    raw: RawCfx,
    path: &Path,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<CfxConfig, ConfigError> {
    let CfxUrl {
        tls,
        host,
        port,
        address: in_url,
    } = parse_url(raw.broker.get_ref()).map_err(|m| at(raw.broker.span(), m))?;
    let keys = TlsKeys {
        broker: &raw.broker,
        ca_file: raw.ca_file.as_ref(),
        client_cert: raw.client_cert.as_ref(),
        client_key: raw.client_key.as_ref(),
    };
    let tls = check_tls(&keys, tls, "amqps://host:5671", path, at)?;
    let address = match (&raw.address, in_url) {
        (Some(address), _) if address.get_ref().trim().is_empty() => {
            return Err(at(
                address.span(),
                "address is empty; name where messages go (a queue, /exchange/NAME)".into(),
            ));
        }
        (Some(address), _) => address.get_ref().trim().to_owned(),
        (None, Some(address)) => address,
        (None, None) => {
            return Err(at(
                raw.broker.span(),
                "no address: give `address` (a queue, /exchange/NAME) or put it in the URL (amqp://HOST:PORT/ADDRESS)".into(),
            ));
        }
    };
    if let Some(env) = &raw.password_env
        && env.get_ref().trim().is_empty()
    {
        return Err(at(
            env.span(),
            "password_env is empty; name the environment variable holding the password".into(),
        ));
    }
    let heartbeat = match &raw.heartbeat {
        Some(text) => duration(
            text,
            Duration::from_secs(10),
            Duration::from_secs(300),
            "heartbeat",
            at,
        )?,
        None => DEFAULT_HEARTBEAT,
    };
    let listen = match &raw.listen {
        Some(text) => Some(text.get_ref().trim().parse().map_err(|_| {
            at(
                text.span(),
                format!(
                    "listen {:?} is not IP:PORT (0.0.0.0:5673; port 0 picks a free one)",
                    text.get_ref()
                ),
            )
        })?),
        None => None,
    };
    let mut handles = BTreeMap::new();
    for (device, handle) in raw.handles.unwrap_or_default() {
        let checked =
            cfx::Handle::new(handle.get_ref()).map_err(|e| at(handle.span(), e.to_string()))?;
        handles.insert(device, checked);
    }
    Ok(CfxConfig {
        tls,
        host,
        port,
        address,
        username: raw.username.map(Spanned::into_inner),
        password_env: raw.password_env.map(Spanned::into_inner),
        heartbeat,
        handles,
        listen,
    })
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCfx {
    broker: Spanned<String>,
    address: Option<Spanned<String>>,
    username: Option<Spanned<String>>,
    password_env: Option<Spanned<String>>,
    heartbeat: Option<Spanned<String>>,
    handles: Option<BTreeMap<String, Spanned<String>>>,
    listen: Option<Spanned<String>>,
    ca_file: Option<Spanned<String>>,
    client_cert: Option<Spanned<String>>,
    client_key: Option<Spanned<String>>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::config::{ONE, parse, refused};

    /// `table` in a file with one station (tables first, so positions are the table's).
    fn with_a_line(table: &str) -> String {
        format!("{table}{ONE}")
    }

    #[test]
    fn a_cfx_table_names_the_broker_the_address_and_each_machines_handle() {
        let config = parse(&with_a_line(
            "[cfx]\nbroker = \"amqp://mes.plant\"\naddress = \"/exchange/cfx\"\nheartbeat = \"30s\"\n\
             [cfx.handles]\nplacer1 = \"Panasonic.BM221.SN1\"\n",
        ))
        .unwrap();
        let cfx = config.interface::<CfxConfig>("cfx").unwrap();
        assert_eq!((cfx.host.as_str(), cfx.port), ("mes.plant", 5672));
        assert_eq!(cfx.address, "/exchange/cfx");
        assert_eq!(cfx.heartbeat, Duration::from_secs(30));
        assert_eq!(cfx.handles["placer1"].as_str(), "Panasonic.BM221.SN1");
    }

    #[test]
    fn the_address_may_be_the_urls_path_and_mistakes_are_refused_where_they_are() {
        assert_eq!(
            parse_url("amqp://127.0.0.1:5673//exchange/cfx").unwrap(),
            CfxUrl {
                tls: false,
                host: "127.0.0.1".to_owned(),
                port: 5673,
                address: Some("/exchange/cfx".to_owned())
            }
        );
        assert_eq!(
            parse_url("amqps://mes/cfx").unwrap(),
            CfxUrl {
                tls: true,
                host: "mes".to_owned(),
                port: 5671,
                address: Some("cfx".to_owned())
            }
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqp://mes/q\"\nca_file = \"ca.pem\"\n"),
            3,
            11,
            "ca_file is for TLS: the broker is amqp://; write amqps://host:5671",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqps://mes/q\"\nca_file = \"missing.pem\"\n"),
            3,
            11,
            "missing.pem",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"http://mes\"\naddress = \"q\"\n"),
            2,
            10,
            "not an AMQP URL",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqp://mes\"\n"),
            2,
            10,
            "no address",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqp://u:p@mes/q\"\n"),
            2,
            10,
            "password_env",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqp://mes:0/q\"\n"),
            2,
            10,
            "not a port",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqp://mes/q\"\nheartbeat = \"10m\"\n"),
            3,
            13,
            "out of range",
        );
        refused(
            &with_a_line(
                "[cfx]\nbroker = \"amqp://mes/q\"\n[cfx.handles]\nplacer1 = \"Panasonic BM\"\n",
            ),
            4,
            11,
            "CFX handle",
        );
        refused(
            &with_a_line("[cfx]\nbroker = \"amqp://mes/q\"\nqueue = \"x\"\n"),
            3,
            1,
            "queue",
        );
    }
}
