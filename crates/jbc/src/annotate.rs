//! Frames in words, for annotated dumps of captured traffic (`cellbus decode jbc`).

use crate::code::{Code, NakReason, interpret};
use crate::frame::{Frame, Header};

/// One line saying what a frame is: who speaks to whom, what is asked or answered, and
/// the value in its unit. The frame decoded, so its BCC was good.
pub fn describe(frame: &Frame) -> String {
    let route = match frame.route {
        Some(route) => format!("{} → {}", route.source, route.target),
        None => "no address".to_owned(),
    };
    let code = Code::from_raw(frame.code);
    let what = match code {
        Some(code) => format!("{} ({code})", code.describe()),
        None => format!("code {} (not a JTSE command)", frame.code),
    };
    let value = || match (code, &frame.data) {
        (Some(code), Some(data)) => match interpret(code, data) {
            Ok(reading) => reading.to_string(),
            Err(e) => format!("{data:?}: {e}"),
        },
        (None, Some(data)) => format!("{data:?}"),
        (_, None) => "no data".to_owned(),
    };
    let meaning = match (frame.header, &frame.data) {
        (Header::Read, _) => format!("read {what}"),
        (Header::Write, _) => format!("write {what} = {}", value()),
        (Header::Ack, Some(_)) => format!("answer: {what} = {}", value()),
        (Header::Ack, None) => format!("acknowledged: {what}"),
        (Header::Nak, data) => {
            let reason = data.and_then(|d| d.as_number()).map(NakReason::from_code);
            match reason {
                Some(reason) => format!("refused {what}: {reason}"),
                None => format!("refused {what} without an error number"),
            }
        }
    };
    format!("{route}  {meaning}  (BCC ok)")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::code::Code;
    use crate::frame::{Address, Data, Route};

    fn route(source: u8, target: u8) -> Option<Route> {
        Some(Route {
            source: Address::new(source).unwrap(),
            target: Address::new(target).unwrap(),
        })
    }

    #[test]
    fn a_read_answer_is_described_with_its_value_and_unit() {
        let code: Code = "ST1".parse().unwrap();
        let frame = Frame {
            route: route(1, 0),
            header: Header::Ack,
            code: code.raw(),
            data: Some(Data::number(350).unwrap()),
        };
        let text = describe(&frame);
        assert!(text.starts_with("01 → 00  answer: "), "{text}");
        assert!(text.contains("350 °C"), "{text}");
    }

    #[test]
    fn a_nak_is_described_with_its_reason() {
        let code: Code = "ST1".parse().unwrap();
        let frame = Frame {
            route: None,
            header: Header::Nak,
            code: code.raw(),
            data: Some(Data::number(3).unwrap()),
        };
        let text = describe(&frame);
        assert!(text.starts_with("no address  refused"), "{text}");
        assert!(text.to_lowercase().contains("out of range"), "{text}");
    }

    #[test]
    fn an_unknown_code_is_named_as_such() {
        let frame = Frame {
            route: route(0, 1),
            header: Header::Read,
            code: "ST3".parse().unwrap(),
            data: None,
        };
        assert!(describe(&frame).contains("not a JTSE command"));
    }
}
