//! Open lines: send bytes, receive bytes before a deadline.

use std::io;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{Mutex, MutexGuard};
use tokio::time::Instant;
use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use crate::endpoint::{
    DataBits, DirectionControl, Echo, Endpoint, Parity, Rs485, SerialSettings, StopBits,
};

/// How long opening a `tcp://` line may take before it fails (a host that is off, or a
/// firewall that drops the connection, would otherwise hold it for minutes).
pub const TCP_CONNECT_TIMEOUT: Duration = Duration::from_secs(5);
/// Idle time before the OS starts probing a `tcp://` line that carries nothing.
pub const TCP_KEEPALIVE_IDLE: Duration = Duration::from_secs(30);
/// Time between keep-alive probes.
pub const TCP_KEEPALIVE_INTERVAL: Duration = Duration::from_secs(10);

/// The most [`Line::discard_input`] drops before a request: twice the largest message of
/// the protocols here (a Panasonic message may carry 4 MiB), and hours of a serial line.
pub const DISCARD_MOST: usize = 8 * 1024 * 1024;

/// Any byte stream a line can run over (a serial port, a TCP socket, an in-memory duplex).
pub trait Io: AsyncRead + AsyncWrite + Send + Unpin {}
impl<T: AsyncRead + AsyncWrite + Send + Unpin> Io for T {}

/// Why a line could not be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OpenError {
    /// The serial port could not be opened.
    #[error("cannot open serial port {path}: {reason}{hint}")]
    Serial {
        /// Device path.
        path: String,
        /// What the OS said.
        reason: String,
        /// What to try.
        hint: &'static str,
    },
    /// The TCP connection failed.
    #[error("cannot connect to {endpoint}: {source}{hint}")]
    Tcp {
        /// The endpoint that failed, as the user named it.
        endpoint: String,
        /// What the OS said.
        source: io::Error,
        /// What to try.
        hint: &'static str,
    },
}

/// What went wrong on an open line.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LineError {
    /// Nothing (complete) arrived before the deadline.
    #[error("no reply within {after:?}")]
    Timeout {
        /// How long we waited.
        after: Duration,
    },
    /// The other end closed the connection.
    #[error("the line was closed by the other end")]
    Closed,
    /// Our own echo did not come back as sent (the `echo=discard` setting does not match
    /// the adapter, or the bus is disturbed).
    #[error(
        "local echo mismatch: sent {sent:02X?}, read back {echoed:02X?}; check the echo= setting"
    )]
    Echo {
        /// What we sent.
        sent: Vec<u8>,
        /// What came back.
        echoed: Vec<u8>,
    },
    /// An I/O error.
    #[error("line I/O error: {0}")]
    Io(#[from] io::Error),
}

impl LineError {
    /// Whether the line is gone and must be reopened.
    pub fn is_fatal(&self) -> bool {
        matches!(self, Self::Closed | Self::Io(_))
    }
}

enum Stream {
    Serial(SerialStream),
    Other(Box<dyn Io>),
}

/// An open line.
pub struct Line {
    stream: Stream,
    name: String,
    settings: Option<SerialSettings>,
    rs485: Rs485,
    /// The line must stay quiet until then (a device's turnaround, an inter-frame gap).
    quiet_until: Option<Instant>,
    /// Whether input may still come that no request waits for (a reply after its
    /// timeout, the rest of a damaged one): the next [`Line::discard_input`] then lets the
    /// runtime look at the line first.
    unsettled: bool,
}

impl std::fmt::Debug for Line {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Line")
            .field("name", &self.name)
            .field("settings", &self.settings)
            .finish()
    }
}

