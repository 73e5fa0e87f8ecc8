use std::time::Duration;

use super::*;
use crate::alarm::limit::Limits;
use crate::point::{AlarmRule, PointDescription, PointKind, Words};

fn t(ms: i64) -> Timestamp {
    Timestamp(1_800_000_000_000 + ms)
}

fn point(id: &str) -> PointId {
    PointId::parse(id).unwrap()
}

fn alarm_on(id: &str, limits: Limits) -> AlarmConfig {
    AlarmConfig {
        point: point(id),
        limits,
        priority: Priority::High,
        message: Some("Band too hot".into()),
        category: None,
        chatter: None,
    }
}

fn sealer_high() -> AlarmConfig {
    alarm_on(
        "sealer0.temperature",
        Limits {
            high: Some(180.0),
            deadband: 2.0,
            on_delay: Duration::from_secs(5),
            off_delay: Duration::from_secs(5),
            ..Limits::default()
        },
    )
}

/// A sealer with a fault point (0 = none) and a temperature.
fn sealer() -> DeviceAlarms {
    let fault = PointSpec::new(
        point("sealer0.fault"),
        std::sync::Arc::new(PointDescription {
            name: Words::from("Fault"),
            unit: None,
            kind: PointKind::Numeric,
            group: Words::from("live"),
            writable: None,
            alarm: Some(AlarmRule::NotEqual(0.0)),
        }),
    );
    DeviceAlarms {
        device: DeviceId::new("sealer0").unwrap(),
        label: "Sealer 0".into(),
        rule_points: vec![fault],
    }
}

fn n(v: f64) -> Value {
    Value::Number(v)
}

fn changes(happened: &[Happened]) -> Vec<(String, Vec<Change>)> {
    happened
        .iter()
        .map(|h| (h.index.to_string(), h.changes.clone()))
        .collect()
}

#[test]
fn a_sealers_temperature_alarm_fires_after_its_on_delay_and_clears_past_its_deadband_after_its_off_delay()
 {
    let mut book = Book::new(&[sealer_high()], &[sealer()]);
    let temperature = point("sealer0.temperature");
    assert!(
        book.value(&temperature, Some(&n(185.0)), t(0)).is_empty(),
        "the on delay runs"
    );
    assert!(book.tick(t(4_999)).is_empty());
    let [raised] = book.tick(t(5_000)).try_into().unwrap();
    let alarm = book.view(raised.index).unwrap();
    assert_eq!(alarm.id, "sealer0.temperature:high");
    assert_eq!(raised.changes, [Change::Activated]);
    assert_eq!(
        (alarm.value, alarm.limit, alarm.state),
        (
            Some(serde_json::json!(185.0)),
            Some(180.0),
            State::Unacknowledged
        )
    );
    assert!(
        book.value(&temperature, Some(&n(179.0)), t(6_000))
            .is_empty(),
        "inside the deadband"
    );
    assert!(book.tick(t(20_000)).is_empty());
    assert!(
        book.value(&temperature, Some(&n(170.0)), t(21_000))
            .is_empty(),
        "the off delay runs"
    );
    let [cleared] = book.tick(t(26_000)).try_into().unwrap();
    assert_eq!(cleared.changes, [Change::Cleared]);
    let alarm = book.view(cleared.index).unwrap();
    assert_eq!(alarm.state, State::ReturnedUnacknowledged);
    assert_eq!(
        book.instance(cleared.index).unwrap().last_value,
        Some(serde_json::json!(170.0))
    );
}

#[test]
fn each_level_of_a_point_is_its_own_alarm_and_other_points_are_not_watched() {
    let config = alarm_on(
        "meter1.active_power",
        Limits {
            high: Some(180.0),
            high_high: Some(200.0),
            ..Limits::default()
        },
    );
    let mut book = Book::new(&[config], &[]);
    let raised = book.value(&point("meter1.active_power"), Some(&n(210.0)), t(0));
    let ids: Vec<String> = raised
        .iter()
        .map(|h| book.view(h.index).unwrap().id)
        .collect();
    assert_eq!(
        ids,
        ["meter1.active_power:high_high", "meter1.active_power:high"]
    );
    let other = point("meter1.voltage");
    assert!(!book.watches(&other));
    assert!(book.value(&other, Some(&n(1e9)), t(0)).is_empty());
}

#[test]
fn a_point_that_loses_its_value_holds_its_alarm_as_it_was() {
    let config = alarm_on(
        "meter1.active_power",
        Limits {
            high: Some(180.0),
            ..Limits::default()
        },
    );
    let mut book = Book::new(&[config], &[]);
    let power = point("meter1.active_power");
    assert_eq!(book.value(&power, Some(&n(190.0)), t(0)).len(), 1);
    assert!(book.value(&power, None, t(1_000)).is_empty());
    assert!(book.tick(t(60_000)).is_empty());
    assert_eq!(book.value(&power, Some(&n(100.0)), t(61_000)).len(), 1);
}

