//! Any RTU device model served over Modbus TCP, as a serial gateway serves the devices on
//! its line.
//!
//! [`MbapServer`] takes each Modbus TCP request off the connection, hands the device the
//! same request as an RTU frame, and sends back each RTU answer behind the request's MBAP
//! header (same transaction id, same unit id). The device stays the one model that also
//! serves RTU: its units, refusals, reply delay and silences are unchanged. A request
//! for a unit the device does not answer gets silence, as behind a gateway whose device
//! does not answer, or, [`MbapServer::answering_silence`], exception 11 after the
//! gateway's own wait, as a serial-to-Ethernet gateway (a Moxa MGate) answers for a unit
//! that is switched off. A broadcast (unit 0) write is applied and not answered.

use std::time::{Duration, Instant};

use wire::{Deframer, Device, LineTiming, Transmit};

use super::codec::RequestCodec;
use super::{Mbap, TransactionId};
use crate::rtu::codec::ResponseCodec as RtuResponseCodec;
use crate::rtu::{ExceptionCode, FunctionCode, RequestAdu, RequestPdu, Response, ResponseAdu};

/// An RTU device behind Modbus TCP framing (see the [module](self)).
#[derive(Debug)]
pub struct MbapServer<D> {
    inner: D,
    requests: Deframer<RequestCodec>,
    dropped: u64,
    /// When set, silence is answered with exception 11 after this long.
    target_timeout: Option<Duration>,
}

impl<D: Device> MbapServer<D> {
    /// Serves `inner`, an RTU device, over Modbus TCP.
    pub fn new(inner: D) -> Self {
        Self {
            inner,
            requests: Deframer::new(RequestCodec),
            dropped: 0,
            target_timeout: None,
        }
    }

    /// Answers a request the device is silent to (a unit it does not have) as a gateway
    /// does: exception 11, "gateway target failed to respond", `after` the request.
    pub fn answering_silence(mut self, after: Duration) -> Self {
        self.target_timeout = Some(after);
        self
    }

    /// How many runs of bytes were dropped because they made no Modbus TCP frame.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// The device's answers to one request, each behind the request's header.
    fn answer(&mut self, request: Mbap<RequestAdu>, now: Instant) -> Vec<Transmit> {
        let Mbap { transaction, adu } = request;
        if let RequestPdu::Other(other) = &adu.pdu {
            // RTU has no length field: a request of an unknown layout may not frame on
            // the device's side. Every device here refuses such a function with
            // exception 1, so answer that at once.
            if adu.is_broadcast() {
                return Vec::new();
            }
            let refusal = ResponseAdu {
                unit: adu.unit,
                response: Response::exception(
                    FunctionCode::of_exception(other.function()),
                    ExceptionCode::ILLEGAL_FUNCTION,
                ),
            };
            return vec![Transmit::now(
                Mbap {
                    transaction,
                    adu: refusal,
                }
                .to_bytes(),
            )];
        }
        let answers: Vec<Transmit> = self
            .inner
            .receive(&adu.to_bytes(), now)
            .into_iter()
            .flat_map(|reply| behind_header(transaction, reply))
            .collect();
        match self.target_timeout {
            Some(after) if answers.is_empty() && !adu.is_broadcast() => {
                let silent = ResponseAdu {
                    unit: adu.unit,
                    response: Response::exception(
                        FunctionCode::of_exception(adu.pdu.function_byte()),
                        ExceptionCode::GATEWAY_TARGET_FAILED,
                    ),
                };
                vec![Transmit::after(
                    after,
                    Mbap {
                        transaction,
                        adu: silent,
                    }
                    .to_bytes(),
                )]
            }
            _ => answers,
        }
    }
}

/// The RTU frames in `reply`, each behind the header of `transaction`; bytes that make no
/// frame (a damaged reply) are not sent.
fn behind_header(transaction: TransactionId, reply: Transmit) -> Vec<Transmit> {
    let mut frames = Deframer::new(RtuResponseCodec);
    frames.push(&reply.bytes);
    std::iter::from_fn(|| frames.next_frame())
        .filter_map(Result::ok)
        .map(|adu| Transmit::after(reply.delay, Mbap { transaction, adu }.to_bytes()))
        .collect()
}

impl<D: Device> Device for MbapServer<D> {
    fn set_timing(&mut self, timing: LineTiming) {
        self.inner.set_timing(timing);
    }

