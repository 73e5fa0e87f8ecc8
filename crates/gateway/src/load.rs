//! How much of each serial line's time the configured polls need, estimated before
//! anything runs: `cellbus config check` shows it and warns (as `serve` does at start) of
//! a line asked for more polls than it can carry. Each driver tells the least time a poll
//! of a group holds its line ([`Driver::poll_time`]: requests and answers on the wire, the
//! waits the protocol requires); a line's load is the sum over its devices' groups of that
//! time over the group's period. An overloaded line still works: the scheduler slows every
//! group by the same factor (see `scheduler`), which is rarely what was meant.

use std::time::Duration;

use link::{Endpoint, SerialSettings};

use crate::config::{CellConfig, LineConfig};
use crate::driver::Driver;

/// One line's estimated load.
#[derive(Debug, Clone, PartialEq)]
pub struct LineLoad {
    /// The line.
    pub line: String,
    /// The share of the line's time the polls need (1.0: all of it), a lower bound.
    pub share: f64,
    /// The group that costs the most: device, group, its period and one poll's time.
    pub heaviest: Option<(String, String, Duration, Duration)>,
}

impl LineLoad {
    /// The warning for a line asked for more than it can carry, if it is.
    pub fn warning(&self) -> Option<String> {
        if self.share <= 1.0 {
            return None;
        }
        let heaviest = self
            .heaviest
            .as_ref()
            .map(|(device, group, period, time)| {
                format!(
                    " (the most: {device}'s {group} every {} takes {} a poll)",
                    humantime::format_duration(*period),
                    humantime::format_duration(round_ms(*time))
                )
            })
            .unwrap_or_default();
        Some(format!(
            "line {}: its polls need about {:.0} % of the line's time{heaviest}, so every poll group will be read about {:.1} times less often than asked; lengthen `poll` or `period`, or split the devices over more lines",
            self.line,
            self.share * 100.0,
            self.share
        ))
    }
}

fn round_ms(d: Duration) -> Duration {
    Duration::from_millis(u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

/// The serial line behind an endpoint, when it has one the timing can be read from.
fn serial_of(endpoint: &Endpoint) -> Option<SerialSettings> {
    match endpoint {
        Endpoint::Serial { settings, .. } => Some(*settings),
        Endpoint::Tcp { line, .. } => *line,
    }
}

/// The estimated load of each line with a serial line behind it (lines over plain TCP
/// are left out: no baud rate to reckon with). Builds each device's driver, as `serve`
/// will, without opening anything: for `cellbus config check`, which has no cell.
pub fn line_loads(config: &CellConfig) -> Vec<LineLoad> {
    config
        .lines
        .iter()
        .filter_map(|line| {
            let serial = serial_of(&line.endpoint)?;
            let drivers: Vec<_> = line
                .devices
                .iter()
                .filter_map(|d| Some((d, d.driver.build().ok()?)))
                .collect();
            let polls = drivers.iter().flat_map(|(device, driver)| {
                driver.groups().into_iter().map(move |group| {
                    let period = device.period_of(&group);
                    (
                        device.driver.id.as_str(),
                        driver.as_ref(),
                        group.name,
                        period,
                    )
                })
            });
            Some(line_load(&line.name, serial, polls))
        })
        .collect()
}

/// The serial line behind `line`, if the load of its polls can be estimated.
pub fn serial_line(line: &LineConfig) -> Option<SerialSettings> {
    serial_of(&line.endpoint)
}

/// The load of the line `name` at `serial` from its polls: each device's id, its driver,
/// one of its groups and the period in force. `serve` gives the drivers its line tasks
/// already hold.
pub fn line_load<'a>(
    name: &str,
    serial: SerialSettings,
    polls: impl IntoIterator<Item = (&'a str, &'a dyn Driver, String, Duration)>,
) -> LineLoad {
    let mut share = 0.0;
    let mut heaviest: Option<(String, String, Duration, Duration)> = None;
    let mut worst = 0.0;
    for (device, driver, group, period) in polls {
        let Some(time) = driver.poll_time(&group, serial) else {
            continue;
        };
        let part = time.as_secs_f64() / period.as_secs_f64().max(1e-3);
        share += part;
        if part > worst {
            worst = part;
            heaviest = Some((device.to_owned(), group, period, time));
        }
    }
    LineLoad {
        line: name.to_owned(),
        share,
        heaviest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plugins::parse_config;

    fn loads(text: &str) -> Vec<LineLoad> {
        line_loads(&parse_config(text, std::path::Path::new("cell.toml")).unwrap())
    }

    #[test]
    fn three_sealers_read_every_100_ms_need_more_than_their_line_and_are_warned_of() {
        let mut text =
            "[[line]]\nname = \"sealers\"\nendpoint = \"serial:///dev/ttyUSB0\"\n".to_owned();
        for n in 0..3 {
            text += &format!(
                "[[line.device]]\nid = \"sealer{n}\"\nprotocol = \"thermosald\"\naddress = {n}\npoll = {{ live = \"100ms\" }}\n"
            );
        }
        let load = &loads(&text)[0];
        // Each poll holds the line at least 240 ms (the regulator's 200 ms and the 40 ms
        // release) plus the wire: three of them ten times a second.
        assert!(load.share > 7.0, "{load:?}");
        let warning = load.warning().unwrap();
        assert!(
            warning.starts_with("line sealers: its polls need about ")
                && warning.contains("sealer")
                && warning.contains("lengthen `poll` or `period`"),
            "{warning}"
        );
    }

    #[test]
    fn the_line_tasks_serve_runs_estimate_what_config_check_does() {
        let mut text =
            "[[line]]\nname = \"sealers\"\nendpoint = \"serial:///dev/ttyUSB0\"\n".to_owned();
        for n in 0..3 {
            text += &format!(
                "[[line.device]]\nid = \"sealer{n}\"\nprotocol = \"thermosald\"\naddress = {n}\npoll = {{ live = \"100ms\" }}\n"
            );
        }
        let config = parse_config(&text, std::path::Path::new("cell.toml")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let store =
            crate::store::Store::open(dir.path(), crate::store::StoreOptions::default()).unwrap();
        let metrics = std::sync::Arc::new(crate::metrics::Metrics::new());
        let (_cell, tasks) = crate::scheduler::build(&config, store.handle(), metrics).unwrap();
        let serial = serial_line(&config.lines[0]).unwrap();
        assert_eq!(tasks[0].load(serial), line_loads(&config)[0]);
    }

    #[test]
    fn the_example_cells_lines_keep_their_periods() {
        for load in loads(crate::EXAMPLE_CONFIG) {
            assert!(load.warning().is_none(), "{load:?}");
            assert!(load.share > 0.0, "{load:?}");
        }
    }

    #[test]
    fn a_jbc_station_at_19200_baud_polled_every_second_uses_a_small_share_of_its_line() {
        let load = &loads(
            "[[line]]\nname = \"rework\"\nendpoint = \"serial:///dev/ttyUSB0\"\n\
             [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n",
        )[0];
        assert!(load.share > 0.0 && load.share < 0.5, "{load:?}");
    }

    #[test]
    fn a_line_over_plain_tcp_has_no_estimate() {
        assert!(
            loads(
                "[[line]]\nname = \"lan\"\nendpoint = \"tcp://127.0.0.1:4001\"\n\
             [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n",
            )
            .is_empty()
        );
    }
}
