//! Encode + decode of the largest read: 125 registers (a 255-byte response) and the
//! 8-byte request that asks for them. Throughput is reported in frames per second.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
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

    let frame = response();
    let mut buf = Vec::with_capacity(260);
    group.bench_function("response_encode_decode", |b| {
        b.iter(|| {
            buf.clear();
            ResponseCodec.encode(black_box(&frame), &mut buf);
            let decoded = ResponseCodec
                .decode(black_box(&buf))
                .expect("valid")
                .expect("whole");
            black_box(decoded)
        })
    });

    let frame = request();
    group.bench_function("request_encode_decode", |b| {
        b.iter(|| {
            buf.clear();
            RequestCodec.encode(black_box(&frame), &mut buf);
            let decoded = RequestCodec
                .decode(black_box(&buf))
                .expect("valid")
                .expect("whole");
            black_box(decoded)
        })
    });
    group.finish();
}

criterion_group!(benches, codec);
criterion_main!(benches);
