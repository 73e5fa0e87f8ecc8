//! `proto/sparkplug_b.proto` and the Rust types in `sparkplug::proto` agree: for each
//! field, a message with only that field set encodes under the field number the
//! `.proto` file gives that field name, inside the right message.

use prost::Message;
use sparkplug::proto::{
    MetaData, Metric, Payload, PropertySet, PropertySetList, PropertyValue, metric, property_value,
};

const SCHEMA: &str = include_str!("../proto/sparkplug_b.proto");

/// The field number under which `bytes` (one encoded field) begins.
fn field_number(bytes: &[u8]) -> u64 {
    let mut key = 0u64;
    for (i, b) in bytes.iter().enumerate() {
        key |= u64::from(b & 0x7F) << (7 * i);
        if b & 0x80 == 0 {
            return key >> 3;
        }
    }
    panic!("no complete key in {bytes:02X?}");
}

/// The field number the schema gives `field` in `message`.
fn schema_number(message: &str, field: &str) -> u64 {
    let start = SCHEMA
        .find(&format!("message {message} {{"))
        .unwrap_or_else(|| panic!("no message {message} in the schema"));
    let block = &SCHEMA[start..];
    let block = &block[..block.find("\n}").expect("every message block ends")];
    block
        .lines()
        .map(|l| l.split("//").next().unwrap_or_default())
        .find_map(|l| {
            let (left, right) = l.split_once('=')?;
            (left.split_whitespace().last()? == field)
                .then(|| right.trim().trim_end_matches(';').trim().parse().ok())?
        })
        .unwrap_or_else(|| panic!("no field {field} in message {message}"))
}

fn check(message: &str, rows: Vec<(&str, Vec<u8>)>) {
    for (field, bytes) in rows {
        assert_eq!(
            field_number(&bytes),
            schema_number(message, field),
            "{message}.{field}"
        );
    }
}

#[test]
fn the_rust_payload_types_match_the_proto_file_field_for_field() {
    let p = Payload::default;
    check(
        "Payload",
        vec![
            (
                "timestamp",
                Payload {
                    timestamp: Some(1),
                    ..p()
                }
                .encode_to_vec(),
            ),
            (
                "metrics",
                Payload {
                    metrics: vec![Metric::default()],
                    ..p()
                }
                .encode_to_vec(),
            ),
            (
                "seq",
                Payload {
                    seq: Some(1),
                    ..p()
                }
                .encode_to_vec(),
            ),
            (
                "uuid",
                Payload {
                    uuid: Some("u".into()),
                    ..p()
                }
                .encode_to_vec(),
            ),
            (
                "body",
                Payload {
                    body: Some(vec![1]),
                    ..p()
                }
                .encode_to_vec(),
            ),
        ],
    );
    let m = Metric::default;
    let v = |value| {
        Metric {
            value: Some(value),
            ..m()
        }
        .encode_to_vec()
    };
    use metric::Value as V;
    check(
        "Metric",
        vec![
            (
                "name",
                Metric {
                    name: Some("n".into()),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "alias",
                Metric {
                    alias: Some(1),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "timestamp",
                Metric {
                    timestamp: Some(1),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "datatype",
                Metric {
                    datatype: Some(1),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "is_historical",
                Metric {
                    is_historical: Some(true),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "is_transient",
                Metric {
                    is_transient: Some(true),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "is_null",
                Metric {
                    is_null: Some(true),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "metadata",
                Metric {
                    metadata: Some(MetaData::default()),
                    ..m()
                }
                .encode_to_vec(),
            ),
            (
                "properties",
                Metric {
                    properties: Some(PropertySet::default()),
                    ..m()
                }
                .encode_to_vec(),
            ),
            ("int_value", v(V::IntValue(1))),
            ("long_value", v(V::LongValue(1))),
            ("float_value", v(V::FloatValue(1.0))),
            ("double_value", v(V::DoubleValue(1.0))),
            ("boolean_value", v(V::BooleanValue(true))),
            ("string_value", v(V::StringValue("s".into()))),
            ("bytes_value", v(V::BytesValue(vec![1]))),
            ("dataset_value", v(V::DatasetValue(vec![1]))),
            ("template_value", v(V::TemplateValue(vec![1]))),
            ("extension_value", v(V::ExtensionValue(vec![1]))),
        ],
    );
    check(
        "PropertySet",
        vec![
            (
                "keys",
                PropertySet {
                    keys: vec!["k".into()],
                    values: vec![],
                }
                .encode_to_vec(),
            ),
            (
                "values",
                PropertySet {
                    keys: vec![],
                    values: vec![PropertyValue::default()],
                }
                .encode_to_vec(),
            ),
        ],
    );
    check(
        "PropertySetList",
        vec![(
            "propertyset",
            PropertySetList {
                propertyset: vec![PropertySet::default()],
            }
            .encode_to_vec(),
        )],
    );
    let pv = PropertyValue::default;
    let v = |value| {
        PropertyValue {
            value: Some(value),
            ..pv()
        }
        .encode_to_vec()
    };
    use property_value::Value as P;
    check(
        "PropertyValue",
        vec![
            (
                "type",
                PropertyValue {
                    r#type: Some(1),
                    ..pv()
                }
                .encode_to_vec(),
            ),
            (
                "is_null",
                PropertyValue {
                    is_null: Some(true),
                    ..pv()
                }
                .encode_to_vec(),
            ),
            ("int_value", v(P::IntValue(1))),
            ("long_value", v(P::LongValue(1))),
            ("float_value", v(P::FloatValue(1.0))),
            ("double_value", v(P::DoubleValue(1.0))),
            ("boolean_value", v(P::BooleanValue(true))),
            ("string_value", v(P::StringValue("s".into()))),
            (
                "propertyset_value",
                v(P::PropertysetValue(PropertySet::default())),
            ),
            (
                "propertysets_value",
                v(P::PropertysetsValue(PropertySetList::default())),
            ),
            ("extension_value", v(P::ExtensionValue(vec![1]))),
        ],
    );
    let md = MetaData::default;
    check(
        "MetaData",
        vec![
            (
                "is_multi_part",
                MetaData {
                    is_multi_part: Some(true),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "content_type",
                MetaData {
                    content_type: Some("c".into()),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "size",
                MetaData {
                    size: Some(1),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "seq",
                MetaData {
                    seq: Some(1),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "file_name",
                MetaData {
                    file_name: Some("f".into()),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "file_type",
                MetaData {
                    file_type: Some("t".into()),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "md5",
                MetaData {
                    md5: Some("m".into()),
                    ..md()
                }
                .encode_to_vec(),
            ),
            (
                "description",
                MetaData {
                    description: Some("d".into()),
                    ..md()
                }
                .encode_to_vec(),
            ),
        ],
    );
}