impl Line {
    /// Opens `endpoint`.
    pub async fn open(endpoint: &Endpoint) -> Result<Self, OpenError> {
        match endpoint {
            Endpoint::Serial {
                path,
                settings,
                rs485,
            } => {
                let port = open_serial(path, settings)?;
                let mut line = Self {
                    stream: Stream::Serial(port),
                    name: endpoint.to_string(),
                    settings: Some(*settings),
                    rs485: *rs485,
                    quiet_until: None,
                    unsettled: false,
                };
                line.set_direction(false).map_err(|e| OpenError::Serial {
                    path: path.clone(),
                    reason: format!(
                        "cannot set {}: {e}",
                        rs485.direction.map(|d| d.to_string()).unwrap_or_default()
                    ),
                    hint: "; this adapter may not support modem-control lines, try without rs485=",
                })?;
                Ok(line)
            }
            Endpoint::Tcp {
                host, port, line, ..
            } => {
                let connect = TcpStream::connect((host.as_str(), *port));
                let connected = tokio::time::timeout(TCP_CONNECT_TIMEOUT, connect)
                    .await
                    .unwrap_or_else(|_| {
                        Err(io::Error::new(
                            io::ErrorKind::TimedOut,
                            format!("no connection within {TCP_CONNECT_TIMEOUT:?}"),
                        ))
                    });
                let stream = connected.map_err(|source| {
                    let hint = match source.kind() {
                        io::ErrorKind::ConnectionRefused => {
                            "; is the device (or its serial server, or the simulator) running, and is the port right?"
                        }
                        io::ErrorKind::TimedOut => {
                            "; is the host on, and does a firewall drop the connection?"
                        }
                        _ => "",
                    };
                    OpenError::Tcp {
                        endpoint: endpoint.to_string(),
                        source,
                        hint,
                    }
                })?;
                stream.set_nodelay(true).ok();
                // A serial server that vanishes (power cut, cable) is noticed even on a
                // line with nothing to send.
                let keepalive = socket2::TcpKeepalive::new()
                    .with_time(TCP_KEEPALIVE_IDLE)
                    .with_interval(TCP_KEEPALIVE_INTERVAL);
                if let Err(e) = socket2::SockRef::from(&stream).set_tcp_keepalive(&keepalive) {
                    tracing::debug!(%endpoint, "TCP keep-alive not set: {e}");
                }
                Ok(Self::from_stream(stream, endpoint.to_string(), *line))
            }
        }
    }

    /// A line over any byte stream: an in-memory duplex in tests, a simulated device
    /// in-process. `settings` is the serial line it stands for, if any (for timing).
    pub fn from_stream(
        stream: impl Io + 'static,
        name: impl Into<String>,
        settings: Option<SerialSettings>,
    ) -> Self {
        Self {
            stream: Stream::Other(Box::new(stream)),
            name: name.into(),
            settings,
            rs485: Rs485::default(),
            quiet_until: None,
            unsettled: false,
        }
    }

    /// The endpoint this line was opened on, for messages.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The serial line's settings, when known.
    pub fn settings(&self) -> Option<SerialSettings> {
        self.settings
    }

    /// Time `chars` characters take on the wire, or zero when the speed is unknown.
    pub fn wire_time(&self, chars: usize) -> Duration {
        self.settings.map(|s| s.time_for(chars)).unwrap_or_default()
    }

    /// Keeps the line quiet until `at`: the next [`send`](Self::send) waits for it. Protocols
    /// use it for turnaround windows (a Thermosald regulator holds the line 40 ms after its
    /// answer) and inter-frame gaps (Modbus RTU's 3.5 characters). It belongs to the line,
    /// not to a client, because every device on the line must respect it. A later call
    /// never shortens an earlier one.
    pub fn keep_quiet_until(&mut self, at: Instant) {
        self.quiet_until = Some(self.quiet_until.map_or(at, |quiet| quiet.max(at)));
    }

    /// Sends `bytes`: waits for the end of any quiet time, switches an RS-485 transceiver
    /// to transmit for their time on the wire, and reads back the adapter's echo when told to.
    pub async fn send(&mut self, bytes: &[u8]) -> Result<(), LineError> {
        if let Some(at) = self.quiet_until.take() {
            tokio::time::sleep_until(at).await;
        }
        self.set_direction(true)?;
        let written = self.write_all(bytes).await;
        if self.rs485.direction.is_some() {
            // The OS returns before the last bit leaves the UART: hold the transceiver in
            // transmit for the frame's time on the wire plus one character.
            tokio::time::sleep(self.wire_time(bytes.len() + 1)).await;
        }
        self.set_direction(false)?;
        written?;
        if self.rs485.echo == Echo::Discard {
            self.discard_echo(bytes).await?;
        }
        Ok(())
    }

    /// Reads what is available, waiting until `deadline` at the latest.
    pub async fn recv(&mut self, buf: &mut [u8], deadline: Instant) -> Result<usize, LineError> {
        // Bytes already there are taken without arming a timer (most reads of a fast line).
        if let Some(n) = self.read_ready(buf).await? {
            return Ok(n);
        }
        let started = Instant::now();
        let read = match &mut self.stream {
            Stream::Serial(port) => tokio::time::timeout_at(deadline, port.read(buf)).await,
            Stream::Other(stream) => tokio::time::timeout_at(deadline, stream.read(buf)).await,
        };
        match read {
            Err(_) => {
                self.unsettled = true;
                Err(LineError::Timeout {
                    after: deadline.saturating_duration_since(started),
                })
            }
            Ok(Ok(0)) => Err(LineError::Closed),
            Ok(Ok(n)) => Ok(n),
            Ok(Err(e)) => Err(LineError::Io(e)),
        }
    }

