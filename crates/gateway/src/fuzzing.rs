//! Fuzz bodies, shared by the fuzz targets in `fuzz/` and the unit tests that run them.
//!
//! Each body feeds outside text through the code a user's input really takes: the TOML
//! configuration through [`parse_config`](crate::plugins::parse_config) (what `cellbus config
//! check` and `serve --config` run), query-parameter times and steps through the HTTP
//! API's parsers, and whole query strings through axum's `Query` extractor and the checks
//! the handlers run; and the bytes an OPC UA connection carries through the relay's
//! secure channel sniffer ([`opcua_sniffer`]) and its chunk reader ([`opcua_chunks`]).
//! None may panic; refusals must be errors, and whatever is accepted must print.

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

/// Feeds `data` to the OPC UA relay's secure channel sniffer, split where its first byte
/// says: the same bytes in one piece and in two must give the same answer.
pub fn opcua_sniffer(data: &[u8]) {
    use crate::northbound::opcua::peers::{ChannelSniffer, Sniffed};
    let split = data.first().map_or(0, |b| usize::from(*b)).min(data.len());
    let mut whole = ChannelSniffer::new();
    let once = whole.feed(data);
    let mut parts = ChannelSniffer::new();
    parts.feed(&data[..split]);
    let twice = if parts.state() == Sniffed::Waiting {
        parts.feed(&data[split..])
    } else {
        parts.state()
    };
    assert_eq!(
        once, twice,
        "the sniffer's answer depends on how the bytes were split"
    );
}

/// Feeds `data` to the OPC UA relay's chunk reader, split where its first byte says, as
/// both a client's and a server's bytes: the same bytes in one piece and in two must give
/// the same chunks, and reading them (sessions created, the next message) must not panic.
pub fn opcua_chunks(data: &[u8]) {
    use crate::northbound::opcua::chunks::{self, ClientSide, Framer, ServerSide};
    let split = data.first().map_or(0, |b| usize::from(*b)).min(data.len());
    let cut = |pieces: &[&[u8]]| {
        let mut framer = Framer::default();
        let mut got = Vec::new();
        for piece in pieces {
            framer.push(piece);
            loop {
                match framer.next_chunk() {
                    Ok(Some(chunk)) => got.push(Ok(chunk)),
                    Ok(None) => break,
                    Err(e) => {
                        got.push(Err(e));
                        return got;
                    }
                }
            }
        }
        got
    };
    let whole = cut(&[data]);
    assert_eq!(
        whole,
        cut(&[&data[..split], &data[split..]]),
        "the chunks depend on how the bytes were split"
    );
    let mut client = ClientSide::default();
    let mut server = ServerSide::default();
    for chunk in whole.iter().flatten() {
        client.see(chunk);
        if let Some(token) = server.see(chunk)
            && let Some(next) = client.next()
        {
            let _ = chunks::close_session(7, next, &token);
        }
    }
    let _ = chunks::created_session(data);
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

    #[test]
    fn the_opcua_chunks_body_survives_sample_and_random_inputs() {
        let samples: [&[u8]; 5] = [
            b"",
            b"\x05HELF\x0c\0\0\0\0\0\0\0MSGF\x18\0\0\0\x07\0\0\0\x01\0\0\0\x02\0\0\0\x02\0\0\0",
            b"OPNF\xff\xff\xff\xff\x01\x02\x03\x04",
            b"MSGF\x07\0\0\0",
            b"\x01\x00\xd0\x01\0\0",
        ];
        for sample in samples {
            opcua_chunks(sample);
        }
        let mut rng = fastrand::Rng::with_seed(43);
        let alphabet = b"OPNMSGCLOFCA\0\x01\x08\x0c\x18\x20\xd0\xff";
        for _ in 0..5000 {
            let len = rng.usize(0..64);
            let data: Vec<u8> = (0..len)
                .map(|_| alphabet[rng.usize(..alphabet.len())])
                .collect();
            opcua_chunks(&data);
        }
    }

    #[test]
    fn the_opcua_sniffer_body_survives_sample_and_random_inputs() {
        let samples: [&[u8]; 5] = [
            b"",
            b"\x05ACKF\x0c\0\0\0\0\0\0\0OPNF\x10\0\0\0\x07\0\0\0",
            b"OPNF\xff\xff\xff\xff\x01\x02\x03\x04",
            b"ACKF\0\0\0\0",
            b"ERRF\x10\0\0\0",
        ];
        for sample in samples {
            opcua_sniffer(sample);
        }
        let mut rng = fastrand::Rng::with_seed(14);
        let alphabet = b"ACKOPNFERRMSG\0\x01\x08\x0c\x10\xff";
        for _ in 0..5000 {
            let len = rng.usize(0..48);
            let data: Vec<u8> = (0..len)
                .map(|_| alphabet[rng.usize(..alphabet.len())])
                .collect();
            opcua_sniffer(&data);
        }
    }
}
