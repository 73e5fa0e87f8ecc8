//! The sans-IO mapping from the cell to OPC UA: node ids, data types, values with their
//! status codes and timestamps, engineering units and ranges.
//!
//! | point kind | OPC UA data type | value |
//! |---|---|---|
//! | numeric | Double | the number |
//! | enumeration | Int32 | the state's number; its labels in the `EnumValues` property (and `EnumStrings` when the numbers are 0, 1, 2, …) |
//! | text | String | the text |
//!
//! | point quality | StatusCode | value |
//! |---|---|---|
//! | good | Good | the value |
//! | stale | Uncertain_LastUsableValue | the last good value |
//! | bad (the read failed, the device is down) | Bad_CommunicationError | none |
//! | never read | Bad_NoCommunication | none |
//!
//! The source timestamp is when the device was read; the server timestamp when the
//! server took the change.
//!
//! The gateway's events are `CellbusEventType` events ([`CellEvent`], a BaseEventType with
//! two more properties: `Kind`, the event's kind as `/api/events` names it, and `Fields`,
//! its facts for programs as a JSON object) on the device's object (the gateway object
//! when they concern no device), with the severity of their kind
//! ([`EventKind::severity`](gateway::event::EventKind::severity), shared with the Sparkplug
//! events). A client that subscribes to BaseEventType gets them too, without the two.

use ::opcua::nodes::BaseEventType;
use ::opcua::types::{
    ByteString, DataTypeId, DataValue, DateTime, EUInformation, EnumValueType, LocalizedText,
    NodeId, Range, StatusCode, UAString, Variant,
};

use gateway::cell::{DeviceStatus, DeviceSummary, PointView};
use gateway::event::Event;
use gateway::point::{EnumState, PointKind, Quality, Value};
use gateway::time::Timestamp;

/// The namespace of the cell's nodes.
pub const NAMESPACE_URI: &str = "urn:cellbus:cell";

/// UNECE's namespace for `EUInformation.unitId` (OPC UA Part 8).
pub const UNECE_NAMESPACE: &str = "http://www.opcfoundation.org/UA/units/un/cefact";

/// OPC UA ticks (100 ns since 1601-01-01) at 1970-01-01.
const TICKS_AT_UNIX_EPOCH: i64 = 116_444_736_000_000_000;
/// Ticks per millisecond.
const TICKS_PER_MS: i64 = 10_000;

/// Where each part of the cell lives in the namespace (string node ids).
pub mod ids {
    use super::NodeId;

    /// The `Cell` folder under `Objects`.
    pub fn cell(ns: u16) -> NodeId {
        NodeId::new(ns, "cell")
    }

    /// A line's folder.
    pub fn line(ns: u16, line: &str) -> NodeId {
        NodeId::new(ns, format!("line:{line}"))
    }

    /// A device's object (its id: `jbc1`).
    pub fn device(ns: u16, device: &str) -> NodeId {
        NodeId::new(ns, device.to_owned())
    }

    /// A device's `Production` folder (its machine state and OEE).
    pub fn production(ns: u16, device: &str) -> NodeId {
        NodeId::new(ns, format!("{device}/Production"))
    }

    /// A device's `Status` variable.
    pub fn device_status(ns: u16, device: &str) -> NodeId {
        NodeId::new(ns, format!("{device}/Status"))
    }

    /// A device's `Error` variable.
    pub fn device_error(ns: u16, device: &str) -> NodeId {
        NodeId::new(ns, format!("{device}/Error"))
    }

    /// A point's variable (its id: `jbc1.air_temperature`).
    pub fn point(ns: u16, point: &str) -> NodeId {
        NodeId::new(ns, point.to_owned())
    }

    /// A property of a point (`EngineeringUnits`, `EURange`).
    pub fn property(ns: u16, point: &str, property: &str) -> NodeId {
        NodeId::new(ns, format!("{point}/{property}"))
    }

    /// The gateway object, and its variables by name.
    pub fn gateway(ns: u16, variable: Option<&str>) -> NodeId {
        match variable {
            Some(name) => NodeId::new(ns, format!("gateway/{name}")),
            None => NodeId::new(ns, "gateway"),
        }
    }

    /// The gateway's `Alarms` object, which holds the methods that act on alarms.
    pub fn alarm_methods(ns: u16) -> NodeId {
        NodeId::new(ns, "gateway/Alarms")
    }

