//! Endpoint URLs and serial settings.
//!
//! ```text
//! serial:///dev/ttyUSB0?baud=19200&framing=8E1
//! serial:///dev/ttyUSB1?baud=9600&rs485=rts&echo=discard
//! /dev/ttyUSB0                      (a bare device path is a serial endpoint)
//! pty/jbc1?baud=9600                (…relative to the working directory; ./pty/jbc1 too)
//! tcp://192.0.2.10:4001             (raw bytes over TCP: ser2net, Moxa NPort, our simulators)
//! tcp://127.0.0.1:5020?baud=9600    (…behind which is a 9600-baud line: timing follows it)
//! modbus-tcp://192.0.2.20:502       (TCP whose protocol frames its own messages: Modbus TCP)
//! modbus-tcp://192.0.2.20           (port 502 unless given)
//! ```
//!
//! `link` frames nothing itself: a `modbus-tcp://` endpoint is a TCP line like any other,
//! and [`TcpFraming::Mbap`] tells the protocol crate that reads the endpoint to frame its
//! messages with the Modbus TCP (MBAP) header instead of sending raw serial frames.
//!
//! Settings a URL leaves out come from the protocol's defaults (JBC: 19200 8E1;
//! Thermosald and CROSS: 9600 8N1).
//!
//! A URL has no room for a relative path: `serial://pty/jbc1` would name host `pty`, so it
//! is refused rather than read as `/pty/jbc1`. A relative path is written without a scheme.

use std::borrow::Cow;
use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use url::Url;

/// Lowest and highest baud rate accepted. Every JBC speed (1200–500000) is inside.
pub const BAUD_RANGE: std::ops::RangeInclusive<u32> = 50..=4_000_000;

/// Where a line is and how to talk on it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// A serial port on this machine.
    Serial {
        /// Device path, e.g. `/dev/ttyUSB0`, or relative to the working directory
        /// (`pty/jbc1`).
        path: String,
        /// Speed and framing.
        settings: SerialSettings,
        /// RS-485 direction control and echo handling.
        rs485: Rs485,
    },
    /// Raw bytes over TCP.
    Tcp {
        /// Host name or address.
        host: String,
        /// TCP port.
        port: u16,
        /// The serial line behind the TCP server, when the URL names one (`?baud=…`): the
        /// clients derive their timing from it.
        line: Option<SerialSettings>,
        /// How messages are framed on the connection: raw serial frames (`tcp://`) or
        /// Modbus TCP (`modbus-tcp://`).
        framing: TcpFraming,
    },
}

/// How the bytes on a TCP endpoint are framed: the URL's scheme says it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum TcpFraming {
    /// `tcp://`: the serial frames as they are on the line behind a serial server.
    #[default]
    Raw,
    /// `modbus-tcp://`: Modbus TCP, each message behind an MBAP header (transaction id,
    /// length, unit id), no CRC.
    Mbap,
}

/// The Modbus TCP port a `modbus-tcp://` URL without a port connects to.
pub const MODBUS_TCP_PORT: u16 = 502;

/// What is wrong with an endpoint URL.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EndpointError {
    /// Not a URL at all.
    #[error(
        "endpoint {url:?} is not a URL ({reason}); write serial:///dev/ttyUSB0, tcp://host:port or modbus-tcp://host:port"
    )]
    NotAUrl {
        /// The text given.
        url: String,
        /// What the URL parser said.
        reason: String,
    },
    /// A scheme other than `serial`, `tcp` or `modbus-tcp`.
    #[error(
        "endpoint {url:?} has scheme {scheme:?}; cellbus speaks serial://, tcp:// and modbus-tcp://"
    )]
    Scheme {
        /// The text given.
        url: String,
        /// The scheme found.
        scheme: String,
    },
    /// A serial URL without a device path.
    #[error("endpoint {url:?} names no serial device; write serial:///dev/ttyUSB0")]
    NoPath {
        /// The text given.
        url: String,
    },
    /// A serial URL with a host part (`serial://pty/jbc1`): a serial port has no host, and
    /// reading the host as the path's first directory would guess.
    #[error(
        "endpoint {url:?} reads {host:?} as a host name, and a serial port has none; write \
         serial:///{host}{path} (three slashes) for the absolute path /{host}{path}, or \
         {host}{path} without serial:// for a path relative to the working directory"
    )]
    SerialHost {
        /// The text given.
        url: String,
        /// The host part, most likely the path's first directory.
        host: String,
        /// The rest of the path.
        path: String,
    },
    /// `HOST:PORT` without a scheme.
    #[error(
        "endpoint {url:?} looks like HOST:PORT; write tcp://{url} (a serial server or a \
         simulator) or modbus-tcp://{url} (Modbus TCP)"
    )]
    HostPort {
        /// The text given.
        url: String,
    },
    /// A TCP URL without host or port.
    #[error("endpoint {url:?} needs a host and a port: tcp://host:port")]
    NoHostPort {
        /// The text given.
        url: String,
    },
    /// An option with a bad value.
    #[error("endpoint {url:?}: option {option}={value:?} is not valid: {expected}")]
    Option {
        /// The text given.
        url: String,
        /// The option name.
        option: String,
        /// The value given.
        value: String,
        /// What would be accepted.
        expected: String,
    },
    /// An option this endpoint does not know.
    #[error("endpoint {url:?}: unknown option {option:?} (known: {known})")]
    UnknownOption {
        /// The text given.
        url: String,
        /// The option name.
        option: String,
        /// The options this kind of endpoint takes.
        known: &'static str,
    },
}

