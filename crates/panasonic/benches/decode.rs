//! Messages per second through the Panasonic message codec: decode (and encode + decode) of
//! a typical polling conversation, decode of a program upload, and decode + typing of R
//! events. Throughput is reported in messages (elements) per second.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use panasonic::message::{Message, MessageCodec};
use panasonic::packet::Packet;
use wire::{Codec, Deframer};

fn message(command: &str, data: &[u8]) -> Message {
    Message::with_data(command, data.to_vec()).expect("valid message")
}

/// C2ST → D1 → A2, C3P → D1 → A2, C2HB → A2: what a host polls every few seconds.
fn poll_cycle() -> Vec<Message> {
    vec![
        message("C2ST", b""),
        message("D1", b"001"),
        message("A2", b""),
        message("C3P", b""),
        message("D1", b"PDEMO-BOARD      "),
        message("A2", b""),
        message("C2HB00000042", b""),
        message("A2", b""),
    ]
}

/// A 2000-step program in one D0 (about 60 kB).
fn upload() -> Message {
    let mut text = b"%HEADER\r\nNAME=BENCH\r\n%STEP\r\n".to_vec();
    for step in 1..=2000 {
        text.extend(format!("{step:04},X012.50,Y008.00,R090,Z{:03}\r\n", step % 40 + 1).bytes());
    }
    text.extend(b"*\r\n");
    message("D0", &text)
}

fn events() -> Vec<Message> {
    [
        "R1ST",
        "R0CT0022",
        "R1RC",
        "R3GDCT",
        "R2E03S012N003Z015M0T000000042",
        "R1HB00000042",
    ]
    .into_iter()
    .map(|text| message(text, b""))
    .collect()
}

fn stream(messages: &[Message]) -> Vec<u8> {
    let mut bytes = Vec::new();
    for m in messages {
        MessageCodec.encode(m, &mut bytes);
    }
    bytes
}

fn decode_all(bytes: &[u8]) -> usize {
    let mut deframer = Deframer::new(MessageCodec);
    deframer.push(bytes);
    let mut n = 0;
    while let Some(result) = deframer.next_frame() {
        black_box(result.expect("clean stream"));
        n += 1;
    }
    n
}

fn codec(c: &mut Criterion) {
    let mut group = c.benchmark_group("panasonic");

    let cycle = poll_cycle();
    let bytes = stream(&cycle);
    group.throughput(Throughput::Elements(cycle.len() as u64));
    group.bench_function("decode poll cycle", |b| {
        b.iter(|| assert_eq!(decode_all(black_box(&bytes)), cycle.len()))
    });
    group.bench_function("encode+decode poll cycle", |b| {
        let mut out = Vec::with_capacity(bytes.len());
        b.iter(|| {
            out.clear();
            for m in &cycle {
                MessageCodec.encode(black_box(m), &mut out);
            }
            assert_eq!(decode_all(&out), cycle.len());
        })
    });

    let big = stream(&[upload()]);
    group.throughput(Throughput::Elements(1));
    group.bench_function("decode 2000-step program upload", |b| {
        b.iter(|| assert_eq!(decode_all(black_box(&big)), 1))
    });

    let events = events();
    let bytes = stream(&events);
    group.throughput(Throughput::Elements(events.len() as u64));
    group.bench_function("decode+classify R events", |b| {
        b.iter(|| {
            let mut deframer = Deframer::new(MessageCodec);
            deframer.push(black_box(&bytes));
            while let Some(Ok(m)) = deframer.next_frame() {
                black_box(Packet::classify(&m));
            }
        })
    });
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
