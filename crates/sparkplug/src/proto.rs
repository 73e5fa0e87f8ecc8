//! The Sparkplug B payload as protobuf messages, field for field as in
//! `proto/sparkplug_b.proto` (proto2: every scalar is optional, so "absent" and
//! "zero" stay apart). Hand-written `prost` derives: no build script, no `protoc`.
//!
//! These are the wire's loose shapes; [`crate::metric`] turns them into values that
//! cannot be invalid.

/// Most metrics one payload may carry. A metric can be 4 bytes on the wire (`12 02 10 01`:
/// an alias alone) and about 500 in memory once decoded, so a 20 MiB payload of such
/// metrics would take gigabytes and seconds to decode; a gateway's largest payloads (a
/// device's birth, a batch of 500 stored changes) hold far fewer.
pub const MAX_METRICS: usize = 100_000;

/// Why a payload was not decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PayloadError {
    /// The bytes are not a Sparkplug B protobuf payload.
    #[error("the payload is not a Sparkplug B payload: {0}")]
    Undecodable(#[from] prost::DecodeError),
    /// More than [`MAX_METRICS`] metrics: counted on the wire and not decoded.
    #[error("the payload carries more than {MAX_METRICS} metrics: not decoded")]
    TooManyMetrics,
}

/// Decodes a payload, after counting its metrics on the wire: one with more than
/// [`MAX_METRICS`] is refused before anything is built.
///
/// # Errors
///
/// [`PayloadError::TooManyMetrics`], or the protobuf decoder's error.
pub fn decode_payload(bytes: &[u8]) -> Result<Payload, PayloadError> {
    if count_metrics(bytes) > MAX_METRICS {
        return Err(PayloadError::TooManyMetrics);
    }
    Ok(<Payload as prost::Message>::decode(bytes)?)
}

/// The payload's metrics (its top-level fields 2), counted up to one past
/// [`MAX_METRICS`] without decoding them; bytes that are not protobuf stop the count
/// (the decoder then says what is wrong).
fn count_metrics(mut bytes: &[u8]) -> usize {
    use prost::encoding::{WireType, decode_key, decode_varint};
    let mut count = 0;
    while !bytes.is_empty() && count <= MAX_METRICS {
        let Ok((tag, wire_type)) = decode_key(&mut bytes) else {
            break;
        };
        let skip = match wire_type {
            WireType::Varint => match decode_varint(&mut bytes) {
                Ok(_) => 0,
                Err(_) => break,
            },
            WireType::SixtyFourBit => 8,
            WireType::ThirtyTwoBit => 4,
            WireType::LengthDelimited => match decode_varint(&mut bytes) {
                Ok(len) => usize::try_from(len).unwrap_or(usize::MAX),
                Err(_) => break,
            },
            WireType::StartGroup | WireType::EndGroup => break,
        };
        if skip > bytes.len() {
            break;
        }
        bytes = &bytes[skip..];
        if tag == 2 {
            count += 1;
        }
    }
    count
}

/// A whole Sparkplug B message body.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Payload {
    /// When the message was made: ms since the Unix epoch, UTC.
    #[prost(uint64, optional, tag = "1")]
    pub timestamp: Option<u64>,
    /// The metrics the message carries.
    #[prost(message, repeated, tag = "2")]
    pub metrics: Vec<Metric>,
    /// The edge node's message counter, 0–255 wrapping (absent on NDEATH and STATE).
    #[prost(uint64, optional, tag = "3")]
    pub seq: Option<u64>,
    /// An identifier for the payload's schema, rarely used.
    #[prost(string, optional, tag = "4")]
    pub uuid: Option<String>,
    /// Opaque bytes, rarely used.
    #[prost(bytes = "vec", optional, tag = "5")]
    pub body: Option<Vec<u8>>,
}

/// One metric: its identity (name and/or alias), type, flags and value.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Metric {
    /// The metric's name; births always carry it, data may use the alias alone.
    #[prost(string, optional, tag = "1")]
    pub name: Option<String>,
    /// The number that stands for the name after the birth.
    #[prost(uint64, optional, tag = "2")]
    pub alias: Option<u64>,
    /// When the value was taken: ms since the Unix epoch, UTC.
    #[prost(uint64, optional, tag = "3")]
    pub timestamp: Option<u64>,
    /// The data type code (see [`crate::DataType`]).
    #[prost(uint32, optional, tag = "4")]
    pub datatype: Option<u32>,
    /// Set on a value stored while the host was away and sent later.
    #[prost(bool, optional, tag = "5")]
    pub is_historical: Option<bool>,
    /// Set on a value the host should not store.
    #[prost(bool, optional, tag = "6")]
    pub is_transient: Option<bool>,
    /// Set when there is no value (then `value` is absent).
    #[prost(bool, optional, tag = "7")]
    pub is_null: Option<bool>,
    /// Describes file or multi-part contents.
    #[prost(message, optional, tag = "8")]
    pub metadata: Option<MetaData>,
    /// Named properties (unit, quality, …).
    #[prost(message, optional, tag = "9")]
    pub properties: Option<PropertySet>,
    /// The value, in the field its data type uses.
    #[prost(
        oneof = "metric::Value",
        tags = "10, 11, 12, 13, 14, 15, 16, 17, 18, 19"
    )]
    pub value: Option<metric::Value>,
}

