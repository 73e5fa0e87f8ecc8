//! Topics: text round trips and the refusals, each naming what is wrong.

use sparkplug::{Id, IdError, MessageKind, Topic, TopicError};

fn id(s: &str) -> Id {
    Id::new(s).expect("test ids are valid")
}

#[test]
fn node_and_device_topics_round_trip_through_text() {
    for text in [
        "spBv1.0/cell/NBIRTH/gw1",
        "spBv1.0/cell/NDATA/gw1",
        "spBv1.0/cell/NDEATH/gw1",
        "spBv1.0/cell/NCMD/gw1",
        "spBv1.0/cell/DBIRTH/gw1/jbc",
        "spBv1.0/cell/DDATA/gw1/jbc",
        "spBv1.0/cell/DDEATH/gw1/jbc",
        "spBv1.0/cell/DCMD/gw1/jbc",
        "spBv1.0/STATE/scada",
    ] {
        let topic: Topic = text.parse().expect("a valid topic");
        assert_eq!(topic.to_string(), text);
    }
}

#[test]
fn a_device_data_topic_parses_into_its_parts() {
    let topic: Topic = "spBv1.0/cell/DDATA/gw1/cross".parse().unwrap();
    assert_eq!(
        topic,
        Topic::Device {
            group: id("cell"),
            kind: MessageKind::Data,
            edge_node: id("gw1"),
            device: id("cross"),
        }
    );
    assert_eq!(topic.message_type(), "DDATA");
}

#[test]
fn a_state_topic_names_its_host() {
    let topic: Topic = "spBv1.0/STATE/scada-1".parse().unwrap();
    assert_eq!(
        topic,
        Topic::State {
            host: id("scada-1")
        }
    );
}

#[test]
fn a_device_id_with_a_slash_is_refused() {
    assert_eq!(
        Id::new("jbc/1"),
        Err(IdError::Forbidden {
            id: "jbc/1".into(),
            character: '/'
        })
    );
    // In a topic, the slash makes one level too many.
    assert_eq!(
        "spBv1.0/cell/DDATA/gw1/jbc/1".parse::<Topic>(),
        Err(TopicError::Levels {
            message_type: "DDATA".into(),
            expected: 5,
            found: 6
        })
    );
}

#[test]
fn ids_with_mqtt_wildcards_are_refused() {
    assert!(matches!(
        Id::new("a+b"),
        Err(IdError::Forbidden { character: '+', .. })
    ));
    assert!(matches!(
        Id::new("#"),
        Err(IdError::Forbidden { character: '#', .. })
    ));
    assert_eq!(
        "spBv1.0/cell/DDATA/gw1/+".parse::<Topic>(),
        Err(TopicError::Id {
            level: "device id",
            error: IdError::Forbidden {
                id: "+".into(),
                character: '+'
            }
        })
    );
}

#[test]
fn an_empty_group_id_is_refused_naming_the_level() {
    assert_eq!(
        "spBv1.0//NDATA/gw1".parse::<Topic>(),
        Err(TopicError::Id {
            level: "group id",
            error: IdError::Empty
        })
    );
}

#[test]
fn a_node_message_with_a_device_level_is_refused() {
    assert_eq!(
        "spBv1.0/cell/NDATA/gw1/jbc".parse::<Topic>(),
        Err(TopicError::Levels {
            message_type: "NDATA".into(),
            expected: 4,
            found: 5
        })
    );
}

#[test]
fn a_device_message_without_a_device_is_refused() {
    assert_eq!(
        "spBv1.0/cell/DBIRTH/gw1".parse::<Topic>(),
        Err(TopicError::Levels {
            message_type: "DBIRTH".into(),
            expected: 5,
            found: 4
        })
    );
}

#[test]
fn an_unknown_message_type_is_named_in_the_error() {
    let err = "spBv1.0/cell/NREBIRTH/gw1".parse::<Topic>().unwrap_err();
    assert_eq!(
        err,
        TopicError::MessageType {
            found: "NREBIRTH".into()
        }
    );
    assert!(err.to_string().contains("NREBIRTH"));
}

#[test]
fn another_namespace_is_refused() {
    assert_eq!(
        "spAv1.0/cell/NDATA/gw1".parse::<Topic>(),
        Err(TopicError::Namespace {
            found: "spAv1.0".into()
        })
    );
    assert!("".parse::<Topic>().is_err());
    assert!("spBv1.0".parse::<Topic>().is_err());
    assert!("spBv1.0/STATE".parse::<Topic>().is_err());
}

#[test]
fn an_id_of_256_bytes_is_taken_and_a_longer_one_is_refused_without_being_repeated() {
    assert!(Id::new("é".repeat(128)).is_ok(), "256 bytes");
    let long = "n".repeat(60_000);
    let error = Id::new(&long).unwrap_err();
    assert!(matches!(error, IdError::TooLong { bytes: 60_000, .. }));
    let words = error.to_string();
    assert!(
        words.len() < 200 && words.contains("60000 bytes") && words.contains("at most 256"),
        "{words}"
    );
}

#[test]
fn ids_and_metric_names_with_control_or_bidirectional_formatting_characters_are_refused() {
    for bad in [
        "jbc\u{0}1",
        "jbc\t1",
        "jbc\u{7f}",
        "jbc\u{85}",
        "a\u{200e}",
        "a\u{200f}",
        "a\u{061c}",
        "a\u{202a}",
        "temp\u{202e}lio",
        "a\u{2066}",
        "a\u{2069}",
    ] {
        let character = bad.chars().find(|c| !c.is_ascii_alphanumeric()).unwrap();
        assert_eq!(
            Id::new(bad),
            Err(IdError::Misleading {
                id: bad.into(),
                character
            }),
            "{bad:?}"
        );
        assert_eq!(
            sparkplug::MetricName::new(bad),
            Err(sparkplug::NameError::Misleading {
                name: bad.into(),
                character
            }),
            "{bad:?}"
        );
    }
    // What users write is still taken: folders, spaces, accents, other scripts.
    for good in ["Node Control/Rebirth", "température four 2", "温度", "درجة"] {
        assert!(sparkplug::MetricName::new(good).is_ok(), "{good}");
    }
    let words = Id::new("temp\u{202e}lio").unwrap_err().to_string();
    assert!(
        words.contains(r"\u{202e}") && !words.contains('\u{202e}'),
        "the error shows the character escaped: {words}"
    );
    assert!(matches!(
        sparkplug::MetricName::new("x".repeat(257)),
        Err(sparkplug::NameError::TooLong { bytes: 257, .. })
    ));
}
