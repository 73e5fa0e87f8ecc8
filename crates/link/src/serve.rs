//! Serving a simulated device on a TCP listener, a PTY or any byte stream.
//!
//! Over loopback a reply arrives in microseconds; a real 9600-baud line needs about a
//! millisecond per character. With a [`SerialSettings`] given as `pace`, the serve loop
//! behaves like the real half-duplex line: a request reaches the device only when its last
//! character would have arrived, and a reply leaves at the line's character rate, never
//! overlapping other traffic. Poll-rate measurements over loopback then mean what they
//! would on the wire.
//!
//! Each device is told the line's timing before any input ([`Device::set_timing`]), so it
//! drops a half frame after its protocol's silence on a paced line, or after
//! [`wire::device::UNPACED_FRAME_GAP`] on an unpaced one: a damaged request can never leave
//! a simulator waiting for bytes that do not come.

use std::collections::VecDeque;
use std::io;
use std::path::{Path, PathBuf};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::time::Instant;
use tokio_serial::{SerialPort, SerialStream};
use wire::{Device, LineTiming};

use crate::endpoint::SerialSettings;
use crate::line::Io;

/// Serves `device` on one byte stream until the other end closes it.
pub async fn serve_stream<S: Io, D: Device>(
    stream: S,
    mut device: D,
    pace: Option<SerialSettings>,
) -> io::Result<()> {
    device.set_timing(LineTiming::paced(pace.map(|line| line.char_time())));
    let (mut reader, mut writer) = tokio::io::split(stream);
    let mut events = Schedule::default();
    let mut buf = vec![0u8; 4096];
    loop {
        let next = events.next_at();
        tokio::select! {
            read = reader.read(&mut buf) => {
                let n = read?;
                if n == 0 {
                    return Ok(());
                }
                let now = Instant::now();
                match pace {
                    // The device hears the request when its last character has arrived.
                    Some(line) => {
                        let heard = events.occupy(now, line.time_for(n));
                        events.push(heard, Event::Hear(buf[..n].to_vec()));
                    }
                    None => {
                        for tx in device.receive(&buf[..n], now.into_std()) {
                            events.push(now + tx.delay, Event::Start(tx.bytes));
                        }
                    }
                }
            }
            () = sleep_until(next), if next.is_some() => {
                let now = Instant::now();
                while let Some((at, event)) = events.pop_due(now) {
                    match event {
                        Event::Hear(bytes) => {
                            for tx in device.receive(&bytes, at.into_std()) {
                                events.push(at + tx.delay, Event::Start(tx.bytes));
                            }
                        }
                        Event::Start(bytes) => match pace {
                            // The reply takes the line for its wire time, after any traffic on it.
                            Some(line) => {
                                let done = events.occupy(at, line.time_for(bytes.len()));
                                events.push(done, Event::Arrive(bytes));
                            }
                            None => writer.write_all(&bytes).await?,
                        },
                        Event::Arrive(bytes) => writer.write_all(&bytes).await?,
                    }
                }
            }
        }
    }
}

async fn sleep_until(at: Option<Instant>) {
    if let Some(at) = at {
        tokio::time::sleep_until(at).await;
    }
}

enum Event {
    /// Bytes of a request, fully arrived: hand them to the device.
    Hear(Vec<u8>),
    /// A reply may start now.
    Start(Vec<u8>),
    /// A reply's last character has gone out: deliver it.
    Arrive(Vec<u8>),
}

/// Pending events in time order, and the time the (half-duplex) line is busy until.
#[derive(Default)]
struct Schedule {
    queue: VecDeque<(Instant, Event)>,
    line_busy_until: Option<Instant>,
}

impl Schedule {
    fn push(&mut self, at: Instant, event: Event) {
        // Stable: events at the same time keep their order.
        let index = self.queue.partition_point(|(t, _)| *t <= at);
        self.queue.insert(index, (at, event));
    }

    fn next_at(&self) -> Option<Instant> {
        self.queue.front().map(|(at, _)| *at)
    }

    fn pop_due(&mut self, now: Instant) -> Option<(Instant, Event)> {
        if self.next_at()? <= now {
            self.queue.pop_front()
        } else {
            None
        }
    }

    /// Takes the line for `duration` from `from` or when it is next free; returns the end.
    fn occupy(&mut self, from: Instant, duration: std::time::Duration) -> Instant {
        let start = self.line_busy_until.map_or(from, |busy| busy.max(from));
        let end = start + duration;
        self.line_busy_until = Some(end);
        end
    }
}

/// Serves a device on every connection to `listener`; each connection is a line to the
/// device `make` returns for it (usually a new line to one shared model).
pub async fn serve_tcp<D, F>(
    listener: TcpListener,
    make: F,
    pace: Option<SerialSettings>,
) -> io::Result<()>
where
    D: Device,
    F: Fn() -> D,
{
    loop {
        let (stream, peer) = listener.accept().await?;
        stream.set_nodelay(true).ok();
        tracing::info!(%peer, "line connected");
        let device = make();
        tokio::spawn(async move {
            match serve_stream(stream, device, pace).await {
                Ok(()) => tracing::info!(%peer, "line closed"),
                Err(e) => tracing::warn!(%peer, "line failed: {e}"),
            }
        });
    }
}

