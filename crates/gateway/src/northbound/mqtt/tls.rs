//! TLS to the broker (`mqtts://`): [`kit::mqtt::tls`], shared with the historian and
//! `cellbus mqtt sub`. The `[mqtt]` table's files are [`kit::mqtt::MqttTls`].

pub use kit::mqtt::tls::{TlsSetupError, check_files, client_config, describe, transport};