    /// A method of the `Alarms` object (`Acknowledge`, `Shelve`, `Unshelve`).
    pub fn alarm_method(ns: u16, method: &str) -> NodeId {
        NodeId::new(ns, format!("gateway/Alarms/{method}"))
    }

    /// An argument list (`InputArguments`, `OutputArguments`) of a method of the
    /// `Alarms` object.
    pub fn alarm_method_arguments(ns: u16, method: &str, which: &str) -> NodeId {
        NodeId::new(ns, format!("gateway/Alarms/{method}/{which}"))
    }

    /// A device's `Alarms` folder.
    pub fn device_alarms(ns: u16, device: &str) -> NodeId {
        NodeId::new(ns, format!("{device}/Alarms"))
    }

    /// An alarm's object (its id: `jbc1:down`, `sealer0.temperature:high`).
    pub fn alarm(ns: u16, alarm: &str) -> NodeId {
        NodeId::new(ns, format!("alarm:{alarm}"))
    }

    /// A variable of an alarm's object (`State`, `Active`, …).
    pub fn alarm_variable(ns: u16, alarm: &str, variable: &str) -> NodeId {
        NodeId::new(ns, format!("alarm:{alarm}/{variable}"))
    }
}

/// The OPC UA data type of a point of `kind`.
pub fn data_type(kind: &PointKind) -> DataTypeId {
    match kind {
        PointKind::Numeric => DataTypeId::Double,
        PointKind::Enum { .. } => DataTypeId::Int32,
        PointKind::Text => DataTypeId::String,
    }
}

/// The status code of a point's quality (`None`: never read).
pub fn status_code(quality: Option<Quality>) -> StatusCode {
    match quality {
        Some(Quality::Good) => StatusCode::Good,
        Some(Quality::Stale) => StatusCode::UncertainLastUsableValue,
        Some(Quality::Bad) => StatusCode::BadCommunicationError,
        None => StatusCode::BadNoCommunication,
    }
}

/// A point's reading as an OPC UA data value: the value with Good, the last good value
/// with Uncertain_LastUsableValue when stale, no value when bad or never read; the source
/// timestamp when the device was read, the server timestamp `now`.
pub fn data_value(kind: &PointKind, view: &PointView, now: Timestamp) -> DataValue {
    stored_data_value(kind, view.value.as_ref(), view.quality, view.t, now)
}

/// A reading (live or stored) as an OPC UA data value (see [`data_value`]).
pub fn stored_data_value(
    kind: &PointKind,
    value: Option<&Value>,
    quality: Option<Quality>,
    t: Option<Timestamp>,
    now: Timestamp,
) -> DataValue {
    let mut status = status_code(quality);
    let value = match quality {
        Some(Quality::Good | Quality::Stale) => match value.map(|v| variant(kind, v)) {
            Some(Some(v)) => Some(v),
            // A value the data type cannot carry is not a reading.
            _ => {
                status = StatusCode::BadCommunicationError;
                None
            }
        },
        _ => None,
    };
    DataValue {
        // Always a value, Empty when there is none: async-opcua 0.19 answers a read of a
        // data value without one with no status at all, which a client takes for Good.
        value: Some(value.unwrap_or(Variant::Empty)),
        status: Some(status),
        source_timestamp: t.map(opc_time),
        server_timestamp: Some(opc_time(now)),
        ..DataValue::default()
    }
}

/// A point's value as the variant of its data type; `None` when it cannot be one.
pub fn variant(kind: &PointKind, value: &Value) -> Option<Variant> {
    match (kind, value) {
        (PointKind::Numeric, Value::Number(n)) => Some(Variant::Double(*n)),
        (PointKind::Enum { .. }, Value::Number(n)) => {
            let whole = n.round();
            (whole == *n && whole >= f64::from(i32::MIN) && whole <= f64::from(i32::MAX))
                .then_some(Variant::Int32(whole as i32))
        }
        (PointKind::Text, Value::Text(t)) => Some(Variant::from(t.as_str())),
        (PointKind::Text, Value::Number(n)) => Some(Variant::from(n.to_string())),
        _ => None,
    }
}

