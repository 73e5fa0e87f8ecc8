//! The `[opcua]` table: where the OPC UA server listens, its security and its users.
//! Read and checked here, beside the server's code; the cell's config hands the table over
//! through [`TableReader`].

use std::collections::HashSet;
use std::fmt;
use std::ops::Range;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use gateway::config::{ConfigError, Settings, Table, TableReader, bounded, duration};

/// The `[opcua]` table's reader.
#[derive(Debug)]
pub struct OpcuaTable;

impl TableReader for OpcuaTable {
    fn table(&self) -> &'static str {
        "opcua"
    }

    fn read(&self, table: &Table<'_>) -> Result<Settings, ConfigError> {
        let raw: RawOpcua = table.read()?;
        check_opcua(raw, &|span, message| table.at(span, message)).map(Settings::new)
    }

    fn environment(&self, settings: &Settings) -> Vec<(&'static str, String)> {
        settings
            .get::<OpcuaConfig>()
            .map(|opcua| {
                opcua
                    .users
                    .iter()
                    .map(|user| ("[[opcua.user]] password_env", user.password_env.clone()))
                    .collect()
            })
            .unwrap_or_default()
    }

    fn summary(&self, settings: &Settings) -> String {
        let Some(opcua) = settings.get::<OpcuaConfig>() else {
            return String::new();
        };
        let users = match opcua.users.len() {
            0 => String::new(),
            1 => ", 1 user".to_owned(),
            n => format!(", {n} users"),
        };
        format!(
            "server on opc.tcp://{}:{} as {}{users}",
            opcua.host, opcua.port, opcua.application_name
        )
    }
}

/// Where the OPC UA server listens by default: loopback only.
pub const DEFAULT_OPCUA_ENDPOINT: &str = "opc.tcp://127.0.0.1:4840";
/// The OPC UA application name by default.
pub const DEFAULT_OPCUA_APPLICATION_NAME: &str = "cellbus";
/// How long a client has by default to activate the session it created: clients activate
/// at once (milliseconds later); a session never activated holds one of the server's
/// session slots for nothing.
pub const DEFAULT_OPCUA_ACTIVATION_TIMEOUT: Duration = Duration::from_secs(5);
/// The longest session timeout granted by default: a client that vanishes (cable pulled)
/// holds its session and its subscriptions this long at most; clients keep a session alive
/// with their publish requests or reads well within a minute.
pub const DEFAULT_OPCUA_SESSION_TIMEOUT: Duration = Duration::from_secs(60);
/// Sessions at once from one IP address by default: a SCADA, an HMI and an engineering
/// tool on one computer need a few; ten leave room and keep one computer from taking the
/// server's 100.
pub const DEFAULT_OPCUA_SESSIONS_PER_ADDRESS: usize = 10;
/// Monitored items at once by default, all sessions and nodes together: ten clients
/// watching 10,000 points each, about 135 MB of the server's memory (1.35 kB an item).
pub const DEFAULT_OPCUA_MAX_MONITORED_ITEMS: u64 = 100_000;

/// The `[opcua]` table: the OPC UA server, its security and its users.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpcuaConfig {
    /// The host of the endpoint URL (and the address bound).
    pub host: String,
    /// The port (0: any free port).
    pub port: u16,
    /// The application's name (also the certificate's common name).
    pub application_name: String,
    /// The application's URI (in its certificate).
    pub application_uri: String,
    /// The endpoints offered: security policy and mode, in the file's order.
    pub security: Vec<OpcuaSecurity>,
    /// Whether anonymous sessions (read-only) are allowed; `None`: only while writes are off.
    pub anonymous: Option<bool>,
    /// Whether every client certificate is trusted (tests only); else the client's
    /// certificate must be in `<data>/opcua/pki/trusted` (rejected ones land in
    /// `<data>/opcua/pki/rejected`).
    pub trust_all_clients: bool,
    /// Who may log in with a user name and password.
    pub users: Vec<OpcuaUser>,
    /// How long a client has to activate the session it created before the gateway closes
    /// it (`activation_timeout`).
    pub activation_timeout: Duration,
    /// The longest session timeout granted (`session_timeout`): a session without a
    /// request for this long is closed.
    pub session_timeout: Duration,
    /// Sessions at once from one IP address (`sessions_per_address`).
    pub sessions_per_address: usize,
    /// Monitored items at once, all sessions and nodes together (`max_monitored_items`).
    pub max_monitored_items: u64,
}

