//! Frames per second through the JBC codec: encode and decode of a typical poll cycle
//! (read requests and their answers, addressed form), and a station answering requests.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use jbc::code::Code;
use jbc::device::{Station, StationConfig};
use jbc::frame::{Address, Data, Frame, FrameCodec, Header, Route};
use jbc::message::Request;
use wire::device::Model;
use wire::{Codec, Deframer};

fn poll_cycle() -> Vec<Frame> {
    let to_station = Some(Route {
        source: Address::ROBOT,
        target: Address::STATION,
    });
    let to_robot = to_station.map(Route::reversed);
    Code::all()
        .into_iter()
        .filter(|c| c.readable())
        .flat_map(|code| {
            let request = Request::read(code).expect("readable").to_frame(to_station);
            let answer = Frame {
                route: to_robot,
                header: Header::Ack,
                code: code.raw(),
                data: Some(Data::number(350).expect("fits")),
            };
            [request, answer]
        })
        .collect()
}

fn codec(c: &mut Criterion) {
    let frames = poll_cycle();
    let mut group = c.benchmark_group("jbc");
    group.throughput(Throughput::Elements(frames.len() as u64));
    group.bench_function("encode+decode", |b| {
        let mut bytes = Vec::with_capacity(16 * frames.len());
        b.iter(|| {
            bytes.clear();
            for frame in &frames {
                FrameCodec.encode(black_box(frame), &mut bytes);
            }
            let mut deframer = Deframer::new(FrameCodec);
            deframer.push(&bytes);
            let mut n = 0;
            while let Some(Ok(frame)) = deframer.next_frame() {
                black_box(frame);
                n += 1;
            }
            assert_eq!(n, frames.len());
        })
    });
    let requests: Vec<Frame> = frames.iter().step_by(2).copied().collect();
    group.throughput(Throughput::Elements(requests.len() as u64));
    group.bench_function("station answers", |b| {
        let mut station = Station::new(StationConfig::default());
        let mut now = Instant::now();
        b.iter(|| {
            for frame in &requests {
                now += Duration::from_millis(10);
                black_box(station.handle(Ok(*frame), now));
            }
        })
    });
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
