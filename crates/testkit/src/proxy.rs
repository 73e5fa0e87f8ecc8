//! A noisy line between two byte streams, in memory or as a TCP proxy.
//!
//! Each direction has its own [`Noise`], seeded from the line's seed; what is read from one
//! end is mangled and written to the other as it comes, so the timing of the traffic is
//! kept. A [`LineControl`] turns the noise off and on and pulls the cable (an outage:
//! everything is lost both ways) for every line that shares it, and adds up their counts.

use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinSet;

use crate::noise::{Noise, NoiseConfig, NoiseCounts};

/// Switches and counts shared by the lines of a test.
#[derive(Debug, Clone, Default)]
pub struct LineControl {
    shared: Arc<Shared>,
}

#[derive(Debug, Default)]
struct Shared {
    quiet: AtomicBool,
    outage: AtomicBool,
    /// Client to device, device to client.
    counts: [Mutex<NoiseCounts>; 2],
}

/// Which way bytes cross a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    ToDevice = 0,
    ToClient = 1,
}

impl LineControl {
    /// Noise on (the default) or off; an outage is separate.
    pub fn set_noisy(&self, noisy: bool) {
        self.shared.quiet.store(!noisy, Ordering::SeqCst);
    }

    /// Pulls the cable (`true`: every byte is lost both ways) or plugs it back.
    pub fn set_outage(&self, out: bool) {
        self.shared.outage.store(out, Ordering::SeqCst);
    }

    /// What the lines did so far, both directions added up.
    pub fn counts(&self) -> NoiseCounts {
        self.to_device().plus(self.to_client())
    }

    /// What the lines did to what clients sent (requests).
    pub fn to_device(&self) -> NoiseCounts {
        self.count(Direction::ToDevice)
    }

    /// What the lines did to what devices sent (answers).
    pub fn to_client(&self) -> NoiseCounts {
        self.count(Direction::ToClient)
    }

    fn count(&self, direction: Direction) -> NoiseCounts {
        *self.shared.counts[direction as usize]
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// Carries one chunk through `noise`, as the switches say.
    fn carry(&self, direction: Direction, noise: &mut Noise, chunk: &[u8]) -> Vec<u8> {
        let before = noise.counts();
        let out = if self.shared.outage.load(Ordering::SeqCst) {
            noise.lose(chunk);
            Vec::new()
        } else if self.shared.quiet.load(Ordering::SeqCst) {
            noise.pass(chunk);
            chunk.to_vec()
        } else {
            noise.apply(chunk)
        };
        let delta = noise.counts().minus(before);
        let mut counts = self.shared.counts[direction as usize]
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        *counts = counts.plus(delta);
        out
    }
}

/// Carries bytes both ways between `client` and `device` through a noisy line until
/// either end closes or fails. Each direction's noise is seeded from `seed`.
pub async fn noisy_pipe<A, B>(
    client: A,
    device: B,
    config: NoiseConfig,
    seed: u64,
    control: LineControl,
) where
    A: AsyncRead + AsyncWrite + Send + 'static,
    B: AsyncRead + AsyncWrite + Send + 'static,
{
    let (a_read, a_write) = tokio::io::split(client);
    let (b_read, b_write) = tokio::io::split(device);
    let forward = carry(
        a_read,
        b_write,
        Direction::ToDevice,
        Noise::new(config, seed),
        control.clone(),
    );
    let backward = carry(
        b_read,
        a_write,
        Direction::ToClient,
        Noise::new(config, seed ^ 0x5eed),
        control,
    );
    // The line is over when either direction ends: a closed end closes both.
    tokio::select! {
        () = forward => {}
        () = backward => {}
    }
}

async fn carry<R, W>(
    mut from: R,
    mut to: W,
    direction: Direction,
    mut noise: Noise,
    control: LineControl,
) where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let mut buf = vec![0u8; 4096];
    loop {
        let n = match from.read(&mut buf).await {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        let out = control.carry(direction, &mut noise, &buf[..n]);
        if !out.is_empty() && to.write_all(&out).await.is_err() {
            break;
        }
    }
    let _ = to.shutdown().await;
}

/// A noisy line as a TCP proxy on 127.0.0.1 (a port the OS chose) in front of a server:
/// each connection to it is carried to `upstream` through its own noisy line. Dropping it
/// stops it and cuts its connections.
#[derive(Debug)]
pub struct NoisyProxy {
    addr: SocketAddr,
    control: LineControl,
    tasks: JoinSet<()>,
}

impl NoisyProxy {
    /// Starts a proxy to `upstream` whose lines have `config`'s trouble; connection number
    /// `n` is seeded with `seed + n`.
    pub async fn start(upstream: SocketAddr, config: NoiseConfig, seed: u64) -> io::Result<Self> {
        Self::start_with(upstream, config, seed, LineControl::default()).await
    }

