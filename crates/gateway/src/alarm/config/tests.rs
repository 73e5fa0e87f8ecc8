use std::time::Duration;

use super::*;
use crate::testing::config::{ONE, parse, refused};

/// `ONE` (a JBC station, `jbc1`, on line 2–8) and an `[[alarm]]` from line 10.
fn with_alarm(body: &str) -> String {
    format!("{ONE}\n[[alarm]]\n{body}\n")
}

#[test]
fn a_limit_alarm_on_a_stations_temperature_is_read_with_its_delays_priority_and_chatter() {
    let config = parse(&with_alarm(
        "point = \"jbc1.air_temperature\"\nhigh = 450.0\nhigh_high = 480.0\ndeadband = 5.0\n\
         on_delay = \"5s\"\noff_delay = \"2s\"\npriority = \"urgent\"\n\
         message = \"Air too hot\"\ncategory = \"process\"\n\
         chatter = { activations = 5, window = \"10m\", shelve = \"30m\" }",
    ))
    .unwrap();
    let [alarm] = config.alarms.as_slice() else {
        panic!("{:?}", config.alarms)
    };
    assert_eq!(alarm.point.as_str(), "jbc1.air_temperature");
    assert_eq!(alarm.limits.high, Some(450.0));
    assert_eq!(alarm.limits.high_high, Some(480.0));
    assert_eq!(alarm.limits.on_delay, Duration::from_secs(5));
    assert_eq!(alarm.priority, Priority::Urgent);
    assert_eq!(alarm.message.as_deref(), Some("Air too hot"));
    let chatter = alarm.chatter.unwrap();
    assert_eq!(chatter.activations, 5);
    assert_eq!(chatter.shelve, Some(Duration::from_secs(1800)));
    let two = parse(&with_alarm(
        "point = \"jbc1.air_temperature\"\nlow = 20.0\npriority = 2",
    ))
    .unwrap();
    assert_eq!(two.alarms[0].priority, Priority::Medium);
}

#[test]
fn alarms_that_cannot_be_true_or_name_what_is_not_there_are_refused_where_they_are() {
    refused(
        &with_alarm("point = \"jbc1.air_temperature\"\nlow = 500.0\nhigh = 450.0"),
        11,
        9,
        "low 500 is not below high 450: the alarm could never be right",
    );
    refused(
        &with_alarm("point = \"jbc9.air_temperature\"\nhigh = 450.0"),
        11,
        9,
        "the cell has no device \"jbc9\"",
    );
    refused(
        &with_alarm("point = \"jbc1.air_temp\"\nhigh = 450.0"),
        11,
        9,
        "device jbc1 has no point \"air_temp\"; its numeric points include air_temperature",
    );
    refused(
        &with_alarm("point = \"jbc1.tool_error\"\nhigh = 1.0"),
        11,
        9,
        "jbc1.tool_error is not a number (an enumeration)",
    );
    refused(
        &with_alarm("point = \"jbc1.air_temperature\""),
        11,
        9,
        "an alarm needs a limit",
    );
    refused(
        &with_alarm("point = \"jbc1.air_temperature\"\nhigh = 450.0\npriority = \"critical\""),
        13,
        12,
        "priority is low, medium, high or urgent",
    );
    refused(
        &with_alarm("point = \"jbc1.air_temperature\"\nhigh = 450.0\non_delay = \"soon\""),
        13,
        12,
        "on_delay \"soon\" is not a duration",
    );
    refused(
        &with_alarm("point = \"jbc1.air_temperature\"\nhigh = 450.0\nlimit = 3.0"),
        13,
        1,
        "unknown field `limit`",
    );
}
