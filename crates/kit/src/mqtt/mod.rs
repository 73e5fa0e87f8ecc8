//! The MQTT connection kit of the gateway, the historian and `cellbus mqtt sub`: broker
//! URLs ([`parse_broker`]), the TLS files ([`MqttTls`]) and the rustls setup ([`tls`]),
//! and the largest packet a client accepts ([`MAX_INCOMING`]).

use std::path::PathBuf;

pub mod tls;

/// Largest MQTT packet accepted: any the protocol allows (its remaining length's maximum,
/// 256 MiB). A smaller bound would not protect anything: the client drops the connection
/// on a larger packet, and a retained one (or one kept for a persistent session) comes
/// again at every reconnection, so one message would keep the link down for good. What a
/// message says is checked after it is read.
pub const MAX_INCOMING: usize = 268_435_455;

/// TLS to the broker (`mqtts://`): whom to trust and what to show. The files are PEM; a
/// relative path in the config file is relative to the file's directory.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MqttTls {
    /// `ca_file`: the CA certificates that sign the broker's; `None`: the system's roots.
    pub ca_file: Option<PathBuf>,
    /// `client_cert` and `client_key`: the certificate (chain) and private key the client
    /// shows a broker that asks for one.
    pub client: Option<MqttClientCert>,
}

/// A client certificate for the broker: `client_cert` and `client_key`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttClientCert {
    /// The certificate, then any intermediates (PEM).
    pub cert: PathBuf,
    /// Its private key (PEM: PKCS#8, PKCS#1 or SEC1).
    pub key: PathBuf,
}

/// A broker URL, read by [`parse_broker`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broker {
    /// The host.
    pub host: String,
    /// The port (1883 for `mqtt://`, 8883 for `mqtts://` when the URL has none).
    pub port: u16,
    /// `mqtts://`: TLS.
    pub tls: bool,
}

/// Reads `mqtt://host[:port]` (port 1883 by default) or `mqtts://host[:port]` (TLS, port
/// 8883 by default).
pub fn parse_broker(given: &str) -> Result<Broker, String> {
    // Errors show the URL without its user name and password.
    let text = &hide_userinfo(given);
    let url = url::Url::parse(given.trim())
        .map_err(|e| format!("broker {text:?} is not a URL ({e}); write mqtt://host:1883"))?;
    let (tls, default_port) = match url.scheme() {
        "mqtt" => (false, 1883),
        "mqtts" => (true, 8883),
        other => {
            return Err(format!(
                "broker {text:?} has scheme {other:?}; write mqtt://host:1883 or mqtts://host:8883"
            ));
        }
    };
    let host = url
        .host_str()
        .filter(|h| !h.is_empty())
        .ok_or_else(|| format!("broker {text:?} names no host; write mqtt://host:1883"))?;
    if url.path().len() > 1 || url.query().is_some() || !url.username().is_empty() {
        return Err(format!(
            "broker {text:?}: write only mqtt://host:port (user name and password go in username and password_env)"
        ));
    }
    let host = host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .to_owned();
    let port = url.port().unwrap_or(default_port);
    if port == 0 {
        return Err(format!(
            "broker {text:?}: port 0 is not a port a broker listens on; write mqtt://host:1883"
        ));
    }
    Ok(Broker { host, port, tls })
}

/// `text` with what comes before an `@` in a URL's authority (a user name and a password)
/// shown as `(hidden)`.
pub fn hide_userinfo(text: &str) -> String {
    let Some((scheme, rest)) = text.split_once("://") else {
        return text.to_owned();
    };
    let end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    match rest[..end].rfind('@') {
        Some(at) => format!("{scheme}://(hidden){}", &rest[at..]),
        None => text.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broker_url_gives_host_port_and_tls_with_the_schemes_default_port() {
        let broker = |host: &str, port, tls| Broker {
            host: host.to_owned(),
            port,
            tls,
        };
        for (url, host, port, tls) in [
            ("mqtt://broker.local", "broker.local", 1883, false),
            (" mqtts://broker.local ", "broker.local", 8883, true),
            ("mqtts://b:18883", "b", 18883, true),
            ("mqtt://[::1]:1884", "::1", 1884, false),
        ] {
            assert_eq!(parse_broker(url), Ok(broker(host, port, tls)), "{url:?}");
        }
    }

    #[test]
    fn a_broker_url_that_is_not_one_is_refused_saying_what_to_write() {
        for (given, words) in [
            ("broker.local", "is not a URL"),
            ("http://b:1883", "has scheme \"http\""),
            ("mqtt://b:0", "port 0 is not a port a broker listens on"),
            ("mqtt://b:1883/topic", "write only mqtt://host:port"),
            ("mqtt://b:1883?x=1", "write only mqtt://host:port"),
        ] {
            let err = parse_broker(given).unwrap_err();
            assert!(err.contains(words), "{given}: {err}");
        }
    }

    #[test]
    fn a_broker_url_with_a_user_and_password_is_refused_without_showing_them() {
        let err = parse_broker("mqtt://user:pw@127.0.0.1:1883").unwrap_err();
        assert!(!err.contains("pw") && !err.contains("user:"), "{err}");
        assert!(err.contains("mqtt://(hidden)@127.0.0.1:1883"), "{err}");
        assert_eq!(
            hide_userinfo("mqtt://host:1883/a@b"),
            "mqtt://host:1883/a@b"
        );
        assert_eq!(hide_userinfo("no scheme@all"), "no scheme@all");
    }
}