/// One endpoint's security: a policy and a message mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct OpcuaSecurity {
    /// The security policy.
    pub policy: OpcuaPolicy,
    /// Signed, or signed and encrypted (`None` only with the policy `None`).
    pub mode: OpcuaMode,
}

/// An OPC UA security policy the server offers (the deprecated Basic128Rsa15 and Basic256
/// are not).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpcuaPolicy {
    /// No security: plain text, no client certificate; only when the config says so.
    None,
    /// Basic256Sha256.
    Basic256Sha256,
    /// Aes128_Sha256_RsaOaep.
    Aes128Sha256RsaOaep,
    /// Aes256_Sha256_RsaPss.
    Aes256Sha256RsaPss,
}

/// An OPC UA message security mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OpcuaMode {
    /// Plain (policy `None` only).
    None,
    /// Signed.
    Sign,
    /// Signed and encrypted.
    SignAndEncrypt,
}

/// A user of the OPC UA server.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OpcuaUser {
    /// The user name.
    pub name: String,
    /// The environment variable holding the password (never the password itself).
    pub password_env: String,
    /// Whether the user may write (with `--allow-writes`).
    pub write: bool,
}

impl OpcuaSecurity {
    /// The default endpoints: Basic256Sha256, signed and signed and encrypted.
    pub const DEFAULT: [OpcuaSecurity; 2] = [
        OpcuaSecurity {
            policy: OpcuaPolicy::Basic256Sha256,
            mode: OpcuaMode::Sign,
        },
        OpcuaSecurity {
            policy: OpcuaPolicy::Basic256Sha256,
            mode: OpcuaMode::SignAndEncrypt,
        },
    ];

    /// No security.
    pub const NONE: OpcuaSecurity = OpcuaSecurity {
        policy: OpcuaPolicy::None,
        mode: OpcuaMode::None,
    };

    /// Reads `None`, or a policy and a mode: `Basic256Sha256 SignAndEncrypt`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let words: Vec<&str> = text.split_whitespace().collect();
        let policy = |word: &str| match word.to_ascii_lowercase().replace('_', "").as_str() {
            "none" => Some(OpcuaPolicy::None),
            "basic256sha256" => Some(OpcuaPolicy::Basic256Sha256),
            "aes128sha256rsaoaep" => Some(OpcuaPolicy::Aes128Sha256RsaOaep),
            "aes256sha256rsapss" => Some(OpcuaPolicy::Aes256Sha256RsaPss),
            _ => None,
        };
        let mode = |word: &str| match word.to_ascii_lowercase().as_str() {
            "sign" => Some(OpcuaMode::Sign),
            "signandencrypt" => Some(OpcuaMode::SignAndEncrypt),
            _ => None,
        };
        let hint = "write \"None\" or a policy and a mode: \"Basic256Sha256 SignAndEncrypt\", \
                    \"Basic256Sha256 Sign\" (policies: Basic256Sha256, Aes128Sha256RsaOaep, \
                    Aes256Sha256RsaPss)";
        match words.as_slice() {
            [word] if policy(word) == Some(OpcuaPolicy::None) => Ok(Self::NONE),
            [p, m] => match (policy(p), mode(m)) {
                (Some(OpcuaPolicy::None), _) => Err(format!(
                    "security {text:?}: None has no mode; write \"None\""
                )),
                (Some(policy), Some(mode)) => Ok(Self { policy, mode }),
                _ => Err(format!("security {text:?} is not known; {hint}")),
            },
            _ => Err(format!("security {text:?} is not known; {hint}")),
        }
    }
}

