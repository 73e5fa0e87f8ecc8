//! TLS to the broker (`mqtts://`) through rustls with the `ring` crypto provider, chosen
//! here rather than process-wide: a client (the gateway, the historian, `cellbus mqtt
//! sub`) trusts the `ca_file` (the gateway's `[mqtt]` table, the historian's and the CLI's
//! flags), else the system's roots (`rustls-native-certs`), and shows `client_cert` with
//! `client_key` to a broker that asks for a client certificate.
//!
//! The errors name the key, the file and what is wrong, never what a key file holds; a
//! failed handshake reads "TLS handshake with broker HOST:PORT failed: …".

use std::io;
use std::path::Path;
use std::sync::Arc;

use rumqttc::{ConnectionError, TlsConfiguration, Transport};
use rustls::pki_types::pem::{self, PemObject};
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use rustls::{AlertDescription, CertificateError, ClientConfig, RootCertStore};

use super::MqttTls;

/// Largest PEM file read: a system CA bundle is about 200 KiB.
const MAX_PEM: u64 = 4 << 20;

/// Why the TLS setup failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct TlsSetupError {
    /// The `[mqtt]` key whose file is wrong (`ca_file`, `client_cert`, `client_key`), or
    /// `broker` when it is about the system's roots.
    pub key: &'static str,
    /// What is wrong, with the file's path.
    pub message: String,
}

fn error(key: &'static str, message: String) -> TlsSetupError {
    TlsSetupError { key, message }
}

/// The transport for a broker with TLS `config` (from [`client_config`]).
pub fn transport(config: &Arc<ClientConfig>) -> Transport {
    Transport::tls_with_config(TlsConfiguration::Rustls(Arc::clone(config)))
}

/// Reads the files of `tls` and builds the client configuration; without a `ca_file` it
/// trusts the system's roots, and fails when the system has none.
pub fn client_config(tls: &MqttTls) -> Result<Arc<ClientConfig>, TlsSetupError> {
    let roots = match &tls.ca_file {
        Some(path) => ca_roots(path)?,
        None => system_roots()?,
    };
    build(tls, roots)
}

/// Reads the files `tls` names (not the system's roots) and checks that they make a
/// client configuration: for `cellbus config check`.
pub fn check_files(tls: &MqttTls) -> Result<(), TlsSetupError> {
    let roots = match &tls.ca_file {
        Some(path) => ca_roots(path)?,
        None => RootCertStore::empty(),
    };
    build(tls, roots).map(drop)
}

fn build(tls: &MqttTls, roots: RootCertStore) -> Result<Arc<ClientConfig>, TlsSetupError> {
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| error("broker", format!("TLS cannot be set up: {e}")))?
        .with_root_certificates(roots);
    let config = match &tls.client {
        None => builder.with_no_client_auth(),
        Some(client) => {
            let certs = certificates("client_cert", &client.cert)?;
            let key = private_key(&client.key)?;
            builder.with_client_auth_cert(certs, key).map_err(|e| {
                error(
                    "client_key",
                    format!(
                        "client_key {} does not go with client_cert {}: {e}",
                        client.key.display(),
                        client.cert.display()
                    ),
                )
            })?
        }
    };
    Ok(Arc::new(config))
}

fn ca_roots(path: &Path) -> Result<RootCertStore, TlsSetupError> {
    let mut roots = RootCertStore::empty();
    for (i, cert) in certificates("ca_file", path)?.into_iter().enumerate() {
        roots.add(cert).map_err(|e| {
            error(
                "ca_file",
                format!(
                    "ca_file {}: certificate {} is not one rustls can trust: {e}",
                    path.display(),
                    i + 1
                ),
            )
        })?;
    }
    Ok(roots)
}

fn system_roots() -> Result<RootCertStore, TlsSetupError> {
    let found = rustls_native_certs::load_native_certs();
    let mut roots = RootCertStore::empty();
    let (added, _) = roots.add_parsable_certificates(found.certs);
    if added == 0 {
        let why = found
            .errors
            .first()
            .map_or_else(String::new, |e| format!(" ({e})"));
        return Err(error(
            "broker",
            format!(
                "no CA certificates found on this system{why}: name the broker's CA in the table's ca_file ([mqtt], [cfx])"
            ),
        ));
    }
    Ok(roots)
}