/// A written variant as a point value, and the JSON the audit log shows; `None` when the
/// variant is not a value of the point's data type (Bad_TypeMismatch).
pub fn written_value(kind: &PointKind, variant: &Variant) -> Option<(Value, serde_json::Value)> {
    let number = |n: f64| Some((Value::Number(n), serde_json::json!(n)));
    match (kind, variant) {
        (PointKind::Text, Variant::String(s)) => {
            let text = s.as_ref().to_owned();
            Some((Value::Text(text.clone()), serde_json::Value::String(text)))
        }
        (PointKind::Text, _) => None,
        (PointKind::Numeric | PointKind::Enum { .. }, v) => match v {
            Variant::Double(n) => number(*n),
            // As the client typed it: 1.23 as a Float is 1.2300000190734863 as a Double,
            // which a point of step 0.01 would refuse. The shortest text of the Float
            // reads back as the number meant.
            Variant::Float(n) => number(n.to_string().parse().unwrap_or(f64::from(*n))),
            Variant::Int32(n) => number(f64::from(*n)),
            Variant::Int16(n) => number(f64::from(*n)),
            Variant::UInt16(n) => number(f64::from(*n)),
            Variant::UInt32(n) => number(f64::from(*n)),
            Variant::SByte(n) => number(f64::from(*n)),
            Variant::Byte(n) => number(f64::from(*n)),
            Variant::Int64(n) => number(*n as f64),
            Variant::UInt64(n) => number(*n as f64),
            _ => None,
        },
    }
}

/// A written value as the audit log shows it: text, a number, true/false, `null` for no
/// value, else its OPC UA text.
pub fn variant_json(variant: &Variant) -> serde_json::Value {
    match variant {
        Variant::Empty => serde_json::Value::Null,
        Variant::Boolean(b) => serde_json::json!(b),
        Variant::String(s) => serde_json::json!(s.as_ref()),
        other => match written_value(&PointKind::Numeric, other) {
            Some((_, number)) => number,
            None => serde_json::json!(other.to_string()),
        },
    }
}

/// What a written value is, in a refusal: `String`, `an array`, `no value`.
pub fn variant_kind(variant: &Variant) -> String {
    match variant {
        Variant::Empty => "no value".to_owned(),
        Variant::Array(_) => "an array".to_owned(),
        other => other
            .scalar_type_id()
            .map_or_else(|| "another type".to_owned(), |t| format!("{t:?}")),
    }
}

/// An enumeration's states as the `EnumValues` property's values.
pub fn enum_values(states: &[EnumState]) -> Vec<EnumValueType> {
    states
        .iter()
        .map(|s| EnumValueType {
            value: s.value,
            display_name: LocalizedText::new("", &s.label),
            description: LocalizedText::null(),
        })
        .collect()
}

/// An enumeration's labels as the `EnumStrings` property's values, when its numbers are
/// 0, 1, 2, … in order (each label's index is its number); `None` otherwise.
pub fn enum_strings(states: &[EnumState]) -> Option<Vec<LocalizedText>> {
    let dense = states
        .iter()
        .enumerate()
        .all(|(i, s)| i64::try_from(i) == Ok(s.value));
    (dense && !states.is_empty()).then(|| {
        states
            .iter()
            .map(|s| LocalizedText::new("", &s.label))
            .collect()
    })
}

/// A point's unit as `EUInformation`, with its UNECE code when it is a common one.
pub fn eu_information(unit: &str) -> EUInformation {
    EUInformation {
        namespace_uri: UNECE_NAMESPACE.into(),
        unit_id: unece_unit_id(unit).unwrap_or(-1),
        display_name: LocalizedText::new("", unit),
        description: LocalizedText::new("", unit),
    }
}

/// The write range as an `EURange`.
pub fn eu_range(range: &gateway::point::WriteRange) -> Range {
    Range {
        low: range.min,
        high: range.max,
    }
}

/// A device's status in words: `up`, `down`, `backed off` or `connecting`.
pub fn device_status(summary: &DeviceSummary) -> &'static str {
    match (summary.status, summary.next_try_at) {
        (DeviceStatus::Connecting, _) => "connecting",
        (DeviceStatus::Up, _) => "up",
        (DeviceStatus::Down, Some(_)) => "backed off",
        (DeviceStatus::Down, None) => "down",
    }
}

/// A device's error in words (empty when it has none).
pub fn device_error(summary: &DeviceSummary) -> String {
    summary
        .error
        .as_ref()
        .map(|e| e.message.clone())
        .unwrap_or_default()
}

