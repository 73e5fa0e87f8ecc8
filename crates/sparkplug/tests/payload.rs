//! The protobuf payload: byte vectors worked out by hand from the wire format,
//! typed values to and from protobuf, and garbage that must give errors, not panics.
//!
//! Protobuf wire format: each field is a key `field_number << 3 | wire_type`
//! (wire type 0 = varint, 2 = length-delimited, 5 = 32-bit, 1 = 64-bit) followed by
//! its value; varints are 7 bits a byte, low first, high bit set on all but the last.

use proptest::prelude::*;
use prost::Message as _;
use sparkplug::proto::{Metric, Payload, metric::Value};
use sparkplug::{
    BdSeq, DataType, EdgeNode, Id, MetricValue, Quality, Timestamp, ValueError, metric,
};

/// Payload { timestamp: 1, metrics: [Metric { name: "a", datatype: 11, boolean_value:
/// true }], seq: 0 }, field by field in tag order:
const SMALL_PAYLOAD: [u8; 13] = [
    0x08, 0x01, // timestamp: field 1, varint (1 << 3 | 0 = 0x08); value 1
    0x12, 0x07, // metrics: field 2, length-delimited (2 << 3 | 2 = 0x12); 7 bytes follow
    0x0A, 0x01, 0x61, //   name: field 1, length-delimited (0x0A); 1 byte; "a"
    0x20, 0x0B, //   datatype: field 4, varint (4 << 3 = 0x20); 11 = Boolean
    0x70, 0x01, //   boolean_value: field 14, varint (14 << 3 = 112 = 0x70); true
    0x18, 0x00, // seq: field 3, varint (3 << 3 = 0x18); 0 — proto2 sends a set zero
];

#[test]
fn a_small_payload_encodes_to_the_bytes_worked_out_by_hand() {
    let payload = Payload {
        timestamp: Some(1),
        metrics: vec![Metric {
            name: Some("a".into()),
            datatype: Some(DataType::Boolean.code()),
            value: Some(MetricValue::Boolean(true).to_proto()),
            ..Metric::default()
        }],
        seq: Some(0),
        ..Payload::default()
    };
    assert_eq!(payload.encode_to_vec(), SMALL_PAYLOAD);
    assert_eq!(Payload::decode(&SMALL_PAYLOAD[..]).unwrap(), payload);
}

/// NDEATH with bdSeq 7: Payload { metrics: [Metric { name: "bdSeq", datatype: 4
/// (Int64), long_value: 7 }] }, no timestamp, no seq.
const NDEATH_BD_SEQ_7: [u8; 13] = [
    0x12, 0x0B, // metrics: field 2, length-delimited; 11 bytes follow
    0x0A, 0x05, b'b', b'd', b'S', b'e', b'q', //   name: field 1; 5 bytes "bdSeq"
    0x20, 0x04, //   datatype: field 4, varint; 4 = Int64
    0x58, 0x07, //   long_value: field 11, varint (11 << 3 = 88 = 0x58); 7
];

#[test]
fn the_will_encodes_to_the_bytes_worked_out_by_hand() {
    let node = EdgeNode::new(
        Id::new("cell").unwrap(),
        Id::new("gw1").unwrap(),
        BdSeq::new(7),
    );
    let will = node.will();
    assert_eq!(will.topic.to_string(), "spBv1.0/cell/NDEATH/gw1");
    assert_eq!(will.payload, NDEATH_BD_SEQ_7);
}

#[test]
fn an_int32_of_minus_one_goes_as_its_twos_complement_bits() {
    assert_eq!(
        MetricValue::Int32(-1).to_proto(),
        Value::IntValue(0xFFFF_FFFF)
    );
    assert_eq!(
        MetricValue::Int8(-1).to_proto(),
        Value::IntValue(0xFFFF_FFFF)
    );
    assert_eq!(
        MetricValue::Int64(-2).to_proto(),
        Value::LongValue(0xFFFF_FFFF_FFFF_FFFE)
    );
    let metric = Metric {
        value: Some(MetricValue::Int32(-1).to_proto()),
        ..Metric::default()
    };
    // int_value: field 10, varint (10 << 3 = 80 = 0x50); 0xFFFFFFFF as a varint is
    // four bytes of 7 ones with the continuation bit, then the last 4 ones.
    assert_eq!(metric.encode_to_vec(), [0x50, 0xFF, 0xFF, 0xFF, 0xFF, 0x0F]);
}

#[test]
fn a_value_in_the_wrong_field_is_refused_naming_both_fields() {
    assert_eq!(
        MetricValue::from_proto(DataType::Int32, Some(&Value::LongValue(5))),
        Err(ValueError::WrongField {
            datatype: DataType::Int32,
            expected: "int_value",
            found: "long_value"
        })
    );
    assert_eq!(
        MetricValue::from_proto(DataType::Double, None),
        Err(ValueError::Missing {
            datatype: DataType::Double,
            expected: "double_value"
        })
    );
}

