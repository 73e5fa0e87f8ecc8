//! Encode + decode of the largest read: 125 registers (a 255-byte response) and the
//! 8-byte request that asks for them. Throughput is reported in frames per second.

use std::hint::black_box;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, Throughput, criterion_group, criterion_main};
use jbus::rtu::{
    Addressed, RegisterValues, Request, RequestAdu, RequestCodec, Response, ResponseAdu,
    ResponseCodec, UnitId,
};
use wire::Codec;

fn request() -> RequestAdu {
    let unit = UnitId::new(2).expect("2 is a unit number");
    Addressed::new(
        unit,
        Request::read_holding_registers(0, 125).expect("125 registers from 0"),
    )
    .to_adu()
}

fn response() -> ResponseAdu {
    let values = (0..125u16).map(|i| i.wrapping_mul(0x9E37)).collect();
    ResponseAdu {
        unit: 2,
        response: Response::ReadHoldingRegisters(RegisterValues::new(values).expect("125 values")),
    }
}

fn codec(c: &mut Criterion) {
    let mut group = c.benchmark_group("rtu_125_registers");
    group.throughput(Throughput::Elements(1));

    let mut buf = Vec::with_capacity(260);
    encode_decode(
        &mut group,
        "response_encode_decode",
        ResponseCodec,
        response(),
        &mut buf,
    );
    encode_decode(
        &mut group,
        "request_encode_decode",
        RequestCodec,
        request(),
        &mut buf,
    );
    group.finish();
}

/// Benches encoding `frame` with `codec` into `buf` and decoding it back.
fn encode_decode<C: Codec<Error: std::fmt::Debug>>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    name: &str,
    codec: C,
    frame: C::Frame,
    buf: &mut Vec<u8>,
) {
    group.bench_function(name, |b| {
        b.iter(|| {
            buf.clear();
            codec.encode(black_box(&frame), buf);
            let decoded = codec
                .decode(black_box(buf.as_slice()))
                .expect("valid")
                .expect("whole");
            black_box(decoded)
        })
    });
}

criterion_group!(benches, codec);
criterion_main!(benches);