/// A gateway time as an OPC UA time.
pub fn opc_time(t: Timestamp) -> DateTime {
    DateTime::from(
        t.0.saturating_mul(TICKS_PER_MS)
            .saturating_add(TICKS_AT_UNIX_EPOCH),
    )
}

/// An OPC UA time as a gateway time (milliseconds; null and far times are clamped).
pub fn gateway_time(t: &DateTime) -> Timestamp {
    let ticks = t.checked_ticks();
    Timestamp((ticks - TICKS_AT_UNIX_EPOCH).div_euclid(TICKS_PER_MS))
}

/// The source name of the gateway's own events (and a line's).
pub const GATEWAY_SOURCE: &str = "gateway";

/// A unique event id: the server's start (ms since 1970) and the event's number since,
/// 8 bytes each, big-endian.
pub fn event_id(start: Timestamp, number: u64) -> ByteString {
    let mut bytes = start.0.to_be_bytes().to_vec();
    bytes.extend_from_slice(&number.to_be_bytes());
    ByteString::from(bytes)
}

/// The name (and string node id) of the gateway's event type.
pub const EVENT_TYPE: &str = "CellbusEventType";

pub use event_type::CellEvent;

/// The event type's Rust side: async-opcua's derive writes its constructors, which carry
/// no documentation.
mod event_type {
    #![allow(missing_docs)]

    use ::opcua::nodes::BaseEventType;
    use ::opcua::types::UAString;

    /// A gateway event as OPC UA raises it: a BaseEventType with the event's kind and fields.
    #[derive(Debug, ::opcua::Event)]
    #[opcua(identifier = "s=CellbusEventType", namespace = "urn:cellbus:cell")]
    pub struct CellEvent {
        /// The BaseEventType fields.
        pub base: BaseEventType,
        /// The namespace of the event type (the cell's).
        pub own_namespace_index: u16,
        /// The event's kind (`write`, `device_event`, `state_changed`, …).
        pub kind: UAString,
        /// The event's fields, a JSON object as `/api/events` gives it.
        pub fields: UAString,
    }
}

/// A gateway event as OPC UA raises it ([`CellEvent`]): its source the device's object
/// (the gateway object when it concerns no device), its time when it happened, its
/// receive time `now`.
pub fn cell_event(ns: u16, event: &Event, id: ByteString, now: Timestamp) -> CellEvent {
    let fields = serde_json::to_string(&event.fields).unwrap_or_else(|_| "{}".to_owned());
    CellEvent {
        base: base_event(ns, event, id, now),
        own_namespace_index: ns,
        kind: UAString::from(event.kind.as_str()),
        fields: UAString::from(fields),
    }
}

/// The BaseEventType part of a gateway event.
fn base_event(ns: u16, event: &Event, id: ByteString, now: Timestamp) -> BaseEventType {
    let (node, name) = match &event.device {
        Some(device) => (ids::device(ns, device.as_str()), device.as_str()),
        None => (ids::gateway(ns, None), GATEWAY_SOURCE),
    };
    let mut e = BaseEventType::new(
        NodeId::new(ns, EVENT_TYPE),
        id,
        LocalizedText::new("", &event.message),
        opc_time(event.t),
    )
    .set_source_node(node)
    .set_source_name(UAString::from(name))
    .set_receive_time(opc_time(now));
    e.severity = event.kind.severity();
    e
}