#[test]
fn an_int8_that_does_not_fit_is_refused_not_cut() {
    assert_eq!(
        MetricValue::from_proto(DataType::Int8, Some(&Value::IntValue(200))),
        Err(ValueError::OutOfRange {
            datatype: DataType::Int8,
            field: "int_value",
            value: 200
        })
    );
    assert_eq!(
        MetricValue::from_proto(DataType::UInt16, Some(&Value::IntValue(70_000))),
        Err(ValueError::OutOfRange {
            datatype: DataType::UInt16,
            field: "int_value",
            value: 70_000
        })
    );
}

#[test]
fn data_type_codes_are_the_specs() {
    assert_eq!(DataType::Int8.code(), 1);
    assert_eq!(DataType::Int64.code(), 4);
    assert_eq!(DataType::UInt8.code(), 5);
    assert_eq!(DataType::UInt64.code(), 8);
    assert_eq!(DataType::Float.code(), 9);
    assert_eq!(DataType::Boolean.code(), 11);
    assert_eq!(DataType::Text.code(), 14);
    for code in 1..=14 {
        assert_eq!(DataType::from_code(code).unwrap().code(), code);
    }
    assert_eq!(
        DataType::from_code(19),
        Err(ValueError::UnsupportedDataType { code: 19 })
    );
}

#[test]
fn quality_codes_are_192_500_and_0() {
    assert_eq!(Quality::Good.code(), 192);
    assert_eq!(Quality::Stale.code(), 500);
    assert_eq!(Quality::Bad.code(), 0);
    assert_eq!(Quality::from_code(500), Some(Quality::Stale));
    assert_eq!(Quality::from_code(7), None);
}

fn any_value() -> impl Strategy<Value = MetricValue> {
    prop_oneof![
        any::<i8>().prop_map(MetricValue::Int8),
        any::<i16>().prop_map(MetricValue::Int16),
        any::<i32>().prop_map(MetricValue::Int32),
        any::<i64>().prop_map(MetricValue::Int64),
        any::<u8>().prop_map(MetricValue::UInt8),
        any::<u16>().prop_map(MetricValue::UInt16),
        any::<u32>().prop_map(MetricValue::UInt32),
        any::<u64>().prop_map(MetricValue::UInt64),
        any::<f32>()
            .prop_filter("NaN is not equal to itself", |f| !f.is_nan())
            .prop_map(MetricValue::Float),
        any::<f64>()
            .prop_filter("NaN is not equal to itself", |f| !f.is_nan())
            .prop_map(MetricValue::Double),
        any::<bool>().prop_map(MetricValue::Boolean),
        ".*".prop_map(MetricValue::String),
        any::<u64>().prop_map(|ms| MetricValue::DateTime(Timestamp::from_millis(ms))),
        ".*".prop_map(MetricValue::Text),
    ]
}

proptest! {
    #[test]
    fn every_value_survives_a_trip_through_protobuf_bytes(value in any_value()) {
        let sent = Metric {
            datatype: Some(value.datatype().code()),
            value: Some(value.to_proto()),
            ..Metric::default()
        };
        let received = Metric::decode(&sent.encode_to_vec()[..]).unwrap();
        let datatype = DataType::from_code(received.datatype.unwrap()).unwrap();
        prop_assert_eq!(MetricValue::from_proto(datatype, received.value.as_ref()), Ok(value));
    }

    #[test]
    fn random_bytes_decode_to_a_payload_or_an_error_never_a_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..256)
    ) {
        if let Ok(payload) = Payload::decode(&bytes[..]) {
            for m in &payload.metrics {
                let _ = Quality::of(m);
                if let Some(Ok(datatype)) = m.datatype.map(DataType::from_code) {
                    let _ = MetricValue::from_proto(datatype, m.value.as_ref());
                }
            }
        }
    }
}

#[test]
fn a_truncated_payload_is_an_error() {
    assert!(Payload::decode(&SMALL_PAYLOAD[..5]).is_err());
    assert!(Payload::decode(&[0xFF, 0xFF, 0xFF][..]).is_err());
}

#[test]
fn the_quality_property_is_read_back_from_a_metric() {
    let m = metric::data_metric(
        3,
        &sparkplug::Sample::stale(Timestamp::from_millis(9)),
        false,
        false,
    );
    assert_eq!(Quality::of(&m), Some(Quality::Stale));
    assert_eq!(m.is_null, Some(true));
    assert_eq!(m.value, None);
}
