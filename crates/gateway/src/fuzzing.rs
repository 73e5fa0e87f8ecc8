//! Fuzz bodies, shared by the fuzz targets in `fuzz/` and the unit tests that run them.
//!
//! Each body feeds outside text through the code a user's input really takes: the TOML
//! configuration through [`parse_config`](crate::plugins::parse_config) (what `cellbus config
//! check` and `serve --config` run, with the gateway crate's own kinds and interfaces),
//! query-parameter times and steps through the HTTP API's parsers, and whole query strings
//! through axum's `Query` extractor and the checks the handlers run. (The OPC UA relay's
//! bodies are `cellbus_opcua::fuzzing`'s.) None may panic; refusals must be errors, and
//! whatever is accepted must print.

use std::path::Path;

use axum::extract::Query;
use axum::http::Uri;

use crate::http::{self, AuditQuery, EventsQuery, HistoryQuery};
use crate::time::Timestamp;

/// A fixed "now" for the bodies (2026-11-03T08:00:00Z), so a run can be replayed.
const NOW: Timestamp = Timestamp(1_793_692_800_000);

/// Parses `data` (if it is UTF-8) as the cell's configuration; an accepted configuration
/// must describe itself without panicking.
pub fn config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match crate::plugins::parse_config(text, Path::new("fuzz.toml")) {
        Ok(cell) => {
            let _ = format!("{cell:?}");
        }
        Err(error) => {
            let _ = error.to_string();
            let _ = error.position();
        }
    }
}

/// Parses `data` (lossily as UTF-8) as a query-parameter time at a fixed now and at a now
/// taken from the input, and as a history step; every time accepted must be within the
/// years 1970 to 9999 and print as RFC 3339 that reads back as the same time.
pub fn time(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let now_from_input = data
        .get(..8)
        .and_then(|b| <[u8; 8]>::try_from(b).ok())
        .map(|b| Timestamp(i64::from_le_bytes(b)));
    for now in [
        Some(NOW),
        Some(Timestamp::MIN),
        Some(Timestamp::MAX),
        now_from_input,
    ]
    .into_iter()
    .flatten()
    {
        match Timestamp::parse_relative(&text, now) {
            Ok(time) => {
                assert!(time.is_printable(), "{text:?} gave {time:?}");
                let printed = time.to_string();
                assert_eq!(
                    Timestamp::parse_relative(&printed, now),
                    Ok(time),
                    "{text:?} printed as {printed:?}"
                );
            }
            Err(error) => {
                let _ = error.to_string();
            }
        }
        // Times outside the range still print (as milliseconds), never panic.
        let _ = now.to_string();
    }
    if let Err(error) = http::parse_step(&text) {
        let _ = error.message;
    }
}

/// Parses `data` as the query string of `/api/history`, `/api/events` and `/api/audit`
/// the way axum's `Query` extractor does, then runs the checks those handlers run.
pub fn query(data: &[u8]) {
    let Some(uri) = query_uri(data) else {
        return;
    };
    if let Ok(Query(q)) = Query::<HistoryQuery>::try_from_uri(&uri) {
        if let Ok(point) = http::history_point(&q) {
            let _ = point.to_string();
        }
        for now in [NOW, Timestamp::MIN, Timestamp::MAX] {
            if let Ok(range) = http::history_range(&q, now) {
                assert!(range.from < range.to, "{range:?}");
                let _ = format!("{} {}", range.from, range.to);
            }
        }
    }
    if let Ok(Query(q)) = Query::<EventsQuery>::try_from_uri(&uri)
        && let Ok(filter) = http::events_filter(q, NOW)
    {
        assert!((1..=http::MAX_LIMIT).contains(&filter.limit));
        for time in filter.from.into_iter().chain(filter.to) {
            assert!(time.is_printable(), "{time:?}");
        }
    }
    if let Ok(Query(q)) = Query::<AuditQuery>::try_from_uri(&uri) {
        let _ = http::check_limit(q.limit);
    }
}

/// `/api/history?<data>` as a URI: bytes a URI cannot hold are percent-encoded (a client
/// would have to send them so), the rest pass as they are, so `&`, `=`, `+` and `%` keep
/// their meaning in the query string.
fn query_uri(data: &[u8]) -> Option<Uri> {
    let mut text = String::from("/api/history?");
    for &byte in data {
        if byte.is_ascii_alphanumeric() || b"&=+%-._~:/?!$'()*,;@".contains(&byte) {
            text.push(char::from(byte));
        } else {
            text.push_str(&format!("%{byte:02X}"));
        }
    }
    text.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_config_body_survives_sample_inputs() {
        let samples: [&[u8]; 7] = [
            b"",
            crate::EXAMPLE_CONFIG.as_bytes(),
            b"[[line]]\nname = \"a\"\nendpoint = \"tcp://127.0.0.1:1\"\n[[line.device]]\nid = \"j\"\nprotocol = \"jbc\"\n",
            b"[[line]]\nname = \"\xc3\xa9\"\n",
            b"token = \"\"\n",
            b"[[line]\n",
            &[0xFF, 0xFE, 0x00],
        ];
        for sample in samples {
            config(sample);
        }
    }

    #[test]
    fn the_time_body_survives_sample_inputs() {
        let samples: [&[u8]; 12] = [
            b"",
            b"now",
            b"-1h",
            b"-100000d",
            b"-999999999999999999999s",
            b"2026-11-03T08:00:00Z",
            b"2026-11-03T08:00:00+01:00",
            b"1970-01-01T00:00:00+01:00",
            b"9999-12-31T23:59:59-01:00",
            b"0000-01-01T00:00:00Z",
            b"10s",
            &[0xFF; 9],
        ];
        for sample in samples {
            time(sample);
        }
    }

    #[test]
    fn the_query_body_survives_sample_inputs() {
        let samples: [&[u8]; 9] = [
            b"",
            b"point=jbc1.air_temperature&from=-1h",
            b"point=jbc1.air_temperature&from=-100000d",
            b"point=a.b&from=now&to=-1h&step=0s",
            b"point=a.b&to=1970-01-01T00:00:00Z",
            b"from=-1h&to=now&device=jbc1&kind=alarm&limit=0",
            b"limit=99999999999999999999999",
            b"device=%FF%00&limit=5&extra=1",
            b"point=%E9&from=%",
        ];
        for sample in samples {
            query(sample);
        }
    }

    #[test]
    fn the_bodies_survive_seeded_random_inputs() {
        let mut rng = fastrand::Rng::with_seed(7);
        let alphabet = b"-0123456789:TZ+.dhmsnow&=%pointfrmstepkindlimt ";
        for _ in 0..2000 {
            let len = rng.usize(0..40);
            let data: Vec<u8> = (0..len)
                .map(|_| alphabet[rng.usize(..alphabet.len())])
                .collect();
            config(&data);
            time(&data);
            query(&data);
        }
    }
}