const SERIAL_OPTIONS: &str = "baud, framing, rs485, echo";
const TCP_OPTIONS: &str = "baud, framing";
const MODBUS_TCP_OPTIONS: &str = "none: Modbus TCP carries no serial settings";

impl Endpoint {
    /// Parses `text`, taking the settings it leaves out from `defaults`. Text without a
    /// scheme is a serial device's path, absolute or relative to the working directory,
    /// optionally followed by `?options`.
    pub fn parse(text: &str, defaults: SerialSettings) -> Result<Self, EndpointError> {
        let text = text.trim();
        if looks_like_host_port(text) {
            return Err(EndpointError::HostPort {
                url: text.to_owned(),
            });
        }
        let url = match Url::parse(text) {
            Ok(url) => url,
            Err(url::ParseError::RelativeUrlWithoutBase) => {
                let (path, query) = text.split_once('?').unwrap_or((text, ""));
                let options = url::form_urlencoded::parse(query.as_bytes());
                return Self::serial(text, path.to_owned(), options, defaults);
            }
            Err(e) => {
                return Err(EndpointError::NotAUrl {
                    url: text.to_owned(),
                    reason: e.to_string(),
                });
            }
        };
        match url.scheme() {
            "serial" => Self::parse_serial(text, &url, defaults),
            "tcp" => Self::parse_tcp(text, &url, defaults),
            "modbus-tcp" => Self::parse_modbus_tcp(text, &url),
            other => Err(EndpointError::Scheme {
                url: text.to_owned(),
                scheme: other.to_owned(),
            }),
        }
    }

    fn parse_serial(
        text: &str,
        url: &Url,
        defaults: SerialSettings,
    ) -> Result<Self, EndpointError> {
        if let Some(host) = url.host_str().filter(|h| !h.is_empty()) {
            return Err(EndpointError::SerialHost {
                url: text.to_owned(),
                host: host.to_owned(),
                path: url.path().to_owned(),
            });
        }
        Self::serial(text, url.path().to_owned(), url.query_pairs(), defaults)
    }