/// The UNECE common code of a unit as OPC UA Part 8 encodes it (the code's characters,
/// 8 bits each).
fn unece_unit_id(unit: &str) -> Option<i32> {
    let code = match unit {
        "°C" => "CEL",
        "K" => "KEL",
        "%" => "P1",
        "V" => "VLT",
        "A" => "AMP",
        "mA" => "4K",
        "W" => "WTT",
        "kW" => "KWT",
        "kVA" => "KVA",
        "kWh" => "KWH",
        "Hz" => "HTZ",
        "s" => "SEC",
        "ms" => "C26",
        "min" => "MIN",
        "h" => "HUR",
        "mm" => "MMT",
        "bar" => "BAR",
        "kPa" => "KPA",
        "l/min" => "L2",
        _ => return None,
    };
    Some(
        code.bytes()
            .fold(0_i32, |id, byte| (id << 8) | i32::from(byte)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ::opcua::types::ObjectTypeId;
    use gateway::event::EventKind;
    use gateway::point::DeviceId;

    /// jbc1's air temperature (°C, read at 1 s) with `value` and `quality`.
    fn view(value: Option<Value>, quality: Option<Quality>) -> PointView {
        let device = DeviceId::new("jbc1").unwrap();
        PointView {
            id: gateway::point::PointId::new(&device, "air_temperature").unwrap(),
            name: "Air temperature".into(),
            unit: Some("°C".into()),
            value,
            text: None,
            quality,
            t: Some(Timestamp(1_000)),
            error: None,
            alarm: false,
            period_ms: 1000,
        }
    }

    fn states(table: &[(i64, &str)]) -> Vec<EnumState> {
        table
            .iter()
            .map(|&(value, label)| EnumState {
                value,
                label: label.to_owned().into(),
            })
            .collect()
    }

    #[test]
    fn enumeration_labels_are_enum_values_and_enum_strings_only_when_numbered_from_zero() {
        let dense = states(&[(0, "off"), (1, "on")]);
        let values = enum_values(&dense);
        assert_eq!(values[1].value, 1);
        assert_eq!(values[1].display_name.text.as_ref(), "on");
        let strings = enum_strings(&dense).expect("0, 1: EnumStrings");
        assert_eq!(strings[0].text.as_ref(), "off");
        let sparse = states(&[(0, "ok"), (5, "fault")]);
        assert_eq!(enum_values(&sparse)[1].value, 5);
        assert_eq!(enum_strings(&sparse), None);
        assert_eq!(enum_strings(&states(&[(1, "one")])), None);
        assert_eq!(enum_strings(&[]), None);
    }

    #[test]
    fn an_event_of_a_device_comes_from_its_object_and_one_of_the_gateway_from_the_gateway() {
        let device = DeviceId::new("cross1").unwrap();
        let event = Event {
            t: Timestamp(1_000),
            kind: EventKind::AlarmRaised,
            line: Some("line1".into()),
            device: Some(device.clone()),
            point: None,
            message: "cross1: source lost".into(),
            fields: gateway::event::fields([("value", serde_json::json!(2))]),
        };
        let id = event_id(Timestamp(5), 7);
        let raised = cell_event(2, &event, id.clone(), Timestamp(2_000));
        let e = &raised.base;
        assert_eq!(e.event_id, id);
        assert_eq!(e.event_type, NodeId::new(2, EVENT_TYPE));
        assert_eq!(e.source_node, ids::device(2, "cross1"));
        assert_eq!(e.source_name, UAString::from("cross1"));
        assert_eq!(e.message, LocalizedText::new("", "cross1: source lost"));
        assert_eq!(e.severity, 700);
        assert_eq!(gateway_time(&e.time), Timestamp(1_000));
        assert_eq!(gateway_time(&e.receive_time), Timestamp(2_000));
        assert_eq!(raised.kind, UAString::from("alarm_raised"));
        assert_eq!(raised.fields, UAString::from(r#"{"value":2}"#));
        let started = Event::of_gateway(EventKind::GatewayStarted, "started".into());
        let raised = cell_event(2, &started, event_id(Timestamp(5), 8), Timestamp(2_000));
        assert_eq!(raised.base.source_node, ids::gateway(2, None));
        assert_eq!(raised.base.source_name, UAString::from(GATEWAY_SOURCE));
        assert_eq!(raised.base.severity, 200);
        assert_eq!(raised.fields, UAString::from("{}"));
    }

    #[test]
    fn a_client_selects_the_kind_and_the_fields_by_their_browse_names() {
        use ::opcua::nodes::Event as _;
        use ::opcua::types::{AttributeId, NumericRange, QualifiedName};
        let event = Event::of_gateway(EventKind::GatewayStarted, "started".into());
        let raised = cell_event(2, &event, event_id(Timestamp(5), 1), Timestamp(6));
        // Kind and Fields are in the cell's namespace, BaseEventType's own fields in 0.
        let select = |type_id: NodeId, ns: u16, name: &str| {
            raised.get_field(
                &type_id,
                AttributeId::Value,
                &NumericRange::None,
                &[QualifiedName::new(ns, name)],
            )
        };
        let ours = NodeId::new(2, EVENT_TYPE);
        assert_eq!(
            select(ours.clone(), 2, "Kind"),
            Variant::from("gateway_started")
        );
        assert_eq!(select(ours.clone(), 2, "Fields"), Variant::from("{}"));
        assert_eq!(
            select(ObjectTypeId::BaseEventType.into(), 0, "Message"),
            Variant::from(LocalizedText::new("", "started"))
        );
        assert_eq!(select(ours, 0, "Severity"), Variant::from(200_u16));
    }

    #[test]
    fn event_ids_differ_by_number_and_by_start() {
        assert_ne!(event_id(Timestamp(5), 1), event_id(Timestamp(5), 2));
        assert_ne!(event_id(Timestamp(5), 1), event_id(Timestamp(6), 1));
        assert_eq!(event_id(Timestamp(5), 1).as_ref().len(), 16);
    }

    #[test]
    fn a_good_number_is_a_good_double_timed_when_the_device_was_read() {
        let v = data_value(
            &PointKind::Numeric,
            &view(Some(Value::Number(21.5)), Some(Quality::Good)),
            Timestamp(9_000),
        );
        assert_eq!(v.value, Some(Variant::Double(21.5)));
        assert_eq!(v.status, Some(StatusCode::Good));
        assert_eq!(
            v.source_timestamp.map(|t| gateway_time(&t)),
            Some(Timestamp(1_000))
        );
        assert_eq!(
            v.server_timestamp.map(|t| gateway_time(&t)),
            Some(Timestamp(9_000))
        );
    }

    #[test]
    fn a_stale_value_is_uncertain_never_good() {
        let v = data_value(
            &PointKind::Numeric,
            &view(Some(Value::Number(21.5)), Some(Quality::Stale)),
            Timestamp(9_000),
        );
        assert_eq!(v.status, Some(StatusCode::UncertainLastUsableValue));
        assert_eq!(v.value, Some(Variant::Double(21.5)));
    }

    #[test]
    fn a_bad_or_never_read_point_has_a_bad_status_and_an_empty_value() {
        let bad = data_value(
            &PointKind::Numeric,
            &view(Some(Value::Number(21.5)), Some(Quality::Bad)),
            Timestamp(9_000),
        );
        assert_eq!(bad.status, Some(StatusCode::BadCommunicationError));
        assert_eq!(bad.value, Some(Variant::Empty), "not the last good value");
        let never = data_value(&PointKind::Numeric, &view(None, None), Timestamp(9_000));
        assert_eq!(never.status, Some(StatusCode::BadNoCommunication));
        assert_eq!(never.value, Some(Variant::Empty));
    }

    #[test]
    fn an_enumeration_is_an_int32_and_text_a_string() {
        let kind = PointKind::Enum {
            states: vec![EnumState {
                value: 9,
                label: "No tool".into(),
            }],
        };
        assert_eq!(data_type(&kind), DataTypeId::Int32);
        assert_eq!(variant(&kind, &Value::Number(9.0)), Some(Variant::Int32(9)));
        assert_eq!(variant(&kind, &Value::Number(9.5)), None);
        assert_eq!(data_type(&PointKind::Text), DataTypeId::String);
        assert_eq!(
            variant(&PointKind::Text, &Value::Text("P-12".into())),
            Some(Variant::from("P-12"))
        );
    }

    #[test]
    fn written_numbers_of_any_width_become_point_values_and_text_only_text() {
        assert_eq!(
            written_value(&PointKind::Numeric, &Variant::Float(2.5)).map(|(v, _)| v),
            Some(Value::Number(2.5))
        );
        assert_eq!(
            written_value(&PointKind::Numeric, &Variant::Int32(350)),
            Some((Value::Number(350.0), serde_json::json!(350.0)))
        );
        assert_eq!(
            written_value(&PointKind::Numeric, &Variant::from("350")),
            None
        );
        assert_eq!(written_value(&PointKind::Text, &Variant::Double(1.0)), None);
    }

    #[test]
    fn units_carry_their_unece_code_and_unknown_units_minus_one() {
        let celsius = eu_information("°C");
        assert_eq!(celsius.unit_id, 4_408_652); // "CEL"
        assert_eq!(celsius.display_name.text.as_ref(), "°C");
        assert_eq!(eu_information("strokes").unit_id, -1);
    }

    #[test]
    fn gateway_and_opc_ua_times_round_trip_in_milliseconds() {
        for ms in [0, 1, 1_700_000_000_123, -5_000] {
            assert_eq!(gateway_time(&opc_time(Timestamp(ms))), Timestamp(ms));
        }
    }
}
