//! Test and bench tools shared by the cellbus crates.
//!
//! - [`chatter`]: [`Chatter`], a line that never stops talking (its reads never wait),
//!   and [`ends_within`] (and [`ends_within_paused`]), which run a test's future on a
//!   thread of its own with a bound in real time, so a hang fails the test instead of
//!   holding it.
//! - `mosquitto` (feature `mqtt`): `Mosquitto`, a real MQTT broker on a free loopback
//!   port (and a TLS listener on a second one with `TlsFiles`), killed on drop.
//! - `sparkplug_sub` (feature `mqtt`): `Subscriber`, a Sparkplug B subscriber that decodes
//!   payloads with the `sparkplug` crate and survives broker restarts.
//! - `postgres` (feature `postgres`): `Postgres`, a real, throwaway PostgreSQL cluster on
//!   a free loopback port, with crash-restart, stop and start again; stopped on drop.
//! - `rabbitmq` (feature `rabbitmq`): `RabbitMq`, a real AMQP 1.0 broker (Debian's
//!   RabbitMQ with its AMQP 1.0 plugin) on free loopback ports, stopped and started again
//!   at will; stopped on drop.
//! - [`noise`]: [`Noise`], a seeded, sans-IO byte mangler with the trouble of a bad
//!   serial line (flipped bits, lost, inserted and duplicated bytes, whole chunks lost,
//!   bursts), and its counts.
//! - [`proxy`]: a noisy line between two byte streams ([`noisy_pipe`]) or between a TCP
//!   client and a server ([`NoisyProxy`]), in both directions, with an outage switch that
//!   loses everything (a pulled cable).
//! - [`tricks`]: [`Tricky`], any simulated device behind a line that plays scripted
//!   tricks on its next replies (drop, damage, delay, replace, bytes or an echo before),
//!   for client tests.
//! - [`free_port`]: a loopback port nothing listens on, for a server a test starts or
//!   for a connection that must be refused.
//! - [`bench_seconds`]: how long a bench binary runs, short under `cargo test`.
//! - [`process_cpu`]: the CPU time this process used, for benches that print it.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod chatter;
pub mod http;
#[cfg(feature = "mqtt")]
pub mod mosquitto;
pub mod noise;
#[cfg(feature = "postgres")]
pub mod postgres;
pub mod proxy;
#[cfg(feature = "rabbitmq")]
pub mod rabbitmq;
#[cfg(feature = "mqtt")]
pub mod sparkplug_sub;
pub mod tricks;

pub use chatter::{Chatter, ends_within, ends_within_paused};
pub use http::get_response;
#[cfg(feature = "mqtt")]
pub use mosquitto::{Mosquitto, TlsFiles, password_file};
pub use noise::{Noise, NoiseConfig, NoiseCounts};
#[cfg(feature = "postgres")]
pub use postgres::Postgres;
pub use proxy::{LineControl, NoisyProxy, noisy_pipe};
#[cfg(feature = "rabbitmq")]
pub use rabbitmq::RabbitMq;
#[cfg(feature = "mqtt")]
pub use sparkplug_sub::{SparkplugMessage, Subscriber, command_payload, rebirth_command};
pub use tricks::{At, Tap, Trick, Tricky};

/// How many seconds a bench binary that prints its figures runs: the environment
/// variable `var` if it holds a number, else `benching` under `cargo bench` and 1 (a smoke
/// run) under `cargo test`.
pub fn bench_seconds(var: &str, benching: u64) -> u64 {
    std::env::var(var)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(if std::env::args().any(|a| a == "--bench") {
            benching
        } else {
            1
        })
}

/// A free loopback port: nothing listened on it when it was picked.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind((std::net::Ipv4Addr::LOCALHOST, 0))
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

/// User + system CPU time of this process so far, from `/proc/self/stat`, in clock ticks
/// of 10 ms; zero where there is no `/proc`.
pub fn process_cpu() -> std::time::Duration {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return std::time::Duration::ZERO;
    };
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    // utime and stime are fields 14 and 15 of the whole line: 11 and 12 after the name.
    std::time::Duration::from_millis((ticks(11) + ticks(12)) * 10)
}