    /// Notes that input no request waits for may still come (an exchange ended without
    /// its answer: retried after a damaged reply, or given up): the next
    /// [`Line::discard_input`] looks harder. A receive that times out notes it itself.
    pub fn expect_late_input(&mut self) {
        self.unsettled = true;
    }

    /// Drops whatever has already arrived (a late reply to an earlier request), so the
    /// next request starts on a quiet line: at most [`DISCARD_MOST`] bytes, so a line
    /// that never stops talking does not hold the request back (what it says next is
    /// judged, and skipped, by the exchange).
    ///
    /// It never waits, nor arms a timer: a deadline of "now" would still cost a tick of
    /// tokio's 1 ms timer wheel per request, which is most of an exchange on a fast line,
    /// and even a far deadline is two trips through the timer wheel's lock.
    pub async fn discard_input(&mut self) -> Result<usize, LineError> {
        if std::mem::take(&mut self.unsettled) {
            // The runtime polls its I/O driver before it resumes a yielded task, so bytes
            // that reached the socket or port since it last looked are seen below. After
            // an answered exchange nothing is owed: what the runtime has seen is enough,
            // and the turn (a second wake of the line's task per request, about 6 % of a
            // point's CPU at 1,000 stations) is saved.
            tokio::task::yield_now().await;
        }
        let mut dropped = 0;
        let mut buf = [0u8; 256];
        while dropped < DISCARD_MOST {
            let Some(n) = self.read_ready(&mut buf).await? else {
                break;
            };
            dropped += n;
        }
        Ok(dropped)
    }

    /// Reads what has already arrived, without waiting: `Ok(None)` when nothing has,
    /// [`LineError::Closed`] at the end of the stream.
    async fn read_ready(&mut self, buf: &mut [u8]) -> Result<Option<usize>, LineError> {
        let stream = &mut self.stream;
        let polled = std::future::poll_fn(|cx| {
            let mut read = tokio::io::ReadBuf::new(buf);
            let result = match stream {
                Stream::Serial(port) => std::pin::Pin::new(port).poll_read(cx, &mut read),
                Stream::Other(other) => std::pin::Pin::new(other).poll_read(cx, &mut read),
            };
            std::task::Poll::Ready(match result {
                std::task::Poll::Pending => None,
                std::task::Poll::Ready(done) => Some(done.map(|()| read.filled().len())),
            })
        })
        .await;
        match polled {
            None => Ok(None),
            Some(Ok(0)) => Err(LineError::Closed),
            Some(Ok(n)) => Ok(Some(n)),
            Some(Err(e)) => Err(LineError::Io(e)),
        }
    }

    async fn write_all(&mut self, bytes: &[u8]) -> Result<(), LineError> {
        match &mut self.stream {
            Stream::Serial(port) => {
                port.write_all(bytes).await?;
                port.flush().await?;
            }
            Stream::Other(stream) => {
                stream.write_all(bytes).await?;
                stream.flush().await?;
            }
        }
        Ok(())
    }

    fn set_direction(&mut self, transmit: bool) -> Result<(), LineError> {
        let (Some(direction), Stream::Serial(port)) = (self.rs485.direction, &mut self.stream)
        else {
            return Ok(());
        };
        let to_io = |e: tokio_serial::Error| LineError::Io(io::Error::other(e.to_string()));
        if matches!(
            direction,
            DirectionControl::Rts | DirectionControl::RtsAndDtr
        ) {
            port.write_request_to_send(transmit).map_err(to_io)?;
        }
        if matches!(
            direction,
            DirectionControl::Dtr | DirectionControl::RtsAndDtr
        ) {
            port.write_data_terminal_ready(transmit).map_err(to_io)?;
        }
        Ok(())
    }

    async fn discard_echo(&mut self, sent: &[u8]) -> Result<(), LineError> {
        let mut echoed = vec![0u8; sent.len()];
        let mut got = 0;
        // The echo arrives within the frame's wire time; allow generous slack for USB latency.
        let deadline = Instant::now() + self.wire_time(sent.len()) + Duration::from_millis(100);
        while got < sent.len() {
            match self.recv(&mut echoed[got..], deadline).await {
                Ok(n) => got += n,
                Err(LineError::Timeout { .. }) => break,
                Err(e) => return Err(e),
            }
        }
        echoed.truncate(got);
        if echoed != sent {
            return Err(LineError::Echo {
                sent: sent.to_vec(),
                echoed,
            });
        }
        Ok(())
    }
}