#[test]
fn a_devices_fault_and_its_silence_are_alarms_of_the_same_model_with_their_own_ids() {
    let mut book = Book::new(&[], &[sealer()]);
    let fault = point("sealer0.fault");
    assert!(book.value(&fault, Some(&n(0.0)), t(0)).is_empty());
    let [raised] = book
        .value(&fault, Some(&n(7.0)), t(1_000))
        .try_into()
        .unwrap();
    let alarm = book.view(raised.index).unwrap();
    assert_eq!(
        (alarm.id.as_str(), alarm.source, alarm.priority),
        ("sealer0.fault", Source::Device, Priority::High)
    );
    assert_eq!(alarm.value, Some(serde_json::json!(7.0)));
    // No value (the device stopped answering): the fault holds; the silence is its own.
    assert!(book.value(&fault, None, t(2_000)).is_empty());
    let device = DeviceId::new("sealer0").unwrap();
    let down = book
        .down(&device, true, Some("no reply"), t(2_000))
        .unwrap();
    let alarm = book.view(down.index).unwrap();
    assert_eq!(
        (alarm.id.as_str(), alarm.source),
        ("sealer0:down", Source::Down)
    );
    assert_eq!(alarm.value, Some(serde_json::json!("no reply")));
    assert!(
        book.down(&device, true, None, t(3_000)).is_none(),
        "still down"
    );
    let up = book.down(&device, false, None, t(4_000)).unwrap();
    assert_eq!(up.changes, [Change::Cleared]);
    assert_eq!(
        book.list(&all()).total,
        2,
        "both wait for an acknowledgement"
    );
}

fn all() -> ListFilter {
    ListFilter {
        limit: 100,
        ..ListFilter::default()
    }
}

#[test]
fn an_operator_acknowledges_shelves_and_unshelves_and_what_does_not_apply_is_refused_with_why() {
    let mut book = Book::new(&[], &[sealer()]);
    let fault = point("sealer0.fault");
    book.value(&fault, Some(&n(3.0)), t(0));
    assert_eq!(
        book.act("sealer9.fault", Action::Acknowledge, t(1), "anna", None),
        Err(ActError::Unknown {
            id: "sealer9.fault".into()
        })
    );
    let acked = book
        .act(
            "sealer0.fault",
            Action::Acknowledge,
            t(1_000),
            "anna",
            Some("band replaced"),
        )
        .unwrap();
    assert_eq!(acked.changes, [Change::Acknowledged]);
    assert_eq!(
        (acked.by.as_deref(), acked.comment.as_deref()),
        (Some("anna"), Some("band replaced"))
    );
    let again = book
        .act("sealer0.fault", Action::Acknowledge, t(2_000), "bob", None)
        .unwrap_err();
    assert!(
        again
            .to_string()
            .contains("already acknowledged (it is active, acknowledged)"),
        "{again}"
    );
    let shelved = book
        .act(
            "sealer0.fault",
            Action::Shelve(Duration::from_secs(60)),
            t(3_000),
            "anna",
            None,
        )
        .unwrap();
    assert_eq!(shelved.changes, [Change::Shelved]);
    assert_eq!(
        book.view(shelved.index).unwrap().shelved_until,
        Some(t(63_000))
    );
    let too_long = book
        .act(
            "sealer0.fault",
            Action::Shelve(Duration::from_secs(8 * 86_400)),
            t(4_000),
            "anna",
            None,
        )
        .unwrap_err();
    assert!(too_long.to_string().contains("7days"), "{too_long}");
    // The shelving runs out: still active, annunciated again.
    let [expired] = book.tick(t(63_000)).try_into().unwrap();
    assert_eq!(expired.changes, [Change::ShelveExpired]);
    assert_eq!(
        book.view(expired.index).unwrap().state,
        State::Unacknowledged
    );
    assert!(matches!(
        book.act("sealer0.fault", Action::Unshelve, t(64_000), "anna", None),
        Err(ActError::Refused {
            refused: Refused::NotShelved,
            ..
        })
    ));
}

#[test]
fn the_list_shows_what_needs_attention_most_urgent_then_newest_first_in_pages() {
    let low = AlarmConfig {
        priority: Priority::Low,
        ..alarm_on(
            "meter1.voltage",
            Limits {
                low: Some(200.0),
                ..Limits::default()
            },
        )
    };
    let mut book = Book::new(&[low, sealer_high()], &[sealer()]);
    book.value(&point("meter1.voltage"), Some(&n(190.0)), t(0));
    book.value(&point("sealer0.fault"), Some(&n(1.0)), t(1_000));
    book.value(&point("sealer0.temperature"), Some(&n(200.0)), t(2_000));
    book.tick(t(7_000));
    let ids = |page: Page| page.alarms.into_iter().map(|a| a.id).collect::<Vec<_>>();
    assert_eq!(
        ids(book.list(&all())),
        [
            "sealer0.temperature:high",
            "sealer0.fault",
            "meter1.voltage:low"
        ]
    );
    let page = book.list(&ListFilter {
        offset: 1,
        limit: 1,
        ..ListFilter::default()
    });
    assert_eq!(page.total, 3);
    assert_eq!(ids(page), ["sealer0.fault"]);
    let low_only = book.list(&ListFilter {
        priority: Some(Priority::Low),
        ..all()
    });
    assert_eq!(ids(low_only), ["meter1.voltage:low"]);
    let counts = book.counts();
    assert_eq!(
        counts
            .iter()
            .map(|c| (c.priority, c.active, c.unacknowledged))
            .collect::<Vec<_>>(),
        [
            (Priority::Low, 1, 1),
            (Priority::Medium, 0, 0),
            (Priority::High, 2, 2),
            (Priority::Urgent, 0, 0)
        ]
    );
    // Acknowledged and returned to normal: off the list.
    book.act("sealer0.fault", Action::Acknowledge, t(8_000), "anna", None)
        .unwrap();
    book.value(&point("sealer0.fault"), Some(&n(0.0)), t(9_000));
    assert_eq!(book.list(&all()).total, 2);
}