impl fmt::Display for OpcuaSecurity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let policy = match self.policy {
            OpcuaPolicy::None => return f.write_str("None"),
            OpcuaPolicy::Basic256Sha256 => "Basic256Sha256",
            OpcuaPolicy::Aes128Sha256RsaOaep => "Aes128Sha256RsaOaep",
            OpcuaPolicy::Aes256Sha256RsaPss => "Aes256Sha256RsaPss",
        };
        let mode = match self.mode {
            OpcuaMode::None => "None",
            OpcuaMode::Sign => "Sign",
            OpcuaMode::SignAndEncrypt => "SignAndEncrypt",
        };
        write!(f, "{policy} {mode}")
    }
}

impl OpcuaConfig {
    /// A server at `host:port` with the defaults: Basic256Sha256 Sign and SignAndEncrypt,
    /// no users, anonymous reading while writes are off.
    pub fn at(host: &str, port: u16) -> Self {
        let application_name = DEFAULT_OPCUA_APPLICATION_NAME.to_owned();
        Self {
            host: host.to_owned(),
            port,
            application_uri: default_application_uri(&application_name),
            application_name,
            security: OpcuaSecurity::DEFAULT.to_vec(),
            anonymous: None,
            trust_all_clients: false,
            users: Vec::new(),
            activation_timeout: DEFAULT_OPCUA_ACTIVATION_TIMEOUT,
            session_timeout: DEFAULT_OPCUA_SESSION_TIMEOUT,
            sessions_per_address: DEFAULT_OPCUA_SESSIONS_PER_ADDRESS,
            max_monitored_items: DEFAULT_OPCUA_MAX_MONITORED_ITEMS,
        }
    }

    /// The endpoint URL (`opc.tcp://host:port`).
    pub fn endpoint(&self) -> String {
        format!("opc.tcp://{}:{}", url_host(&self.host), self.port)
    }
}

/// Reads `opc.tcp://host[:port]` (port 4840 by default) into host and port.
pub fn parse_opcua_endpoint(text: &str) -> Result<(String, u16), String> {
    let url = url::Url::parse(text.trim()).map_err(|e| {
        format!("endpoint {text:?} is not a URL ({e}); write opc.tcp://127.0.0.1:4840")
    })?;
    if url.scheme() != "opc.tcp" {
        return Err(format!(
            "endpoint {text:?} has scheme {:?}; write opc.tcp://host:4840",
            url.scheme()
        ));
    }
    let host = url
        .host_str()
        .ok_or_else(|| format!("endpoint {text:?} names no host; write opc.tcp://host:4840"))?;
    if !matches!(url.path(), "" | "/") || url.query().is_some() || !url.username().is_empty() {
        return Err(format!(
            "endpoint {text:?}: write only opc.tcp://host:port (no path, query or user)"
        ));
    }
    let host = host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .to_owned();
    Ok((host, url.port().unwrap_or(4840)))
}

fn url_host(host: &str) -> String {
    if host.contains(':') {
        format!("[{host}]")
    } else {
        host.to_owned()
    }
}

/// `urn:cellbus:<host name>:<application name>`.
fn default_application_uri(application_name: &str) -> String {
    format!(
        "urn:{}:{application_name}",
        gateway::northbound::default_edge_node_id()
    )
}

