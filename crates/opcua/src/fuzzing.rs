//! Fuzz bodies, shared by the fuzz targets in `fuzz/` and the unit tests that run them:
//! the bytes an OPC UA connection carries through the relay's secure channel sniffer
//! ([`opcua_sniffer`]) and its chunk reader ([`opcua_chunks`]). None may panic, and
//! splitting the bytes anywhere must not change what they say.

/// Feeds `data` to the OPC UA relay's secure channel sniffer, split where its first byte
/// says: the same bytes in one piece and in two must give the same answer.
pub fn opcua_sniffer(data: &[u8]) {
    use crate::peers::{ChannelSniffer, Sniffed};
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
    use crate::chunks::{self, ClientSide, Framer, ServerSide};
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