    /// Like [`start`](Self::start), sharing `control` (one switch for several proxies).
    pub async fn start_with(
        upstream: SocketAddr,
        config: NoiseConfig,
        seed: u64,
        control: LineControl,
    ) -> io::Result<Self> {
        let listener = TcpListener::bind(("127.0.0.1", 0)).await?;
        let addr = listener.local_addr()?;
        let mut tasks = JoinSet::new();
        let lines = control.clone();
        tasks.spawn(async move {
            let connections = AtomicU64::new(0);
            let mut open = JoinSet::new();
            loop {
                let Ok((client, _)) = listener.accept().await else {
                    continue;
                };
                let n = connections.fetch_add(1, Ordering::Relaxed);
                let control = lines.clone();
                open.spawn(async move {
                    match TcpStream::connect(upstream).await {
                        Ok(server) => {
                            let _ = client.set_nodelay(true);
                            let _ = server.set_nodelay(true);
                            noisy_pipe(client, server, config, seed.wrapping_add(n), control).await;
                        }
                        Err(e) => tracing::warn!("noisy proxy: cannot reach {upstream}: {e}"),
                    }
                });
                // Forget the lines that ended.
                while open.try_join_next().is_some() {}
            }
        });
        Ok(Self {
            addr,
            control,
            tasks,
        })
    }

    /// Where clients connect.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The switches and counts of its lines.
    pub fn control(&self) -> &LineControl {
        &self.control
    }

    /// Stops accepting and cuts every line.
    pub fn stop(&mut self) {
        self.tasks.abort_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_clean_proxy_carries_bytes_both_ways() {
        let server = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let upstream = server.local_addr().unwrap();
        tokio::spawn(async move {
            let (mut s, _) = server.accept().await.unwrap();
            let mut buf = [0u8; 5];
            s.read_exact(&mut buf).await.unwrap();
            s.write_all(b"world").await.unwrap();
        });
        let proxy = NoisyProxy::start(upstream, NoiseConfig::CLEAN, 1)
            .await
            .unwrap();
        let mut c = TcpStream::connect(proxy.addr()).await.unwrap();
        c.write_all(b"hello").await.unwrap();
        let mut buf = [0u8; 5];
        c.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"world");
        let counts = proxy.control().counts();
        assert_eq!((counts.bytes, counts.damaged_chunks), (10, 0));
    }

    #[tokio::test(start_paused = true)]
    async fn an_outage_loses_everything_until_the_cable_is_back() {
        let (client, mut near) = tokio::io::duplex(256);
        let (far, mut device) = tokio::io::duplex(256);
        let control = LineControl::default();
        tokio::spawn(noisy_pipe(
            client,
            far,
            NoiseConfig::CLEAN,
            1,
            control.clone(),
        ));
        control.set_outage(true);
        near.write_all(b"lost").await.unwrap();
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
        control.set_outage(false);
        near.write_all(b"kept").await.unwrap();
        let mut buf = [0u8; 4];
        device.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"kept");
        assert_eq!(control.counts().lost_in_outage, 1);
    }
}
