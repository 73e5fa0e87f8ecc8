//! Encode + decode of a 125-register read, against rmodbus and tokio-modbus.
//!
//! - `codec/*`: the client's codec work for one read of 125 holding registers: encode the
//!   8-byte request, decode the 255-byte response into 125 values. jbus (`to_adu`,
//!   `decode_response`, `check_response`) against rmodbus (`generate_get_holdings`,
//!   `parse_u16`).
//! - `client/*`: tokio-modbus keeps its codec private, so it is measured through its
//!   client over an in-memory transport that answers every request at once, and jbus's
//!   client over the same transport: request out, answer in, checked, values returned.
//!
//! The work is the same on each side (request built and encoded; answer CRC-checked, its
//! unit, function and count checked, 125 values decoded). Differences that remain: rmodbus
//! writes into buffers the bench reuses where jbus allocates its frame and values, and the
//! jbus client also drops stale input (a yield to the runtime, one read) and keeps a
//! deadline (a timer armed only when the answer is not there yet), which tokio-modbus (no
//! timeout of its own) does not. On this machine (2026-11) the jbus client took 0.93 µs per
//! request and tokio-modbus 1.06 µs; before CRC-16 used the 16-byte-step tables and the
//! line stopped arming timers for bytes already there, jbus took 1.58 µs.
//!
//! Run with `cargo bench -p jbus --bench versus -- --warm-up-time 1 --measurement-time 2`;
//! the ratio is the tokio-modbus or rmodbus time over the jbus time.

use std::hint::black_box;
use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use jbus::client::{Client, ClientConfig};
use jbus::rtu::{
    Addressed, RegisterValues, Request, Response, ResponseAdu, UnitId, check_response,
    codec::decode_response,
};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

const UNIT: u8 = 2;
const COUNT: u16 = 125;

/// The device's answer: 125 registers, 255 bytes.
fn response_bytes() -> Vec<u8> {
    let values = (0..COUNT).map(|i| i.wrapping_mul(0x9E37)).collect();
    ResponseAdu {
        unit: UNIT,
        response: Response::ReadHoldingRegisters(RegisterValues::new(values).expect("125 values")),
    }
    .to_bytes()
}

fn codec(c: &mut Criterion) {
    let answer = response_bytes();
    let mut group = c.benchmark_group("codec_125_registers");
    group.throughput(Throughput::Elements(1));

    let unit = UnitId::new(UNIT).expect("a unit number");
    group.bench_function("jbus", |b| {
        b.iter(|| {
            let request = Addressed::new(
                unit,
                Request::read_holding_registers(black_box(0), black_box(COUNT)).expect("valid"),
            );
            let bytes = request.to_adu().to_bytes();
            black_box(&bytes);
            let (adu, _) = decode_response(black_box(&answer))
                .expect("valid")
                .expect("whole");
            black_box(check_response(&request, &adu).expect("the answer"))
        })
    });

    group.bench_function("rmodbus", |b| {
        let mut request = Vec::with_capacity(8);
        let mut values = Vec::with_capacity(usize::from(COUNT));
        b.iter(|| {
            let mut mreq = rmodbus::client::ModbusRequest::new(UNIT, rmodbus::ModbusProto::Rtu);
            request.clear();
            mreq.generate_get_holdings(black_box(0), black_box(COUNT), &mut request)
                .expect("valid");
            black_box(&request);
            values.clear();
            mreq.parse_u16(black_box(&answer), &mut values)
                .expect("the answer");
            black_box(values.len())
        })
    });
    group.finish();
}

/// A transport whose device answers every request at once with the same bytes.
struct Loopback {
    answer: Vec<u8>,
    pending: usize,
}

impl AsyncRead for Loopback {
    fn poll_read(
        mut self: Pin<&mut Self>,
        _cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if self.pending == 0 {
            // Nothing to read until the next request; the clients never wait here long
            // (jbus drops stale input with an immediate deadline).
            return Poll::Pending;
        }
        let start = self.answer.len() - self.pending;
        let n = self.pending.min(buf.remaining());
        buf.put_slice(&self.answer[start..start + n]);
        self.pending -= n;
        Poll::Ready(Ok(()))
    }
}

impl AsyncWrite for Loopback {
    fn poll_write(
        mut self: Pin<&mut Self>,
        _cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.pending = self.answer.len();
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

fn clients(c: &mut Criterion) {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .expect("a runtime");
    let mut group = c.benchmark_group("client_125_registers");
    group.throughput(Throughput::Elements(1));

    let line = runtime.block_on(async {
        let transport = Loopback {
            answer: response_bytes(),
            pending: 0,
        };
        link::SharedLine::new(link::Line::from_stream(transport, "loopback", None))
    });
    let mut client = Client::new(line, ClientConfig::default());
    let unit = UnitId::new(UNIT).expect("a unit number");
    group.bench_function("jbus", |b| {
        b.iter(|| {
            runtime
                .block_on(client.read_holding_registers(unit, black_box(0), COUNT))
                .expect("the answer")
        })
    });

    let mut context = tokio_modbus::client::rtu::attach_slave(
        Loopback {
            answer: response_bytes(),
            pending: 0,
        },
        tokio_modbus::Slave(UNIT),
    );
    group.bench_function("tokio-modbus", |b| {
        use tokio_modbus::client::Reader as _;
        b.iter(|| {
            runtime
                .block_on(context.read_holding_registers(black_box(0), COUNT))
                .expect("no I/O error")
                .expect("no exception")
        })
    });
    group.finish();
}

criterion_group!(benches, codec, clients);
criterion_main!(benches);