/// Why a PTY could not be set up.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PtyError {
    /// The pseudo-terminal pair could not be created.
    #[error("cannot create a pseudo-terminal: {0}")]
    Create(String),
    /// Something that is not a link stands where the link should go.
    #[error("{path} exists and is not a symbolic link; choose another path or remove it")]
    PathTaken {
        /// The path asked for.
        path: PathBuf,
    },
    /// The link could not be made.
    #[error("cannot link {path} to {target}: {source}")]
    Link {
        /// The path asked for.
        path: PathBuf,
        /// The PTY's device.
        target: String,
        /// What the OS said.
        source: io::Error,
    },
}

/// A pseudo-terminal whose device end is linked at a path of the user's choice, so any
/// serial program can open it as if it were a port. The link is removed on drop.
#[derive(Debug)]
pub struct Pty {
    master: SerialStream,
    /// Kept open so the line stays up while programs open and close the link.
    _slave: SerialStream,
    link: PathBuf,
}

impl Pty {
    /// Creates a PTY pair and links its device end at `link` (replacing an old link).
    /// Call it inside a tokio runtime.
    pub fn create(link: &Path) -> Result<Self, PtyError> {
        let (master, slave) = SerialStream::pair().map_err(|e| PtyError::Create(e.to_string()))?;
        let target = slave
            .name()
            .ok_or_else(|| PtyError::Create("the PTY has no device name".into()))?;
        match std::fs::symlink_metadata(link) {
            Ok(meta) if meta.file_type().is_symlink() => {
                std::fs::remove_file(link).map_err(|source| PtyError::Link {
                    path: link.to_owned(),
                    target: target.clone(),
                    source,
                })?;
            }
            Ok(_) => {
                return Err(PtyError::PathTaken {
                    path: link.to_owned(),
                });
            }
            Err(_) => {}
        }
        std::os::unix::fs::symlink(&target, link).map_err(|source| PtyError::Link {
            path: link.to_owned(),
            target,
            source,
        })?;
        Ok(Self {
            master,
            _slave: slave,
            link: link.to_owned(),
        })
    }

    /// Where programs open the line.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// Serves `device` on the PTY until the process ends or an I/O error occurs.
    pub async fn serve<D: Device>(
        mut self,
        device: D,
        pace: Option<SerialSettings>,
    ) -> io::Result<()> {
        let master = &mut self.master;
        serve_stream(master, device, pace).await
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.link);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;
    use wire::Transmit;

    /// Answers each chunk with `ok:` + the chunk, 10 ms later.
    struct Answer;

    impl Device for Answer {
        fn receive(&mut self, bytes: &[u8], _now: std::time::Instant) -> Vec<Transmit> {
            let mut reply = b"ok:".to_vec();
            reply.extend_from_slice(bytes);
            vec![Transmit::after(Duration::from_millis(10), reply)]
        }
    }

    #[tokio::test(start_paused = true)]
    async fn replies_leave_after_the_device_delay() {
        let (a, mut b) = tokio::io::duplex(256);
        tokio::spawn(serve_stream(a, Answer, None));
        let started = Instant::now();
        b.write_all(b"hi").await.unwrap();
        let mut buf = [0u8; 5];
        b.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"ok:hi");
        assert_eq!(started.elapsed(), Duration::from_millis(10));
    }

    #[tokio::test(start_paused = true)]
    async fn paced_lines_take_the_wire_time_of_request_and_reply() {
        let (a, mut b) = tokio::io::duplex(256);
        // 10 bits per character at 10 000 bit/s: 1 ms per character.
        tokio::spawn(serve_stream(
            a,
            Answer,
            Some(SerialSettings::new_8n1(10_000)),
        ));
        let started = Instant::now();
        b.write_all(b"0123456789").await.unwrap();
        let mut buf = [0u8; 13];
        b.read_exact(&mut buf).await.unwrap();
        // 10 ms to hear the request, 10 ms device delay, 13 ms to send the reply.
        assert_eq!(started.elapsed(), Duration::from_millis(33));
    }

    #[tokio::test]
    async fn each_tcp_connection_is_its_own_line() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        tokio::spawn(serve_tcp(listener, || Answer, None));
        let mut one = tokio::net::TcpStream::connect(addr).await.unwrap();
        let mut two = tokio::net::TcpStream::connect(addr).await.unwrap();
        one.write_all(b"1").await.unwrap();
        two.write_all(b"2").await.unwrap();
        let mut buf = [0u8; 4];
        two.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"ok:2");
        one.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"ok:1");
    }

    #[tokio::test]
    async fn a_pty_serves_the_device_at_the_linked_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyCELL");
        let pty = Pty::create(&path).unwrap();
        tokio::spawn(pty.serve(Answer, None));
        let endpoint =
            crate::Endpoint::parse(path.to_str().unwrap(), SerialSettings::new_8n1(9600)).unwrap();
        let mut line = crate::Line::open(&endpoint).await.unwrap();
        line.send(b"pty").await.unwrap();
        let mut got = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(5);
        while got.len() < 6 {
            let mut buf = [0u8; 16];
            let n = line.recv(&mut buf, deadline).await.unwrap();
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, b"ok:pty");
    }

    #[tokio::test]
    async fn a_pty_refuses_to_replace_a_regular_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("taken");
        std::fs::write(&path, b"keep me").unwrap();
        assert!(matches!(
            Pty::create(&path),
            Err(PtyError::PathTaken { .. })
        ));
        assert_eq!(std::fs::read(&path).unwrap(), b"keep me");
    }
}
