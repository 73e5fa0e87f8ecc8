//! A table's TLS keys (`ca_file`, `client_cert`, `client_key`), for a broker reached over
//! TLS (`mqtts://`, `amqps://`): checked when the configuration is read, so that `cellbus
//! config check` reports a missing file or bad PEM where it is named. The rustls setup
//! itself is `kit::mqtt::tls`.

use std::ops::Range;
use std::path::Path;

use kit::mqtt::{MqttClientCert, MqttTls};

/// The TLS files of a broker (`ca_file`, and `client_cert` with `client_key`): kit's, first
/// made for MQTT.
pub type TlsFiles = MqttTls;
use toml::Spanned;

use crate::config::ConfigError;

/// The keys as the table has them.
pub struct TlsKeys<'a> {
    /// The broker URL (where an error about the system's roots points).
    pub broker: &'a Spanned<String>,
    /// `ca_file`.
    pub ca_file: Option<&'a Spanned<String>>,
    /// `client_cert`.
    pub client_cert: Option<&'a Spanned<String>>,
    /// `client_key`.
    pub client_key: Option<&'a Spanned<String>>,
}

/// The TLS files of a broker reached over TLS (`tls`); `None` for a plain one, which
/// must name no TLS key (`secure` says what the user should write instead: the TLS URL).
/// Relative paths are relative to the config file at `path`. The files are read here and
/// again when the gateway starts.
pub fn check_tls(
    keys: &TlsKeys<'_>,
    tls: bool,
    secure: &str,
    path: &Path,
    at: &impl Fn(Range<usize>, String) -> ConfigError,
) -> Result<Option<MqttTls>, ConfigError> {
    let named = [
        ("ca_file", keys.ca_file),
        ("client_cert", keys.client_cert),
        ("client_key", keys.client_key),
    ];
    if !tls {
        if let Some((key, Some(value))) = named.iter().find(|(_, v)| v.is_some()) {
            let scheme = keys
                .broker
                .get_ref()
                .split("://")
                .next()
                .unwrap_or_default();
            return Err(at(
                value.span(),
                format!(
                    "{key} is for TLS: the broker is {scheme}://; write {secure} or remove {key}"
                ),
            ));
        }
        return Ok(None);
    }
    let base = path.parent().unwrap_or(Path::new(""));
    for (key, value) in named {
        if let Some(value) = value
            && value.get_ref().trim().is_empty()
        {
            return Err(at(
                value.span(),
                format!("{key} is empty; name a PEM file or remove {key}"),
            ));
        }
    }
    let file = |value: &Spanned<String>| base.join(value.get_ref().trim());
    let client = match (keys.client_cert, keys.client_key) {
        (Some(cert), Some(key)) => Some(MqttClientCert {
            cert: file(cert),
            key: file(key),
        }),
        (None, None) => None,
        (Some(cert), None) => {
            return Err(at(
                cert.span(),
                "client_cert needs client_key (its private key, PEM)".into(),
            ));
        }
        (None, Some(key)) => {
            return Err(at(
                key.span(),
                "client_key needs client_cert (its certificate, PEM)".into(),
            ));
        }
    };
    let tls = MqttTls {
        ca_file: keys.ca_file.map(file),
        client,
    };
    kit::mqtt::tls::check_files(&tls).map_err(|e| {
        let span = match e.key {
            "ca_file" => keys.ca_file,
            "client_cert" => keys.client_cert,
            "client_key" => keys.client_key,
            _ => None,
        }
        .map_or(keys.broker.span(), Spanned::span);
        at(span, e.message)
    })?;
    Ok(Some(tls))
}