/// The certificates of the PEM file at `path`, for `key`; at least one.
fn certificates(
    key: &'static str,
    path: &Path,
) -> Result<Vec<CertificateDer<'static>>, TlsSetupError> {
    let bytes = read(key, path)?;
    let certs = CertificateDer::pem_slice_iter(&bytes)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| {
            error(
                key,
                format!("{key} {}: {}", path.display(), pem_problem(&e)),
            )
        })?;
    if certs.is_empty() {
        return Err(error(
            key,
            format!(
                "{key} {} holds no certificate (PEM, -----BEGIN CERTIFICATE-----)",
                path.display()
            ),
        ));
    }
    Ok(certs)
}

/// The private key of the PEM file at `path`; what it holds is never shown.
fn private_key(path: &Path) -> Result<PrivateKeyDer<'static>, TlsSetupError> {
    let bytes = read("client_key", path)?;
    PrivateKeyDer::from_pem_slice(&bytes).map_err(|e| {
        let what = match e {
            pem::Error::NoItemsFound => {
                "holds no private key (PEM: PKCS#8, PKCS#1 or SEC1)".to_owned()
            }
            e => pem_problem(&e),
        };
        error(
            "client_key",
            format!("client_key {}: {what}", path.display()),
        )
    })
}

/// What is wrong with a PEM file, without quoting it.
fn pem_problem(e: &pem::Error) -> String {
    match e {
        pem::Error::MissingSectionEnd { .. } => "not valid PEM: a section has no END line".into(),
        pem::Error::IllegalSectionStart { .. } => "not valid PEM: a malformed BEGIN line".into(),
        pem::Error::Base64Decode(_) => "not valid PEM: bad base64 in a section".into(),
        pem::Error::NoItemsFound => "holds nothing usable".into(),
        pem::Error::Io(e) => format!("cannot be read: {e}"),
        _ => "not valid PEM".into(),
    }
}

fn read(key: &'static str, path: &Path) -> Result<Vec<u8>, TlsSetupError> {
    crate::bounded::read_bounded(path, MAX_PEM).map_err(|why| {
        let why = if why.starts_with("is larger") {
            format!("{why}: not a PEM file")
        } else {
            why
        };
        error(key, format!("{key} {}: {why}", path.display()))
    })
}

/// What a lost or refused connection to `host:port` says; a TLS failure reads
/// "TLS handshake with broker HOST:PORT failed: …", with a hint for the usual causes. (A
/// broker that refuses the client's certificate says so once the handshake is done on
/// the client's side, while the client waits for its CONNACK: that too is reported as the
/// handshake's failure.)
pub fn describe(e: &ConnectionError, host: &str, port: u16) -> String {
    if let Some(tls) = rustls_error(e) {
        return handshake(tls, host, port);
    }
    match e {
        ConnectionError::Tls(e) => format!("TLS handshake with broker {host}:{port} failed: {e}"),
        e => e.to_string(),
    }
}

/// The rustls error behind `e`, through sources and I/O errors' inner errors.
fn rustls_error<'a>(e: &'a (dyn std::error::Error + 'static)) -> Option<&'a rustls::Error> {
    let mut next = Some(e);
    while let Some(e) = next {
        if let Some(found) = e.downcast_ref::<rustls::Error>() {
            return Some(found);
        }
        if let Some(inner) = e.downcast_ref::<io::Error>().and_then(io::Error::get_ref)
            && let Some(found) = rustls_error(inner)
        {
            return Some(found);
        }
        next = e.source();
    }
    None
}

fn handshake(e: &rustls::Error, host: &str, port: u16) -> String {
    let hint = match e {
        rustls::Error::InvalidCertificate(CertificateError::UnknownIssuer) => {
            " (no CA the gateway trusts signed the broker's certificate: check ca_file)"
        }
        rustls::Error::InvalidCertificate(
            CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. },
        ) => " (the broker's certificate is not for the host name in the broker URL)",
        rustls::Error::AlertReceived(
            AlertDescription::CertificateRequired
            | AlertDescription::BadCertificate
            | AlertDescription::UnknownCA
            | AlertDescription::HandshakeFailure,
        ) => " (the broker refused the gateway: check client_cert and client_key)",
        _ => "",
    };
    format!("TLS handshake with broker {host}:{port} failed: {e}{hint}")
}
