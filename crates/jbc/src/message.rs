//! Typed messages: what the robot asks ([`Request`]), what the station answers ([`Reply`]),
//! and whether a frame off the line answers a given request ([`match_reply`]).

use std::fmt;

use crate::code::{Code, NakReason, Tool};
use crate::frame::{DATA_MAX, DATA_MIN, Data, Frame, Header, RawCode, Route};

/// A request from the robot: read a code, or write a value to it.
///
/// Build it with [`Request::read`] or [`Request::write`], which refuse what the station
/// would refuse for certain (reading an action, writing a measurement, a port status other
/// than 0/1…); limits that depend on the station's settings (MIN/MAX temperatures) are left
/// to the station, which answers NAK 3.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Request {
    /// `R` + code, no data.
    Read(Code),
    /// `W` + code + data.
    Write(Code, Data),
}

/// A request the station would refuse for certain.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RequestError {
    /// Reading an action (`RSP`, `RST`).
    #[error("{code} ({what}) can only be written: it is an action, not a value", what = code.describe())]
    WriteOnly {
        /// The code.
        code: Code,
    },
    /// Writing a measurement, a counter or a fixed property.
    #[error("{code} ({what}) can only be read", what = code.describe())]
    ReadOnly {
        /// The code.
        code: Code,
    },
    /// A value the code never takes.
    #[error("{value} cannot be written to {code} ({what}): it takes {min} to {max}", what = code.describe())]
    OutOfRange {
        /// The code.
        code: Code,
        /// The value given.
        value: i64,
        /// Lowest value.
        min: i32,
        /// Highest value.
        max: i32,
    },
    /// A code the station does not accept (adjust temperature without a tool, `A10`).
    #[error(
        "{code} is not a code the station accepts: adjust temperatures exist for JT (A11) and TE (A12)"
    )]
    NotAccepted {
        /// The code.
        code: Code,
    },
}

/// Values a write may carry, per code: the spec's only port statuses (`00000`, `00001`),
/// the two work modes, `00000` for the reset actions (their data carries no meaning; this
/// crate always sends zero), and whatever fits the data field otherwise.
fn write_range(code: Code) -> (i32, i32) {
    match code {
        Code::PortStatus(_) => (0, 1),
        Code::WorkMode(_) => (0, 1),
        Code::ResetParameters | Code::ResetSettings => (0, 0),
        _ => (DATA_MIN, DATA_MAX),
    }
}

fn check_accepted(code: Code) -> Result<(), RequestError> {
    match code {
        Code::AdjustTemp(_, Tool::None) => Err(RequestError::NotAccepted { code }),
        _ => Ok(()),
    }
}

impl Request {
    /// A read of `code`; refuses write-only codes.
    pub fn read(code: Code) -> Result<Request, RequestError> {
        check_accepted(code)?;
        if !code.readable() {
            return Err(RequestError::WriteOnly { code });
        }
        Ok(Request::Read(code))
    }

    /// A write of `value` to `code`; refuses read-only codes and values the code never
    /// takes (see the range rules on [`Request`]).
    pub fn write(code: Code, value: i32) -> Result<Request, RequestError> {
        check_accepted(code)?;
        if !code.writable() {
            return Err(RequestError::ReadOnly { code });
        }
        let (min, max) = write_range(code);
        if !(min..=max).contains(&value) {
            return Err(RequestError::OutOfRange {
                code,
                value: value.into(),
                min,
                max,
            });
        }
        let data = Data::number(value).map_err(|_| RequestError::OutOfRange {
            code,
            value: value.into(),
            min,
            max,
        })?;
        Ok(Request::Write(code, data))
    }

    /// The code asked about.
    pub fn code(&self) -> Code {
        match *self {
            Request::Read(code) | Request::Write(code, _) => code,
        }
    }

    /// `R` or `W`.
    pub fn header(&self) -> Header {
        match self {
            Request::Read(_) => Header::Read,
            Request::Write(..) => Header::Write,
        }
    }