fn open_serial(path: &str, settings: &SerialSettings) -> Result<SerialStream, OpenError> {
    let builder = tokio_serial::new(path, settings.baud)
        .data_bits(match settings.data_bits {
            DataBits::Five => tokio_serial::DataBits::Five,
            DataBits::Six => tokio_serial::DataBits::Six,
            DataBits::Seven => tokio_serial::DataBits::Seven,
            DataBits::Eight => tokio_serial::DataBits::Eight,
        })
        .parity(match settings.parity {
            Parity::None => tokio_serial::Parity::None,
            Parity::Even => tokio_serial::Parity::Even,
            Parity::Odd => tokio_serial::Parity::Odd,
        })
        .stop_bits(match settings.stop_bits {
            StopBits::One => tokio_serial::StopBits::One,
            StopBits::Two => tokio_serial::StopBits::Two,
        })
        .flow_control(tokio_serial::FlowControl::None);
    builder.open_native_async().map_err(|e| {
        let hint = match e.kind() {
            tokio_serial::ErrorKind::NoDevice => {
                "; check the device path and the cable (ls /dev/serial/by-id lists the adapters)"
            }
            tokio_serial::ErrorKind::Io(io::ErrorKind::NotFound) if !path.starts_with('/') => {
                "; no such device: a path without a leading / is relative to the working directory"
            }
            tokio_serial::ErrorKind::Io(io::ErrorKind::NotFound) => {
                "; no such device: check the path (ls /dev/serial/by-id lists the adapters)"
            }
            tokio_serial::ErrorKind::Io(io::ErrorKind::PermissionDenied) => {
                "; permission denied: add your user to the dialout group (sudo usermod -aG dialout $USER) and log in again"
            }
            _ if e.description.contains("busy") || e.description.contains("ermission") => {
                "; the port may be in use by another program, or your user may need the dialout group"
            }
            _ => "",
        };
        OpenError::Serial { path: path.to_owned(), reason: e.description, hint }
    })
}

/// A line shared by several devices: one request at a time, in the order they ask
/// (tokio's mutex is fair), never interleaved.
#[derive(Debug, Clone)]
pub struct SharedLine(Arc<Mutex<Line>>);

impl SharedLine {
    /// Shares `line`.
    pub fn new(line: Line) -> Self {
        Self(Arc::new(Mutex::new(line)))
    }

    /// Waits for the line; it is ours until the guard is dropped.
    pub async fn lock(&self) -> MutexGuard<'_, Line> {
        self.0.lock().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line over a real loopback connection, and the device's end of it.
    async fn tcp_line() -> (Line, tokio::net::TcpStream) {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (ours, theirs) = tokio::join!(tokio::net::TcpStream::connect(addr), listener.accept());
        let line = Line::from_stream(ours.unwrap(), "tcp test", None);
        (line, theirs.unwrap().0)
    }

    #[tokio::test(start_paused = true)]
    async fn a_reply_that_comes_after_its_timeout_is_dropped_before_the_next_request() {
        let (mut line, mut device) = tcp_line().await;
        let mut buf = [0u8; 16];
        let deadline = Instant::now() + Duration::from_millis(100);
        let timeout = line.recv(&mut buf, deadline).await.unwrap_err();
        assert!(matches!(timeout, LineError::Timeout { .. }), "{timeout:?}");
        // The device answers at last, just before our next request.
        device.write_all(b"late\n").await.unwrap();
        assert_eq!(line.discard_input().await.unwrap(), 5);
        device.write_all(b"answer\n").await.unwrap();
        let n = line
            .recv(&mut buf, Instant::now() + Duration::from_secs(1))
            .await
            .unwrap();
        assert_eq!(&buf[..n], b"answer\n");
    }

    #[tokio::test(start_paused = true)]
    async fn after_an_exchange_ended_without_its_answer_late_input_is_dropped_too() {
        let (mut line, mut device) = tcp_line().await;
        line.expect_late_input();
        device.write_all(b"rest of a damaged reply").await.unwrap();
        assert_eq!(line.discard_input().await.unwrap(), 23);
    }

