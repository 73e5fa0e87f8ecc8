//! ISA-18.2's state table, transition by transition.

use super::*;

fn t(s: u64) -> Timestamp {
    Timestamp(1_800_000_000_000).plus(Duration::from_secs(s))
}

fn alarm() -> Alarm {
    Alarm::new(None)
}

#[test]
fn normal_becomes_unacknowledged_when_the_condition_activates() {
    let mut a = alarm();
    assert_eq!(a.condition(true, t(0)), [Change::Activated]);
    assert_eq!(a.state(), State::Unacknowledged);
    assert!(a.annunciated());
    assert_eq!(
        (a.first_active, a.last_active, a.count),
        (Some(t(0)), Some(t(0)), 1)
    );
}

#[test]
fn unacknowledged_becomes_acknowledged_when_the_operator_acknowledges() {
    let mut a = alarm();
    a.condition(true, t(0));
    assert_eq!(a.acknowledge(), Ok(Change::Acknowledged));
    assert_eq!(a.state(), State::Acknowledged);
    assert!(a.annunciated(), "an active alarm stays in the list");
}

#[test]
fn acknowledged_returns_to_normal_when_the_condition_clears() {
    let mut a = alarm();
    a.condition(true, t(0));
    a.acknowledge().unwrap();
    assert_eq!(a.condition(false, t(5)), [Change::Cleared]);
    assert_eq!(a.state(), State::Normal);
    assert!(!a.annunciated());
}

#[test]
fn unacknowledged_that_clears_waits_as_returned_unacknowledged_then_normal_when_acknowledged() {
    let mut a = alarm();
    a.condition(true, t(0));
    a.condition(false, t(5));
    assert_eq!(a.state(), State::ReturnedUnacknowledged);
    assert!(a.annunciated(), "still in the list until acknowledged");
    assert_eq!(a.acknowledge(), Ok(Change::Acknowledged));
    assert_eq!(a.state(), State::Normal);
}

#[test]
fn returned_unacknowledged_activating_again_is_unacknowledged_and_keeps_its_first_activation() {
    let mut a = alarm();
    a.condition(true, t(0));
    a.condition(false, t(5));
    a.condition(true, t(9));
    assert_eq!(a.state(), State::Unacknowledged);
    assert_eq!(a.first_active, Some(t(0)));
    assert_eq!(a.last_active, Some(t(9)));
    assert_eq!(a.count, 2);
}

#[test]
fn acknowledging_what_needs_no_acknowledgement_is_refused() {
    let mut a = alarm();
    assert_eq!(
        a.acknowledge(),
        Err(Refused::NothingToAcknowledge("normal"))
    );
    a.condition(true, t(0));
    a.acknowledge().unwrap();
    assert_eq!(
        a.acknowledge(),
        Err(Refused::NothingToAcknowledge("active, acknowledged"))
    );
}

#[test]
fn a_repeated_condition_changes_nothing() {
    let mut a = alarm();
    a.condition(true, t(0));
    assert!(a.condition(true, t(1)).is_empty());
    assert_eq!(a.count, 1);
}

#[test]
fn a_shelved_alarm_follows_its_condition_silently_and_expires_showing_it_as_it_is() {
    let mut a = alarm();
    a.condition(true, t(0));
    assert_eq!(a.shelve(Duration::from_secs(60), t(1)), Ok(Change::Shelved));
    assert!(!a.annunciated());
    assert_eq!(a.shelved_until(), Some(t(61)));
    // It clears and comes back while shelved: counted, not shown.
    a.condition(false, t(10));
    a.condition(true, t(20));
    assert!(!a.annunciated());
    assert_eq!(a.count, 2);
    assert_eq!(a.tick(t(60)), None);
    assert_eq!(a.tick(t(61)), Some(Change::ShelveExpired));
    assert_eq!(
        a.state(),
        State::Unacknowledged,
        "still active: annunciated again"
    );
    assert!(a.annunciated());
}

#[test]
fn an_alarm_that_returns_to_normal_while_shelved_is_normal_when_unshelved() {
    let mut a = alarm();
    a.condition(true, t(0));
    a.acknowledge().unwrap();
    a.shelve(Duration::from_secs(600), t(1)).unwrap();
    a.condition(false, t(2));
    assert_eq!(a.unshelve(), Ok(Change::Unshelved));
    assert_eq!(a.state(), State::Normal);
    assert_eq!(a.unshelve(), Err(Refused::NotShelved));
}

#[test]
fn a_shelving_must_last_from_a_second_to_a_week() {
    let mut a = alarm();
    assert!(matches!(
        a.shelve(Duration::from_millis(10), t(0)),
        Err(Refused::ShelveDuration { .. })
    ));
    let error = a.shelve(MAX_SHELVE * 2, t(0)).unwrap_err();
    assert!(error.to_string().contains("7days"), "{error}");
}

#[test]
fn an_alarm_out_of_service_is_silent_refuses_actions_and_shows_its_condition_when_back() {
    let mut a = alarm();
    assert_eq!(a.set_out_of_service(true), Some(Change::RemovedFromService));
    assert_eq!(a.set_out_of_service(true), None);
    a.condition(true, t(0));
    assert!(!a.annunciated());
    assert_eq!(a.acknowledge(), Err(Refused::OutOfService));
    assert_eq!(
        a.shelve(Duration::from_secs(60), t(0)),
        Err(Refused::OutOfService)
    );
    assert_eq!(a.set_out_of_service(false), Some(Change::ReturnedToService));
    assert_eq!(a.state(), State::Unacknowledged);
}

#[test]
fn a_chattering_alarm_is_counted_and_shelved_on_its_own_when_the_rule_says_so() {
    let rule = ChatterRule {
        activations: 3,
        window: Duration::from_secs(60),
        shelve: Some(Duration::from_secs(600)),
    };
    let mut a = Alarm::new(Some(rule));
    for s in [0, 10, 20] {
        a.condition(true, t(s));
        a.condition(false, t(s + 1));
    }
    assert_eq!(a.chattered, 0, "three in a minute are allowed");
    assert_eq!(
        a.condition(true, t(30)),
        [Change::Activated, Change::ShelvedForChattering]
    );
    assert_eq!(a.chattered, 1);
    assert_eq!(a.shelved_until(), Some(t(630)));
    // Activations an hour apart do not chatter.
    let mut slow = Alarm::new(Some(rule));
    for s in [0, 3600, 7200, 10800, 14400] {
        slow.condition(true, t(s));
        slow.condition(false, t(s + 1));
    }
    assert_eq!(slow.chattered, 0);
}

#[test]
fn states_are_named_as_serde_names_them_in_the_api() {
    for state in [
        State::Normal,
        State::Unacknowledged,
        State::Acknowledged,
        State::ReturnedUnacknowledged,
    ] {
        assert_eq!(serde_json::json!(state), state.as_str());
    }
}