fn check_opcua(
    raw: RawOpcua,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<OpcuaConfig, ConfigError> {
    let (host, port) = match &raw.endpoint {
        Some(text) => parse_opcua_endpoint(text.get_ref()).map_err(|m| at(text.span(), m))?,
        None => parse_opcua_endpoint(DEFAULT_OPCUA_ENDPOINT)
            .expect("the default OPC UA endpoint is a valid URL"),
    };
    let nonempty = |field: &Option<Spanned<String>>, key: &str| match field {
        Some(text) if text.get_ref().trim().is_empty() => Err(at(
            text.span(),
            format!("{key} is empty; remove it for the default"),
        )),
        Some(text) => Ok(Some(text.get_ref().trim().to_owned())),
        None => Ok(None),
    };
    let application_name = nonempty(&raw.application_name, "application_name")?
        .unwrap_or_else(|| DEFAULT_OPCUA_APPLICATION_NAME.to_owned());
    let application_uri = match nonempty(&raw.application_uri, "application_uri")? {
        Some(uri) if !uri.contains(':') => {
            let span = raw.application_uri.as_ref().map_or(0..0, Spanned::span);
            return Err(at(
                span,
                format!("application_uri {uri:?} is not a URI; write urn:plant:cellbus"),
            ));
        }
        Some(uri) => uri,
        None => default_application_uri(&application_name),
    };
    let security = match &raw.security {
        None => OpcuaSecurity::DEFAULT.to_vec(),
        Some(list) if list.get_ref().is_empty() => {
            return Err(at(
                list.span(),
                "security is empty: the server would offer no endpoint; remove it for \
                 Basic256Sha256 Sign and SignAndEncrypt"
                    .into(),
            ));
        }
        Some(list) => {
            let mut seen = HashSet::new();
            let mut security = Vec::new();
            for text in list.get_ref() {
                let s = OpcuaSecurity::parse(text.get_ref()).map_err(|m| at(text.span(), m))?;
                if !seen.insert(s) {
                    return Err(at(text.span(), format!("security {s} is listed twice")));
                }
                security.push(s);
            }
            security
        }
    };
    let mut users = Vec::new();
    let mut names = HashSet::new();
    for user in raw.user {
        let name = user.name.get_ref().trim();
        if name.is_empty() {
            return Err(at(user.name.span(), "the user name is empty".into()));
        }
        if !names.insert(name.to_owned()) {
            return Err(at(
                user.name.span(),
                format!("user {name:?} is listed twice"),
            ));
        }
        let env = user.password_env.get_ref().trim();
        if env.is_empty() {
            return Err(at(
                user.password_env.span(),
                "password_env is empty; name the environment variable holding the password".into(),
            ));
        }
        if !security.iter().any(|s| s.policy != OpcuaPolicy::None) {
            return Err(at(
                user.name.span(),
                "users log in only on a secure endpoint (their passwords would cross the \
                 network in clear); add \"Basic256Sha256 SignAndEncrypt\" to security"
                    .into(),
            ));
        }
        users.push(OpcuaUser {
            name: name.to_owned(),
            password_env: env.to_owned(),
            write: user.write.map(Spanned::into_inner).unwrap_or(false),
        });
    }
    let activation_timeout = match &raw.activation_timeout {
        Some(text) => duration(
            text,
            Duration::from_secs(1),
            Duration::from_secs(60),
            "activation_timeout",
            at,
        )?,
        None => DEFAULT_OPCUA_ACTIVATION_TIMEOUT,
    };
    let session_timeout = match &raw.session_timeout {
        Some(text) => duration(
            text,
            Duration::from_secs(10),
            Duration::from_secs(3600),
            "session_timeout",
            at,
        )?,
        None => DEFAULT_OPCUA_SESSION_TIMEOUT,
    };
    let sessions_per_address = match &raw.sessions_per_address {
        Some(n) => bounded(
            n,
            1..=OPCUA_MAX_SESSIONS,
            "sessions_per_address",
            " (the server's sessions at once)",
            at,
        )?,
        None => DEFAULT_OPCUA_SESSIONS_PER_ADDRESS,
    };
    let max_monitored_items = match &raw.max_monitored_items {
        Some(n) => bounded(
            n,
            1..=10_000_000,
            "max_monitored_items",
            " (each costs about 1.35 kB of memory)",
            at,
        )?,
        None => DEFAULT_OPCUA_MAX_MONITORED_ITEMS,
    };
    Ok(OpcuaConfig {
        host,
        port,
        application_name,
        application_uri,
        security,
        anonymous: raw.anonymous.map(Spanned::into_inner),
        trust_all_clients: raw
            .trust_all_clients
            .map(Spanned::into_inner)
            .unwrap_or(false),
        users,
        activation_timeout,
        session_timeout,
        sessions_per_address,
        max_monitored_items,
    })
}

/// Sessions the OPC UA server holds at once (every client's, activated or not).
pub const OPCUA_MAX_SESSIONS: usize = 100;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOpcua {
    endpoint: Option<Spanned<String>>,
    application_name: Option<Spanned<String>>,
    application_uri: Option<Spanned<String>>,
    security: Option<Spanned<Vec<Spanned<String>>>>,
    anonymous: Option<Spanned<bool>>,
    trust_all_clients: Option<Spanned<bool>>,
    activation_timeout: Option<Spanned<String>>,
    session_timeout: Option<Spanned<String>>,
    sessions_per_address: Option<Spanned<i64>>,
    max_monitored_items: Option<Spanned<i64>>,
    #[serde(default)]
    user: Vec<RawOpcuaUser>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOpcuaUser {
    name: Spanned<String>,
    password_env: Spanned<String>,
    write: Option<Spanned<bool>>,
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use gateway::EXAMPLE_CONFIG;

    const LINE: &str = "[[line]]\nname = \"l\"\nendpoint = \"tcp://127.0.0.1:1\"\n\
                        [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\naddress = 1\n";

    /// Checks `text` as the `cellbus` binary with OPC UA does.
    fn parse_config(text: &str, path: &Path) -> Result<gateway::CellConfig, ConfigError> {
        let registry = gateway::plugins::builtin().with_interface(&crate::Opcua);
        gateway::config::parse_config(text, path, &registry.config)
    }

    fn parse(opcua: &str) -> Result<Option<OpcuaConfig>, ConfigError> {
        parse_config(&format!("{LINE}{opcua}"), Path::new("cell.toml"))
            .map(|c| c.interface::<OpcuaConfig>("opcua").cloned())
    }

    #[test]
    fn an_empty_opcua_table_gets_the_secure_defaults_on_loopback() {
        let config = parse("[opcua]\n").unwrap().unwrap();
        assert_eq!((config.host.as_str(), config.port), ("127.0.0.1", 4840));
        assert_eq!(config.endpoint(), "opc.tcp://127.0.0.1:4840");
        assert_eq!(config.security, OpcuaSecurity::DEFAULT.to_vec());
        assert_eq!(config.anonymous, None);
        assert!(!config.trust_all_clients);
        assert!(config.application_uri.starts_with("urn:"));
        assert_eq!(parse("").unwrap(), None);
    }

    #[test]
    fn security_none_is_offered_only_when_listed() {
        let config = parse("[opcua]\nsecurity = [\"None\", \"Basic256Sha256 SignAndEncrypt\"]\n")
            .unwrap()
            .unwrap();
        assert_eq!(
            config.security,
            vec![OpcuaSecurity::NONE, OpcuaSecurity::DEFAULT[1]]
        );
    }

    #[test]
    fn a_bad_security_entry_is_refused_at_its_line_and_column() {
        let e = parse("[opcua]\nsecurity = [\"None\", \"Basic128 Sign\"]\n").unwrap_err();
        assert_eq!(e.position(), Some((9, 21)), "{e}");
        assert!(e.to_string().contains("Basic128 Sign"), "{e}");
    }

    #[test]
    fn users_are_read_with_their_password_variable_and_write_right() {
        let config = parse(
            "[opcua]\nendpoint = \"opc.tcp://0.0.0.0:4841\"\n\
             [[opcua.user]]\nname = \"op\"\npassword_env = \"OP_PW\"\nwrite = true\n\
             [[opcua.user]]\nname = \"viewer\"\npassword_env = \"VIEW_PW\"\n",
        )
        .unwrap()
        .unwrap();
        assert_eq!(config.port, 4841);
        assert_eq!(
            config.users,
            vec![
                OpcuaUser {
                    name: "op".into(),
                    password_env: "OP_PW".into(),
                    write: true
                },
                OpcuaUser {
                    name: "viewer".into(),
                    password_env: "VIEW_PW".into(),
                    write: false
                },
            ]
        );
    }

    #[test]
    fn users_on_an_insecure_only_server_and_wrong_endpoints_are_refused() {
        let e = parse(
            "[opcua]\nsecurity = [\"None\"]\n[[opcua.user]]\nname = \"op\"\npassword_env = \"P\"\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("secure endpoint"), "{e}");
        let e = parse("[opcua]\nendpoint = \"http://127.0.0.1:4840\"\n").unwrap_err();
        assert_eq!(e.position(), Some((9, 12)), "{e}");
        let e = parse("[opcua]\nendpont = \"opc.tcp://127.0.0.1:4840\"\n").unwrap_err();
        assert!(e.to_string().contains("endpont"), "{e}");
    }

    #[test]
    fn the_session_and_monitored_item_limits_have_safe_defaults_and_are_read() {
        let config = parse("[opcua]\n").unwrap().unwrap();
        assert_eq!(config.activation_timeout, Duration::from_secs(5));
        assert_eq!(config.session_timeout, Duration::from_secs(60));
        assert_eq!(config.sessions_per_address, 10);
        assert_eq!(config.max_monitored_items, 100_000);
        let config = parse(
            "[opcua]\nactivation_timeout = \"2s\"\nsession_timeout = \"5m\"\n\
             sessions_per_address = 3\nmax_monitored_items = 20000\n",
        )
        .unwrap()
        .unwrap();
        assert_eq!(config.activation_timeout, Duration::from_secs(2));
        assert_eq!(config.session_timeout, Duration::from_secs(300));
        assert_eq!(config.sessions_per_address, 3);
        assert_eq!(config.max_monitored_items, 20_000);
    }

    #[test]
    fn the_examples_opcua_table_uncommented_parses_with_the_defaults_it_shows() {
        let table: String = EXAMPLE_CONFIG
            .lines()
            .skip_while(|l| *l != "# [opcua]")
            .take_while(|l| !l.starts_with("# [[opcua.user]]"))
            .map(|l| l.strip_prefix("# ").unwrap_or(l.trim_start_matches('#')))
            .map(|l| format!("{l}\n"))
            .collect();
        assert!(table.contains("max_monitored_items"), "{table}");
        let config = parse(&table).unwrap().unwrap();
        let defaults = OpcuaConfig::at("127.0.0.1", 4840);
        assert_eq!(config.activation_timeout, defaults.activation_timeout);
        assert_eq!(config.session_timeout, defaults.session_timeout);
        assert_eq!(config.sessions_per_address, defaults.sessions_per_address);
        assert_eq!(config.max_monitored_items, defaults.max_monitored_items);
    }

    #[test]
    fn a_bad_session_or_monitored_item_limit_is_refused_naming_the_key_at_its_place() {
        for (line, column, key) in [
            ("activation_timeout = \"0s\"", 22, "activation_timeout"),
            ("activation_timeout = \"soon\"", 22, "activation_timeout"),
            ("session_timeout = \"2h\"", 19, "session_timeout"),
            ("sessions_per_address = 0", 24, "sessions_per_address"),
            ("sessions_per_address = 101", 24, "sessions_per_address"),
            ("max_monitored_items = -1", 23, "max_monitored_items"),
            ("max_monitored_items = 10000001", 23, "max_monitored_items"),
            ("max_monitored_item = 5", 1, "max_monitored_item"),
        ] {
            let e = parse(&format!("[opcua]\n{line}\n")).unwrap_err();
            assert_eq!(e.position(), Some((9, column)), "{line}: {e}");
            assert!(e.to_string().contains(key), "{line}: {e}");
        }
    }
}

#[cfg(test)]
mod environment_tests {
    use gateway::plugins::builtin;

    #[test]
    fn a_users_password_variable_that_is_not_set_fails_the_check_naming_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cell.toml");
        std::fs::write(
            &path,
            "[[line]]\nname = \"l\"\nendpoint = \"tcp://127.0.0.1:1\"\n\
             [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n\
             [opcua]\n[[opcua.user]]\nname = \"operator\"\n\
             password_env = \"CELLBUS_TEST_OPCUA_NEVER_SET\"\n",
        )
        .unwrap();
        let plugins = builtin().with_interface(&crate::Opcua).config;
        let error = gateway::config::check_config(&path, &plugins)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("cell.toml:10:")
                && error.contains(
                    "[[opcua.user]] password_env names the environment variable CELLBUS_TEST_OPCUA_NEVER_SET, which is not set here"
                ),
            "{error}"
        );
    }
}