    /// The frame to send; `route` is robot → station in the addressed form, `None` in the
    /// form without address.
    pub fn to_frame(&self, route: Option<Route>) -> Frame {
        let data = match *self {
            Request::Read(_) => None,
            Request::Write(_, data) => Some(data),
        };
        Frame {
            route,
            header: self.header(),
            code: self.code().raw(),
            data,
        }
    }
}

impl fmt::Display for Request {
    /// `read ST1` or `write ST1 = 00350`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Request::Read(code) => write!(f, "read {code}"),
            Request::Write(code, data) => write!(f, "write {code} = {data}"),
        }
    }
}

/// A station's answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Reply {
    /// `A`: accepted; data when answering a read.
    Ack {
        /// The code answered.
        code: RawCode,
        /// The value read, for a read.
        data: Option<Data>,
    },
    /// `N`: refused, with the reason.
    Nak {
        /// The code refused (echoed from the request).
        code: RawCode,
        /// Why.
        reason: NakReason,
    },
}

/// A frame that is not a station's answer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReplyError {
    /// A request (`R` or `W`), not an answer.
    #[error("a {header} frame is a request, not a station's answer")]
    NotAReply {
        /// The header.
        header: Header,
    },
    /// A NAK without a communication-error number in its data.
    #[error("NAK for {code} carries no error number (data {data:?})")]
    NakWithoutNumber {
        /// The code refused.
        code: RawCode,
        /// The data field, if any.
        data: Option<String>,
    },
}

impl Reply {
    /// Reads a station's answer from a frame.
    pub fn from_frame(frame: &Frame) -> Result<Reply, ReplyError> {
        match frame.header {
            Header::Read | Header::Write => Err(ReplyError::NotAReply {
                header: frame.header,
            }),
            Header::Ack => Ok(Reply::Ack {
                code: frame.code,
                data: frame.data,
            }),
            Header::Nak => match frame.data.as_ref().and_then(Data::as_number) {
                Some(n) => Ok(Reply::Nak {
                    code: frame.code,
                    reason: NakReason::from_code(n),
                }),
                None => Err(ReplyError::NakWithoutNumber {
                    code: frame.code,
                    data: frame.data.map(|d| d.to_string()),
                }),
            },
        }
    }

    /// The frame that carries this answer on `route` (station → robot).
    pub fn to_frame(&self, route: Option<Route>) -> Frame {
        match *self {
            Reply::Ack { code, data } => Frame {
                route,
                header: Header::Ack,
                code,
                data,
            },
            Reply::Nak { code, reason } => Frame {
                route,
                header: Header::Nak,
                code,
                data: Some(nak_data(reason)),
            },
        }
    }
}

/// The data field of a NAK: the error number; a number that does not fit (only possible
/// for [`NakReason::Other`]) becomes 99999, undefined.
fn nak_data(reason: NakReason) -> Data {
    Data::number(reason.code()).unwrap_or_else(|_| {
        Data::number(NakReason::UNDEFINED).expect("99999 fits the five-character data field")
    })
}

/// What a frame off the line means for the request in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Match {
    /// The station accepted: the value read, or `None` for a write.
    Answer(Option<Data>),
    /// The station refused.
    Refused(NakReason),
    /// Not the answer to this request (another code, another route, a request, a
    /// malformed answer): keep listening.
    NotOurs,
}

