//! TLS to the broker (`mqtts://`): [`kit::mqtt::tls`], shared with the historian and
//! `cellbus mqtt sub`.
//!
//! The configuration's `[mqtt]` TLS files are still [`crate::config::MqttTls`], a twin of
//! [`kit::mqtt::MqttTls`]; [`client_config`] and [`check_files`] take the configuration's
//! and convert it here, in one place, until the configuration uses kit's type.

use std::sync::Arc;

use rustls::ClientConfig;

use crate::config::MqttTls;

pub use kit::mqtt::tls::{TlsSetupError, describe, transport};

/// Reads the files of `tls` and builds the client configuration; without a `ca_file` it
/// trusts the system's roots, and fails when the system has none.
pub fn client_config(tls: &MqttTls) -> Result<Arc<ClientConfig>, TlsSetupError> {
    kit::mqtt::tls::client_config(&kit_tls(tls))
}

/// Reads the files `tls` names (not the system's roots) and checks that they make a
/// client configuration: for `cellbus config check`.
pub fn check_files(tls: &MqttTls) -> Result<(), TlsSetupError> {
    kit::mqtt::tls::check_files(&kit_tls(tls))
}

/// The configuration's TLS files as kit's type.
fn kit_tls(tls: &MqttTls) -> kit::mqtt::MqttTls {
    kit::mqtt::MqttTls {
        ca_file: tls.ca_file.clone(),
        client: tls.client.as_ref().map(|c| kit::mqtt::MqttClientCert {
            cert: c.cert.clone(),
            key: c.key.clone(),
        }),
    }
}
