//! Frames per second through the codec (encode + decode), the deframer, and the twin.
//! Run briefly on shared machines: `cargo bench -p thermosald -- --warm-up-time 1 --measurement-time 2`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use thermosald::device::RegulatorBus;
use thermosald::frame::{Count, Direction, Frame, FrameCodec, MessageNumber, RawValue, Target};
use thermosald::{Address, Table};
use wire::device::Model;
use wire::{Codec, Deframer};

fn reply(message: u8, count: Count, items: usize) -> Frame {
    let data = (0..items)
        .map(|i| RawValue::new((i * 37 % 1000) as u16).expect("below 1000"))
        .collect();
    Frame::new(
        Target::Address(Address::new(3).expect("valid")),
        MessageNumber::new(message).expect("valid"),
        Direction::Reply,
        count,
        data,
    )
    .expect("at most 25 items")
}

fn codec(c: &mut Criterion) {
    let mut group = c.benchmark_group("encode+decode");
    group.throughput(Throughput::Elements(1));
    let frames = [
        (
            "single item (12 B)",
            reply(52, Count::item(15).expect("index"), 1),
        ),
        (
            "run-time table (30 B)",
            reply(53, Count::All, Table::Runtime.len()),
        ),
        (
            "machine table (84 B)",
            reply(51, Count::All, Table::Machine.len()),
        ),
    ];
    for (name, frame) in frames {
        let mut buf = Vec::with_capacity(96);
        group.bench_function(name, |b| {
            b.iter(|| {
                buf.clear();
                FrameCodec.encode(black_box(&frame), &mut buf);
                let decoded = FrameCodec.decode(black_box(&buf));
                black_box(decoded).ok().flatten().map(|(f, _)| f)
            })
        });
    }
    group.finish();

    let mut stream = Vec::new();
    for i in 0..100usize {
        stream.extend_from_slice(b"\x00noise");
        stream.extend(reply(53, Count::All, 7 + i % 2 * 18).to_bytes());
    }
    let mut group = c.benchmark_group("deframer");
    group.throughput(Throughput::Elements(100));
    group.bench_function("100 frames with noise, 64-byte chunks", |b| {
        b.iter(|| {
            let mut deframer = Deframer::new(FrameCodec);
            let mut frames = 0;
            for chunk in stream.chunks(64) {
                deframer.push(chunk);
                while let Some(input) = deframer.next_frame() {
                    frames += usize::from(input.is_ok());
                }
            }
            black_box(frames)
        })
    });
    group.finish();

    let mut group = c.benchmark_group("twin");
    group.throughput(Throughput::Elements(1));
    let t0 = Instant::now();
    let mut line =
        RegulatorBus::new(&[Address::new(0).expect("valid")], t0).expect("one regulator");
    let query = FrameCodec
        .decode(b"%053Q990\n")
        .expect("valid")
        .expect("whole")
        .0;
    let mut now = t0;
    group.bench_function("run-time read answered (model time +250 ms each)", |b| {
        b.iter(|| {
            now += Duration::from_millis(250);
            black_box(line.handle(Ok(query.clone()), now))
        })
    });
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