/// The value fields of [`Metric`].
pub mod metric {
    /// One of a metric's value fields.
    #[derive(Clone, PartialEq, prost::Oneof)]
    pub enum Value {
        /// Int8/16/32 as two's complement bits, UInt8/16/32.
        #[prost(uint32, tag = "10")]
        IntValue(u32),
        /// Int64 as two's complement bits, UInt64, DateTime.
        #[prost(uint64, tag = "11")]
        LongValue(u64),
        /// Float.
        #[prost(float, tag = "12")]
        FloatValue(f32),
        /// Double.
        #[prost(double, tag = "13")]
        DoubleValue(f64),
        /// Boolean.
        #[prost(bool, tag = "14")]
        BooleanValue(bool),
        /// String, Text.
        #[prost(string, tag = "15")]
        StringValue(String),
        /// Bytes, File.
        #[prost(bytes = "vec", tag = "16")]
        BytesValue(Vec<u8>),
        /// A DataSet message, carried unread.
        #[prost(bytes = "vec", tag = "17")]
        DatasetValue(Vec<u8>),
        /// A Template message, carried unread.
        #[prost(bytes = "vec", tag = "18")]
        TemplateValue(Vec<u8>),
        /// An extension message, carried unread.
        #[prost(bytes = "vec", tag = "19")]
        ExtensionValue(Vec<u8>),
    }
}

/// Properties as two parallel lists: `keys[i]` names `values[i]`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertySet {
    /// The property names.
    #[prost(string, repeated, tag = "1")]
    pub keys: Vec<String>,
    /// The property values, in the order of `keys`.
    #[prost(message, repeated, tag = "2")]
    pub values: Vec<PropertyValue>,
}

/// A list of property sets.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertySetList {
    /// The sets.
    #[prost(message, repeated, tag = "1")]
    pub propertyset: Vec<PropertySet>,
}

/// One property's type and value.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PropertyValue {
    /// The data type code (see [`crate::DataType`]).
    #[prost(uint32, optional, tag = "1")]
    pub r#type: Option<u32>,
    /// Set when there is no value.
    #[prost(bool, optional, tag = "2")]
    pub is_null: Option<bool>,
    /// The value, in the field its type uses.
    #[prost(oneof = "property_value::Value", tags = "3, 4, 5, 6, 7, 8, 9, 10, 11")]
    pub value: Option<property_value::Value>,
}

/// The value fields of [`PropertyValue`].
pub mod property_value {
    /// One of a property's value fields.
    #[derive(Clone, PartialEq, prost::Oneof)]
    pub enum Value {
        /// Int8/16/32 as two's complement bits, UInt8/16/32.
        #[prost(uint32, tag = "3")]
        IntValue(u32),
        /// Int64 as two's complement bits, UInt64, DateTime.
        #[prost(uint64, tag = "4")]
        LongValue(u64),
        /// Float.
        #[prost(float, tag = "5")]
        FloatValue(f32),
        /// Double.
        #[prost(double, tag = "6")]
        DoubleValue(f64),
        /// Boolean.
        #[prost(bool, tag = "7")]
        BooleanValue(bool),
        /// String, Text.
        #[prost(string, tag = "8")]
        StringValue(String),
        /// A nested property set.
        #[prost(message, tag = "9")]
        PropertysetValue(super::PropertySet),
        /// A list of property sets.
        #[prost(message, tag = "10")]
        PropertysetsValue(super::PropertySetList),
        /// An extension message, carried unread.
        #[prost(bytes = "vec", tag = "11")]
        ExtensionValue(Vec<u8>),
    }
}

/// Describes file or multi-part metric contents.
#[derive(Clone, PartialEq, prost::Message)]
pub struct MetaData {
    /// The value is one part of several.
    #[prost(bool, optional, tag = "1")]
    pub is_multi_part: Option<bool>,
    /// A MIME type.
    #[prost(string, optional, tag = "2")]
    pub content_type: Option<String>,
    /// The whole size in bytes.
    #[prost(uint64, optional, tag = "3")]
    pub size: Option<u64>,
    /// The part's number.
    #[prost(uint64, optional, tag = "4")]
    pub seq: Option<u64>,
    /// A file name.
    #[prost(string, optional, tag = "5")]
    pub file_name: Option<String>,
    /// A file type.
    #[prost(string, optional, tag = "6")]
    pub file_type: Option<String>,
    /// An MD5 sum of the contents.
    #[prost(string, optional, tag = "7")]
    pub md5: Option<String>,
    /// Words about the contents.
    #[prost(string, optional, tag = "8")]
    pub description: Option<String>,
}

#[cfg(test)]
mod tests {
    use prost::Message as _;

    use super::*;

    #[test]
    fn a_payload_of_more_metrics_than_the_bound_is_refused_before_it_is_decoded() {
        // 08 01: timestamp 1; then metrics of one alias each, 4 bytes apiece.
        let tiny = |n: usize| {
            let mut bytes = vec![0x08, 0x01];
            for _ in 0..n {
                bytes.extend([0x12, 0x02, 0x10, 0x01]);
            }
            bytes
        };
        let at_the_bound = decode_payload(&tiny(MAX_METRICS)).expect("decoded");
        assert_eq!(at_the_bound.metrics.len(), MAX_METRICS);
        assert_eq!(
            decode_payload(&tiny(MAX_METRICS + 1)),
            Err(PayloadError::TooManyMetrics)
        );
        // Other fields and nested metrics do not count; garbage is the decoder's to name.
        let payload = Payload {
            timestamp: Some(5),
            metrics: vec![Metric::default(); 3],
            seq: Some(7),
            uuid: Some("u".into()),
            body: Some(vec![1; 300]),
        };
        assert_eq!(decode_payload(&payload.encode_to_vec()), Ok(payload));
        assert!(matches!(
            decode_payload(&[0xFF, 0xFF, 0xFF]),
            Err(PayloadError::Undecodable(_))
        ));
    }
}
