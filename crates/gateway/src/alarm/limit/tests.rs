use super::*;

fn t(ms: i64) -> Timestamp {
    Timestamp(1_800_000_000_000 + ms)
}

fn high(limit: f64, deadband: f64, on: u64, off: u64) -> Condition {
    Condition::new(
        Level::High,
        Limits {
            high: Some(limit),
            deadband,
            on_delay: Duration::from_secs(on),
            off_delay: Duration::from_secs(off),
            ..Limits::default()
        },
    )
}

#[test]
fn a_high_limit_without_delays_activates_above_it_and_clears_below_it_less_the_deadband() {
    let mut c = high(180.0, 2.0, 0, 0);
    assert_eq!(c.value(180.0, t(0)), None, "at the limit is not above it");
    assert_eq!(c.value(180.5, t(1000)), Some(true));
    assert_eq!(c.value(179.0, t(2000)), None, "within the deadband");
    assert_eq!(c.value(177.9, t(3000)), Some(false));
}

#[test]
fn the_on_delay_waits_for_the_condition_to_hold_and_fires_without_a_new_value() {
    let mut c = high(180.0, 0.0, 5, 0);
    assert_eq!(c.value(185.0, t(0)), None);
    assert_eq!(c.due(), Some(t(5000)));
    assert_eq!(c.tick(t(4999)), None);
    assert_eq!(c.tick(t(5000)), Some(true));
    assert_eq!(c.due(), None);
}

#[test]
fn a_spike_shorter_than_the_on_delay_raises_nothing() {
    let mut c = high(180.0, 0.0, 5, 0);
    c.value(185.0, t(0));
    assert_eq!(c.value(170.0, t(3000)), None);
    assert_eq!(c.tick(t(10_000)), None);
}

#[test]
fn the_off_delay_keeps_the_alarm_until_the_value_stayed_back_long_enough() {
    let mut c = high(180.0, 2.0, 0, 5);
    c.value(185.0, t(0));
    assert_eq!(c.value(170.0, t(1000)), None);
    assert_eq!(
        c.value(185.0, t(3000)),
        None,
        "back above: the clearing is off"
    );
    assert_eq!(c.value(170.0, t(4000)), None);
    assert_eq!(c.tick(t(8999)), None);
    assert_eq!(c.tick(t(9000)), Some(false));
}

#[test]
fn a_low_limit_mirrors_the_high() {
    let mut c = Condition::new(
        Level::Low,
        Limits {
            low: Some(10.0),
            deadband: 1.0,
            ..Limits::default()
        },
    );
    assert_eq!(c.value(9.0, t(0)), Some(true));
    assert_eq!(c.value(10.5, t(1000)), None);
    assert_eq!(c.value(11.5, t(2000)), Some(false));
}

#[test]
fn a_rate_of_change_alarm_compares_with_the_value_before() {
    let mut c = Condition::new(
        Level::RateOfChange,
        Limits {
            rate_of_change: Some(10.0),
            ..Limits::default()
        },
    );
    assert_eq!(c.value(100.0, t(0)), None);
    assert_eq!(c.value(105.0, t(1000)), None, "5 per second");
    assert_eq!(c.value(80.0, t(2000)), Some(true), "25 per second, falling");
    assert_eq!(c.value(82.0, t(3000)), Some(false));
}

#[test]
fn limits_that_cannot_hold_are_refused_with_why() {
    let limits = |low, high| Limits {
        low: Some(low),
        high: Some(high),
        ..Limits::default()
    };
    assert!(limits(10.0, 20.0).check().is_ok());
    let error = limits(30.0, 20.0).check().unwrap_err();
    assert!(error.contains("low 30 is not below high 20"), "{error}");
    let error = Limits {
        deadband: 6.0,
        ..limits(10.0, 20.0)
    }
    .check()
    .unwrap_err();
    assert!(error.contains("deadband 6 is too wide"), "{error}");
    let error = Limits::default().check().unwrap_err();
    assert!(error.contains("needs a limit"), "{error}");
    let error = Limits {
        high: Some(10.0),
        high_high: Some(5.0),
        ..Limits::default()
    }
    .check()
    .unwrap_err();
    assert!(
        error.contains("high 10 is not below high_high 5"),
        "{error}"
    );
    let error = Limits {
        high: Some(f64::NAN),
        ..Limits::default()
    }
    .check()
    .unwrap_err();
    assert!(error.contains("not a number"), "{error}");
}
