//! A host application's STATE message.

use sparkplug::{HostState, Id, Qos, Timestamp};

#[test]
fn a_host_state_is_the_specs_json_on_a_retained_qos1_topic() {
    let state = HostState::new(true, Timestamp::from_millis(1_700_000_000_123));
    let publish = state.publish(Id::new("scada").unwrap());
    assert_eq!(publish.topic.to_string(), "spBv1.0/STATE/scada");
    assert_eq!((publish.qos, publish.retain), (Qos::AtLeastOnce, true));
    assert_eq!(
        publish.payload,
        br#"{"online":true,"timestamp":1700000000123}"#
    );
    assert_eq!(HostState::from_json(&publish.payload).unwrap(), state);
}

#[test]
fn a_state_payload_that_is_not_the_json_is_an_error() {
    assert!(HostState::from_json(b"ONLINE").is_err());
    assert!(HostState::from_json(br#"{"online":"yes","timestamp":1}"#).is_err());
    assert!(HostState::from_json(br#"{"timestamp":1}"#).is_err());
}