/// Whether `frame` answers `request`, sent on `expected_route` (robot → station; `None`
/// in the form without address).
///
/// The answer must come back on the reversed route (station → robot) or, without address,
/// without one; carry `A` or `N` and the request's code; an `A` to a read must carry data
/// and an `A` to a write must not; an `N` must carry its error number.
pub fn match_reply(request: &Request, expected_route: Option<Route>, frame: &Frame) -> Match {
    if frame.route != expected_route.map(Route::reversed) || frame.code != request.code().raw() {
        return Match::NotOurs;
    }
    match (frame.header, request, frame.data) {
        (Header::Ack, Request::Read(_), Some(data)) => Match::Answer(Some(data)),
        (Header::Ack, Request::Write(..), None) => Match::Answer(None),
        (Header::Nak, _, Some(data)) => match data.as_number() {
            Some(n) => Match::Refused(NakReason::from_code(n)),
            None => Match::NotOurs,
        },
        _ => Match::NotOurs,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::code::Port;
    use crate::frame::Address;

    const P: Port = Port::One;

    fn route() -> Route {
        Route {
            source: Address::ROBOT,
            target: Address::STATION,
        }
    }

    fn reply(header: Header, code: &str, data: Option<&str>) -> Frame {
        Frame {
            route: Some(route().reversed()),
            header,
            code: code.parse().expect("3 printable chars"),
            data: data
                .map(|d| Data::from_bytes(d.as_bytes().try_into().expect("5")).expect("printable")),
        }
    }

    #[test]
    fn read_request_encodes_the_spec_example_rst1() {
        let frame = Request::read(Code::SelectAirTemp(P))
            .unwrap()
            .to_frame(Some(route()));
        assert_eq!(frame.to_bytes(), b"\x020001RST1\x03\x64");
    }

    #[test]
    fn write_request_carries_zero_padded_data() {
        let frame = Request::write(Code::SelectAirTemp(P), 375)
            .unwrap()
            .to_frame(Some(route()));
        assert_eq!(frame.to_bytes(), b"\x020001WST100375\x03\x50");
        let frame = Request::write(Code::AdjustTemp(P, Tool::Jt), -50)
            .unwrap()
            .to_frame(Some(route()));
        assert_eq!(frame.to_bytes(), b"\x020001WA11-0050\x03\x3e");
    }

    #[test]
    fn requests_refuse_what_the_station_always_refuses() {
        assert_eq!(
            Request::read(Code::ResetParameters),
            Err(RequestError::WriteOnly {
                code: Code::ResetParameters
            })
        );
        assert_eq!(
            Request::write(Code::AirTemp(P), 1),
            Err(RequestError::ReadOnly {
                code: Code::AirTemp(P)
            })
        );
        assert_eq!(
            Request::write(Code::PortStatus(P), 10),
            Err(RequestError::OutOfRange {
                code: Code::PortStatus(P),
                value: 10,
                min: 0,
                max: 1
            })
        );
        assert!(Request::write(Code::WorkMode(P), 2).is_err());
        assert!(Request::write(Code::ResetSettings, 1).is_err());
        assert!(Request::write(Code::ResetSettings, 0).is_ok());
        assert!(Request::write(Code::SelectAirTemp(P), 100_000).is_err());
        assert!(Request::write(Code::SelectAirTemp(P), -10_000).is_err());
        assert!(Request::write(Code::SelectAirTemp(P), 99_999).is_ok());
        assert_eq!(
            Request::read(Code::AdjustTemp(P, Tool::None)),
            Err(RequestError::NotAccepted {
                code: Code::AdjustTemp(P, Tool::None)
            })
        );
        let text = Request::write(Code::PortStatus(P), 10)
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("port status") && text.contains("0 to 1"),
            "{text}"
        );
    }

    #[test]
    fn the_answer_to_a_read_carries_data() {
        let read = Request::read(Code::SelectAirTemp(P)).unwrap();
        let ack = reply(Header::Ack, "ST1", Some("00350"));
        assert_eq!(
            match_reply(&read, Some(route()), &ack),
            Match::Answer(ack.data)
        );
        let empty = reply(Header::Ack, "ST1", None);
        assert_eq!(match_reply(&read, Some(route()), &empty), Match::NotOurs);
    }

    #[test]
    fn the_answer_to_a_write_carries_no_data() {
        let write = Request::write(Code::SelectAirTemp(P), 350).unwrap();
        assert_eq!(
            match_reply(&write, Some(route()), &reply(Header::Ack, "ST1", None)),
            Match::Answer(None)
        );
        assert_eq!(
            match_reply(
                &write,
                Some(route()),
                &reply(Header::Ack, "ST1", Some("00350"))
            ),
            Match::NotOurs
        );
    }

    #[test]
    fn a_nak_for_our_code_is_a_refusal_with_its_reason() {
        let write = Request::write(Code::SelectAirTemp(P), 999).unwrap();
        let nak = reply(Header::Nak, "ST1", Some("00003"));
        assert_eq!(
            match_reply(&write, Some(route()), &nak),
            Match::Refused(NakReason::OutOfRange)
        );
        let odd = reply(Header::Nak, "ST1", Some("00042"));
        assert_eq!(
            match_reply(&write, Some(route()), &odd),
            Match::Refused(NakReason::Other(42))
        );
        let no_number = reply(Header::Nak, "ST1", Some(" JTSE"));
        assert_eq!(
            match_reply(&write, Some(route()), &no_number),
            Match::NotOurs
        );
    }

    #[test]
    fn frames_for_another_code_route_or_form_are_not_ours() {
        let read = Request::read(Code::SelectAirTemp(P)).unwrap();
        assert_eq!(
            match_reply(
                &read,
                Some(route()),
                &reply(Header::Ack, "SF1", Some("00050"))
            ),
            Match::NotOurs
        );
        // Our own request echoed back (robot → station) is not an answer.
        let mut echo = read.to_frame(Some(route()));
        assert_eq!(match_reply(&read, Some(route()), &echo), Match::NotOurs);
        echo.header = Header::Ack;
        echo.data = Data::number(1).ok();
        assert_eq!(match_reply(&read, Some(route()), &echo), Match::NotOurs);
        // Another station's answer.
        let mut other = reply(Header::Ack, "ST1", Some("00350"));
        other.route = Some(Route {
            source: Address::new(2).unwrap(),
            target: Address::ROBOT,
        });
        assert_eq!(match_reply(&read, Some(route()), &other), Match::NotOurs);
        // The form without address when we expect addresses, and the other way round.
        let mut bare = reply(Header::Ack, "ST1", Some("00350"));
        bare.route = None;
        assert_eq!(match_reply(&read, Some(route()), &bare), Match::NotOurs);
        assert_eq!(match_reply(&read, None, &bare), Match::Answer(bare.data));
        assert_eq!(
            match_reply(&read, None, &reply(Header::Ack, "ST1", Some("00350"))),
            Match::NotOurs
        );
    }

    #[test]
    fn reply_from_frame_reads_acks_and_naks() {
        let ack = reply(Header::Ack, "ST1", Some("00350"));
        assert_eq!(
            Reply::from_frame(&ack),
            Ok(Reply::Ack {
                code: ack.code,
                data: ack.data
            })
        );
        let nak = reply(Header::Nak, "ST3", Some("00004"));
        let parsed = Reply::from_frame(&nak).unwrap();
        assert_eq!(
            parsed,
            Reply::Nak {
                code: nak.code,
                reason: NakReason::ControlCode
            }
        );
        assert_eq!(parsed.to_frame(nak.route), nak);
        let request = Request::read(Code::StationModel).unwrap().to_frame(None);
        assert_eq!(
            Reply::from_frame(&request),
            Err(ReplyError::NotAReply {
                header: Header::Read
            })
        );
        assert!(matches!(
            Reply::from_frame(&reply(Header::Nak, "ST1", None)),
            Err(ReplyError::NakWithoutNumber { .. })
        ));
    }

    #[test]
    fn a_nak_whose_number_does_not_fit_is_sent_as_undefined() {
        let frame = Reply::Nak {
            code: "ST1".parse().unwrap(),
            reason: NakReason::Other(123_456),
        }
        .to_frame(None);
        assert_eq!(frame.data.and_then(|d| d.as_number()), Some(99999));
    }
}