    fn receive(&mut self, bytes: &[u8], now: Instant) -> Vec<Transmit> {
        self.requests.push(bytes);
        let mut out = Vec::new();
        while let Some(input) = self.requests.next_frame() {
            match input {
                Ok(request) => out.extend(self.answer(request, now)),
                Err(error) => {
                    self.dropped += 1;
                    tracing::debug!(%error, "dropping bytes that make no Modbus TCP request");
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use wire::device::SharedModel;

    use super::*;
    use crate::rtu::{Addressed, Answer, Request, UnitId, check_response};
    use crate::slave::{DEFAULT_REPLY_DELAY, Slave};
    use crate::tcp::codec::decode_response;

    fn unit(n: u8) -> UnitId {
        UnitId::new(n).expect("test unit")
    }

    fn server() -> MbapServer<impl Device> {
        MbapServer::new(SharedModel::new(Slave::all_writable(unit(3))).line())
    }

    fn ask(
        server: &mut MbapServer<impl Device>,
        transaction: u16,
        request: &Addressed,
    ) -> Vec<(Mbap<ResponseAdu>, std::time::Duration)> {
        let bytes = Mbap {
            transaction: TransactionId(transaction),
            adu: request.to_adu(),
        }
        .to_bytes();
        server
            .receive(&bytes, Instant::now())
            .into_iter()
            .map(|tx| {
                let (frame, len) = decode_response(&tx.bytes)
                    .expect("a valid frame")
                    .expect("a whole frame");
                assert_eq!(len, tx.bytes.len());
                (frame, tx.delay)
            })
            .collect()
    }

    #[test]
    fn the_answer_echoes_the_transaction_id_and_unit_after_the_devices_delay() {
        let mut s = server();
        let write = Addressed::new(unit(3), Request::write_single_register(7, 4242));
        assert_eq!(ask(&mut s, 0xBEEF, &write).len(), 1);
        let read = Addressed::new(unit(3), Request::read_holding_registers(6, 2).expect("2"));
        let answers = ask(&mut s, 0x0102, &read);
        let [(frame, delay)] = answers.as_slice() else {
            panic!("one answer: {answers:?}")
        };
        assert_eq!(frame.transaction, TransactionId(0x0102));
        assert_eq!(frame.adu.unit, 3);
        assert_eq!(*delay, DEFAULT_REPLY_DELAY);
        assert_eq!(
            check_response(&read, &frame.adu),
            Ok(Answer::Registers(vec![0, 4242]))
        );
    }

    #[test]
    fn a_unit_the_device_does_not_answer_gets_silence() {
        let mut s = server();
        let read = Addressed::new(unit(4), Request::read_coils(0, 1).expect("1"));
        assert!(ask(&mut s, 1, &read).is_empty());
    }

    #[test]
    fn as_a_gateway_a_unit_that_does_not_answer_gets_exception_11_after_the_wait() {
        let wait = std::time::Duration::from_millis(150);
        let mut s = server().answering_silence(wait);
        let read = Addressed::new(unit(4), Request::read_coils(0, 1).expect("1"));
        let answers = ask(&mut s, 7, &read);
        let [(frame, delay)] = answers.as_slice() else {
            panic!("one answer: {answers:?}")
        };
        assert_eq!(*delay, wait);
        assert_eq!((frame.transaction, frame.adu.unit), (TransactionId(7), 4));
        assert_eq!(
            frame.adu.response,
            Response::exception(
                FunctionCode::of_exception(1),
                ExceptionCode::GATEWAY_TARGET_FAILED
            )
        );
        // The unit that is there answers as before; a broadcast still gets nothing.
        let there = Addressed::new(unit(3), Request::read_coils(0, 1).expect("1"));
        assert_eq!(ask(&mut s, 8, &there)[0].1, DEFAULT_REPLY_DELAY);
        let bytes = Mbap {
            transaction: TransactionId(9),
            adu: crate::rtu::Broadcast(crate::rtu::Write::SingleRegister(
                crate::rtu::WriteRegister {
                    address: 1,
                    value: 2,
                },
            ))
            .to_adu(),
        }
        .to_bytes();
        assert!(s.receive(&bytes, Instant::now()).is_empty());
    }

    #[test]
    fn requests_split_anywhere_and_back_to_back_are_each_answered() {
        let mut s = server();
        let mut stream = Vec::new();
        for transaction in [10, 11, 12] {
            let read = Addressed::new(unit(3), Request::read_coils(0, 3).expect("3"));
            stream.extend(
                Mbap {
                    transaction: TransactionId(transaction),
                    adu: read.to_adu(),
                }
                .to_bytes(),
            );
        }
        let mut answered = Vec::new();
        for chunk in stream.chunks(5) {
            for tx in s.receive(chunk, Instant::now()) {
                let (frame, _) = decode_response(&tx.bytes).expect("valid").expect("whole");
                answered.push(frame.transaction.0);
            }
        }
        assert_eq!(answered, [10, 11, 12]);
    }

    #[test]
    fn a_function_rtu_cannot_frame_is_refused_with_exception_1() {
        let mut s = server();
        let bytes = [0, 9, 0, 0, 0, 5, 3, 0x2B, 0x0E, 0x01, 0x00];
        let out = s.receive(&bytes, Instant::now());
        let [tx] = out.as_slice() else {
            panic!("one answer: {out:?}")
        };
        let (frame, _) = decode_response(&tx.bytes).expect("valid").expect("whole");
        assert_eq!(frame.transaction, TransactionId(9));
        assert_eq!(
            frame.adu.response,
            Response::exception(
                FunctionCode::of_exception(0x2B),
                ExceptionCode::ILLEGAL_FUNCTION
            )
        );
    }

    #[test]
    fn garbage_is_dropped_and_the_next_request_answered() {
        let mut s = server();
        let read = Addressed::new(unit(3), Request::read_holding_registers(0, 1).expect("1"));
        let mut bytes = vec![0xFF, 0xFF, 0x12];
        bytes.extend(
            Mbap {
                transaction: TransactionId(5),
                adu: read.to_adu(),
            }
            .to_bytes(),
        );
        let out = s.receive(&bytes, Instant::now());
        assert_eq!(out.len(), 1);
        assert!(s.dropped() > 0);
    }
}