    /// A serial endpoint at `path` with `options` (`baud`, `framing`, `rs485`, `echo`).
    fn serial<'a>(
        text: &str,
        path: String,
        options: impl Iterator<Item = (Cow<'a, str>, Cow<'a, str>)>,
        defaults: SerialSettings,
    ) -> Result<Self, EndpointError> {
        if path.is_empty() || path == "/" {
            return Err(EndpointError::NoPath {
                url: text.to_owned(),
            });
        }
        let mut settings = defaults;
        let mut rs485 = Rs485::default();
        for (key, value) in options {
            let bad = |expected: &str| EndpointError::Option {
                url: text.to_owned(),
                option: key.to_string(),
                value: value.to_string(),
                expected: expected.to_owned(),
            };
            match &*key {
                "baud" => settings.baud = parse_baud(&value).map_err(|e| bad(&e))?,
                "framing" => settings.set_framing(&value).map_err(|e| bad(&e))?,
                "rs485" => rs485.direction = Some(value.parse().map_err(|e: String| bad(&e))?),
                "echo" => rs485.echo = value.parse().map_err(|e: String| bad(&e))?,
                _ => {
                    return Err(EndpointError::UnknownOption {
                        url: text.to_owned(),
                        option: key.to_string(),
                        known: SERIAL_OPTIONS,
                    });
                }
            }
        }
        Ok(Self::Serial {
            path,
            settings,
            rs485,
        })
    }

    fn parse_tcp(text: &str, url: &Url, defaults: SerialSettings) -> Result<Self, EndpointError> {
        let no_host = || EndpointError::NoHostPort {
            url: text.to_owned(),
        };
        let host = url
            .host_str()
            .filter(|h| !h.is_empty())
            .ok_or_else(no_host)?;
        let host = host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .to_owned();
        let port = url.port().ok_or_else(no_host)?;
        let mut line: Option<SerialSettings> = None;
        for (key, value) in url.query_pairs() {
            let bad = |expected: &str| EndpointError::Option {
                url: text.to_owned(),
                option: key.to_string(),
                value: value.to_string(),
                expected: expected.to_owned(),
            };
            let settings = line.get_or_insert(defaults);
            match &*key {
                "baud" => settings.baud = parse_baud(&value).map_err(|e| bad(&e))?,
                "framing" => settings.set_framing(&value).map_err(|e| bad(&e))?,
                _ => {
                    return Err(EndpointError::UnknownOption {
                        url: text.to_owned(),
                        option: key.to_string(),
                        known: TCP_OPTIONS,
                    });
                }
            }
        }
        Ok(Self::Tcp {
            host,
            port,
            line,
            framing: TcpFraming::Raw,
        })
    }

    fn parse_modbus_tcp(text: &str, url: &Url) -> Result<Self, EndpointError> {
        let host = url
            .host_str()
            .filter(|h| !h.is_empty())
            .ok_or_else(|| EndpointError::NoHostPort {
                url: text.to_owned(),
            })?
            .trim_start_matches('[')
            .trim_end_matches(']')
            .to_owned();
        if let Some((key, _)) = url.query_pairs().next() {
            return Err(EndpointError::UnknownOption {
                url: text.to_owned(),
                option: key.to_string(),
                known: MODBUS_TCP_OPTIONS,
            });
        }
        Ok(Self::Tcp {
            host,
            port: url.port().unwrap_or(MODBUS_TCP_PORT),
            line: None,
            framing: TcpFraming::Mbap,
        })
    }

    /// Whether the endpoint carries Modbus TCP (`modbus-tcp://`).
    pub fn is_mbap(&self) -> bool {
        matches!(
            self,
            Self::Tcp {
                framing: TcpFraming::Mbap,
                ..
            }
        )
    }

    /// The serial line's settings, where the endpoint has or names one.
    pub fn line_settings(&self) -> Option<SerialSettings> {
        match self {
            Self::Serial { settings, .. } => Some(*settings),
            Self::Tcp { line, .. } => *line,
        }
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Serial {
                path,
                settings,
                rs485,
            } => {
                // A relative path has no URL form: it is written as given, as it is parsed.
                let scheme = if path.starts_with('/') {
                    "serial://"
                } else {
                    ""
                };
                write!(
                    f,
                    "{scheme}{path}?baud={}&framing={}",
                    settings.baud,
                    settings.framing()
                )?;
                if let Some(direction) = rs485.direction {
                    write!(f, "&rs485={direction}")?;
                }
                if rs485.echo == Echo::Discard {
                    write!(f, "&echo=discard")?;
                }
                Ok(())
            }
            Self::Tcp {
                host,
                port,
                line,
                framing,
            } => {
                let scheme = match framing {
                    TcpFraming::Raw => "tcp",
                    TcpFraming::Mbap => "modbus-tcp",
                };
                if host.contains(':') {
                    write!(f, "{scheme}://[{host}]:{port}")?;
                } else {
                    write!(f, "{scheme}://{host}:{port}")?;
                }
                if let Some(settings) = line {
                    write!(f, "?baud={}&framing={}", settings.baud, settings.framing())?;
                }
                Ok(())
            }
        }
    }
}

/// `host:4001`, `192.0.2.10:4001`, `[::1]:502`: a TCP address given without its scheme.
fn looks_like_host_port(text: &str) -> bool {
    !text.contains('/')
        && text.rsplit_once(':').is_some_and(|(host, port)| {
            !host.is_empty() && !port.is_empty() && port.bytes().all(|b| b.is_ascii_digit())
        })
}

fn parse_baud(value: &str) -> Result<u32, String> {
    let expected = || {
        format!(
            "a speed in bit/s from {} to {}",
            BAUD_RANGE.start(),
            BAUD_RANGE.end()
        )
    };
    let baud: u32 = value.parse().map_err(|_| expected())?;
    if BAUD_RANGE.contains(&baud) {
        Ok(baud)
    } else {
        Err(expected())
    }
}

/// Speed and character framing of a serial line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialSettings {
    /// Bits per second.
    pub baud: u32,
    /// Data bits per character.
    pub data_bits: DataBits,
    /// Parity bit.
    pub parity: Parity,
    /// Stop bits.
    pub stop_bits: StopBits,
}

/// Data bits per character.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataBits {
    /// 5 bits.
    Five,
    /// 6 bits.
    Six,
    /// 7 bits.
    Seven,
    /// 8 bits.
    Eight,
}

/// Parity bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parity {
    /// No parity bit (`N`).
    None,
    /// Even parity (`E`).
    Even,
    /// Odd parity (`O`).
    Odd,
}

/// Stop bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopBits {
    /// One stop bit.
    One,
    /// Two stop bits.
    Two,
}