#[test]
fn an_alarm_is_put_back_as_its_last_journal_entry_saved_it() {
    let mut book = Book::new(&[sealer_high()], &[sealer()]);
    let entry = serde_json::json!({
        "alarm": "sealer0.temperature:high",
        "state": "returned_unacknowledged",
        "active": false,
        "shelved_until": "2027-01-15T08:00:00.000Z",
        "first_active": "2027-01-15T07:00:00.000Z",
        "last_active": "2027-01-15T07:30:00.000Z",
        "value": 191.5,
        "count": 4,
        "chattered": 1,
    });
    assert!(book.restore("sealer0.temperature:high", &entry, t(0)));
    assert!(
        !book.restore("sealer0.pressure:high", &entry, t(0)),
        "not in the config"
    );
    assert!(
        !book.restore("sealer0.fault", &serde_json::json!({"state": 3}), t(0)),
        "not an entry"
    );
    let alarm = book
        .view(book.index_of("sealer0.temperature:high").unwrap())
        .unwrap();
    assert_eq!(alarm.state, State::ReturnedUnacknowledged);
    assert_eq!(alarm.count, 4);
    assert_eq!(alarm.value, Some(serde_json::json!(191.5)));
    assert_eq!(
        alarm.shelved_until.map(|t| t.to_string()).as_deref(),
        Some("2027-01-15T08:00:00.000Z")
    );
    assert_eq!(book.list(&all()).total, 1);
}

#[test]
fn a_chattering_alarm_is_shelved_on_its_own_when_its_rule_says_so() {
    let config = AlarmConfig {
        chatter: Some(crate::alarm::state::ChatterRule {
            activations: 2,
            window: Duration::from_secs(60),
            shelve: Some(Duration::from_secs(600)),
        }),
        ..alarm_on(
            "meter1.active_power",
            Limits {
                high: Some(180.0),
                ..Limits::default()
            },
        )
    };
    let mut book = Book::new(&[config], &[]);
    let power = point("meter1.active_power");
    let mut seen = Vec::new();
    for (i, v) in [190.0, 100.0, 190.0, 100.0, 190.0].into_iter().enumerate() {
        seen.extend(book.value(&power, Some(&n(v)), t(i as i64 * 1_000)));
    }
    assert_eq!(
        changes(&seen).last().unwrap().1,
        [Change::Activated, Change::ShelvedForChattering]
    );
    let alarm = book.view(0).unwrap();
    assert_eq!(alarm.shelved_until, Some(t(4_000 + 600_000)));
    assert_eq!(alarm.chattered, 1);
}

#[test]
fn an_alarm_taken_out_of_service_refuses_acknowledgement_until_it_returns_as_its_condition_is() {
    let mut book = Book::new(&[], &[sealer()]);
    book.value(&point("sealer0.fault"), Some(&n(4.0)), t(0));
    let out = book
        .act(
            "sealer0.fault",
            Action::OutOfService(true),
            t(1_000),
            "maintenance",
            Some("band swap"),
        )
        .unwrap();
    assert_eq!(out.changes, [Change::RemovedFromService]);
    let alarm = book.view(out.index).unwrap();
    assert!(alarm.out_of_service);
    assert_eq!(book.list(&all()).total, 1, "listed, to be returned");
    assert!(matches!(
        book.act("sealer0.fault", Action::Acknowledge, t(2_000), "anna", None),
        Err(ActError::Refused {
            refused: Refused::OutOfService,
            ..
        })
    ));
    // Repaired meanwhile: back in service, normal.
    book.value(&point("sealer0.fault"), Some(&n(0.0)), t(3_000));
    let back = book
        .act(
            "sealer0.fault",
            Action::OutOfService(false),
            t(4_000),
            "maintenance",
            None,
        )
        .unwrap();
    assert_eq!(back.changes, [Change::ReturnedToService]);
    assert_eq!(book.view(back.index).unwrap().state, State::Normal);
    assert!(matches!(
        book.act(
            "sealer0.fault",
            Action::OutOfService(false),
            t(5_000),
            "anna",
            None
        ),
        Err(ActError::Refused {
            refused: Refused::InService,
            ..
        })
    ));
}