    #[tokio::test]
    async fn opening_a_missing_serial_port_names_the_path_and_gives_a_hint() {
        let endpoint = Endpoint::parse(
            "serial:///dev/cellbus-no-such-port",
            SerialSettings::new_8n1(9600),
        )
        .unwrap();
        let err = Line::open(&endpoint).await.unwrap_err().to_string();
        assert!(err.contains("/dev/cellbus-no-such-port"), "{err}");
        assert!(err.contains("check the"), "{err}");
    }

    #[tokio::test]
    async fn opening_a_missing_relative_serial_port_says_where_it_was_looked_for() {
        let endpoint =
            Endpoint::parse("cellbus-no-such-dir/jbc1", SerialSettings::new_8n1(9600)).unwrap();
        let err = Line::open(&endpoint).await.unwrap_err().to_string();
        assert!(
            err.starts_with("cannot open serial port cellbus-no-such-dir/jbc1: "),
            "{err}"
        );
        assert!(err.contains("relative to the working directory"), "{err}");
    }

    #[tokio::test]
    async fn connecting_to_a_closed_tcp_port_says_what_to_check() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        drop(listener);
        let endpoint = Endpoint::parse(
            &format!("tcp://127.0.0.1:{port}"),
            SerialSettings::new_8n1(9600),
        )
        .unwrap();
        let err = Line::open(&endpoint).await.unwrap_err().to_string();
        assert!(err.contains(&format!("127.0.0.1:{port}")), "{err}");
        assert!(
            err.contains("is the device (or its serial server, or the simulator) running"),
            "{err}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn recv_times_out_at_the_deadline() {
        let (a, _b) = tokio::io::duplex(64);
        let mut line = Line::from_stream(a, "test", None);
        let mut buf = [0u8; 8];
        let err = line
            .recv(&mut buf, Instant::now() + Duration::from_millis(300))
            .await
            .unwrap_err();
        assert!(matches!(err, LineError::Timeout { after } if after == Duration::from_millis(300)));
    }

    #[tokio::test(start_paused = true)]
    async fn send_waits_for_the_quiet_time_and_the_longest_one_wins() {
        let (a, mut b) = tokio::io::duplex(64);
        let mut line = Line::from_stream(a, "test", None);
        let started = Instant::now();
        line.keep_quiet_until(started + Duration::from_millis(40));
        line.keep_quiet_until(started + Duration::from_millis(10));
        line.send(b"x").await.unwrap();
        assert_eq!(started.elapsed(), Duration::from_millis(40));
        let mut buf = [0u8; 1];
        b.read_exact(&mut buf).await.unwrap();
        // Once waited for, the quiet time is spent.
        line.send(b"y").await.unwrap();
        assert_eq!(started.elapsed(), Duration::from_millis(40));
    }

    #[tokio::test(start_paused = true)]
    async fn discard_input_drops_what_already_arrived() {
        let (a, mut b) = tokio::io::duplex(64);
        let mut line = Line::from_stream(a, "test", None);
        b.write_all(b"late reply").await.unwrap();
        assert_eq!(line.discard_input().await.unwrap(), 10);
        b.write_all(b"x").await.unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(
            line.recv(&mut buf, Instant::now() + Duration::from_secs(1))
                .await
                .unwrap(),
            1
        );
    }

    #[tokio::test(start_paused = true)]
    async fn echo_discard_drops_our_own_bytes_and_reports_a_mismatch() {
        let (a, mut b) = tokio::io::duplex(64);
        let mut line = Line::from_stream(a, "test", Some(SerialSettings::new_8n1(9600)));
        line.rs485.echo = Echo::Discard;
        // An adapter that echoes faithfully, then one that garbles the echo.
        let echo = tokio::spawn(async move {
            let mut buf = [0u8; 5];
            b.read_exact(&mut buf).await.unwrap();
            b.write_all(&buf).await.unwrap();
            b.write_all(b"REPLY").await.unwrap();
            b.read_exact(&mut buf).await.unwrap();
            b.write_all(b"hellO").await.unwrap();
            b
        });
        line.send(b"hello").await.unwrap();
        let mut buf = [0u8; 8];
        let n = line
            .recv(&mut buf, Instant::now() + Duration::from_secs(1))
            .await
            .unwrap();
        assert_eq!(&buf[..n], b"REPLY");
        let err = line.send(b"hello").await.unwrap_err();
        assert!(
            matches!(err, LineError::Echo { ref echoed, .. } if echoed == b"hellO"),
            "{err}"
        );
        echo.await.unwrap();
    }
}