impl SerialSettings {
    /// 8 data bits, no parity, 1 stop bit at `baud` (Thermosald, CROSS).
    pub const fn new_8n1(baud: u32) -> Self {
        Self {
            baud,
            data_bits: DataBits::Eight,
            parity: Parity::None,
            stop_bits: StopBits::One,
        }
    }

    /// 8 data bits, even parity, 1 stop bit at `baud` (the JBC manual's example, 19200-8E1).
    pub const fn new_8e1(baud: u32) -> Self {
        Self {
            baud,
            data_bits: DataBits::Eight,
            parity: Parity::Even,
            stop_bits: StopBits::One,
        }
    }

    /// Bits on the wire per character: start, data, parity and stop bits.
    pub fn bits_per_char(&self) -> u32 {
        let data = match self.data_bits {
            DataBits::Five => 5,
            DataBits::Six => 6,
            DataBits::Seven => 7,
            DataBits::Eight => 8,
        };
        let parity = u32::from(self.parity != Parity::None);
        let stop = match self.stop_bits {
            StopBits::One => 1,
            StopBits::Two => 2,
        };
        1 + data + parity + stop
    }

    /// Time one character takes on the wire.
    pub fn char_time(&self) -> Duration {
        Duration::from_nanos(
            u64::from(self.bits_per_char()) * 1_000_000_000 / u64::from(self.baud.max(1)),
        )
    }

    /// Time `chars` characters take on the wire.
    pub fn time_for(&self, chars: usize) -> Duration {
        let bits = u64::from(self.bits_per_char()) * chars as u64;
        Duration::from_nanos(bits.saturating_mul(1_000_000_000) / u64::from(self.baud.max(1)))
    }

    /// The framing as written in URLs and manuals: `8E1`.
    pub fn framing(&self) -> String {
        let data = self.bits_per_char()
            - 1
            - u32::from(self.parity != Parity::None)
            - if self.stop_bits == StopBits::Two {
                2
            } else {
                1
            };
        let parity = match self.parity {
            Parity::None => 'N',
            Parity::Even => 'E',
            Parity::Odd => 'O',
        };
        let stop = if self.stop_bits == StopBits::Two {
            2
        } else {
            1
        };
        format!("{data}{parity}{stop}")
    }

    /// Sets data bits, parity and stop bits from text like `8E1`.
    pub fn set_framing(&mut self, text: &str) -> Result<(), String> {
        let expected = || "data bits 5-8, parity N/E/O, stop bits 1/2, e.g. 8N1 or 8E1".to_owned();
        let [d, p, s] = text.as_bytes() else {
            return Err(expected());
        };
        self.data_bits = match d {
            b'5' => DataBits::Five,
            b'6' => DataBits::Six,
            b'7' => DataBits::Seven,
            b'8' => DataBits::Eight,
            _ => return Err(expected()),
        };
        self.parity = match p.to_ascii_uppercase() {
            b'N' => Parity::None,
            b'E' => Parity::Even,
            b'O' => Parity::Odd,
            _ => return Err(expected()),
        };
        self.stop_bits = match s {
            b'1' => StopBits::One,
            b'2' => StopBits::Two,
            _ => return Err(expected()),
        };
        Ok(())
    }
}

impl fmt::Display for SerialSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.baud, self.framing())
    }
}

/// RS-485 half-duplex handling on a serial port.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rs485 {
    /// Which modem-control line switches the transceiver to transmit (held at 1 while
    /// sending); `None` when the adapter switches by itself.
    pub direction: Option<DirectionControl>,
    /// What to do with the adapter's local echo of what we send.
    pub echo: Echo,
}

/// Modem-control lines that switch an RS-485 transceiver's direction (1 = transmit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DirectionControl {
    /// `rs485=rts`.
    Rts,
    /// `rs485=dtr`.
    Dtr,
    /// `rs485=rts+dtr`: both lines.
    RtsAndDtr,
}

impl FromStr for DirectionControl {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "rts" => Ok(Self::Rts),
            "dtr" => Ok(Self::Dtr),
            "rts+dtr" | "rts,dtr" | "both" => Ok(Self::RtsAndDtr),
            _ => Err("rts, dtr or rts+dtr (the line held at 1 while transmitting)".to_owned()),
        }
    }
}

impl fmt::Display for DirectionControl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Rts => "rts",
            Self::Dtr => "dtr",
            Self::RtsAndDtr => "rts+dtr",
        })
    }
}

/// Local echo handling: many USB–RS-485 adapters return every byte they send.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Echo {
    /// The adapter does not echo (`echo=none`, the default).
    #[default]
    None,
    /// Read back and drop our own bytes after each send (`echo=discard`).
    Discard,
}

impl FromStr for Echo {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "none" | "off" => Ok(Self::None),
            "discard" => Ok(Self::Discard),
            _ => Err("none or discard".to_owned()),
        }
    }
}

#[cfg(test)]
mod tests;
