use super::*;

fn device() -> DeviceId {
    DeviceId::new("jbc1").unwrap()
}

fn setpoint() -> PointSpec {
    PointSpec::new(
        PointId::new(&device(), "air_temperature_setpoint").unwrap(),
        PointDescription {
            name: "Selected air temperature".into(),
            unit: Some("°C".into()),
            kind: PointKind::Numeric,
            group: "live".into(),
            writable: Some(WriteRange {
                min: 150.0,
                max: 450.0,
                integer: true,
                step: None,
            }),
            alarm: None,
        },
    )
}

fn tool_on() -> PointSpec {
    PointSpec::new(
        PointId::new(&device(), "tool_on").unwrap(),
        PointDescription {
            name: "Tool on".into(),
            unit: None,
            kind: PointKind::Enum {
                states: vec![
                    EnumState {
                        value: 0,
                        label: "off".into(),
                    },
                    EnumState {
                        value: 1,
                        label: "on".into(),
                    },
                ],
            },
            group: "live".into(),
            writable: Some(WriteRange {
                min: 0.0,
                max: 1.0,
                integer: true,
                step: None,
            }),
            alarm: None,
        },
    )
}

#[test]
fn device_ids_follow_the_plain_name_rule() {
    assert!(DeviceId::new("jbc1").is_ok());
    assert!(DeviceId::new("sealer-0_a").is_ok());
    for bad in ["", "JBC1", "jbc 1", "-x", "a.b", &"x".repeat(65)] {
        let err = DeviceId::new(bad).unwrap_err();
        assert_eq!(err.text, bad);
    }
}

#[test]
fn point_ids_split_into_device_and_point() {
    let id = PointId::parse("jbc1.air_temperature").unwrap();
    assert_eq!(id.device(), "jbc1");
    assert_eq!(id.name(), "air_temperature");
    assert!(PointId::parse("jbc1").is_err());
    assert!(PointId::parse("jbc1.").is_err());
    assert!(PointId::parse(".x").is_err());
}

#[test]
fn writes_inside_the_range_pass_and_outside_are_refused_with_the_facts() {
    let spec = setpoint();
    assert_eq!(
        spec.check_write(&Value::Number(350.0))
            .map(Checked::into_value),
        Ok(Value::Number(350.0))
    );
    assert_eq!(
        spec.check_write(&Value::Text("400".into()))
            .map(Checked::into_value),
        Ok(Value::Number(400.0))
    );
    let err = spec.check_write(&Value::Number(900.0)).unwrap_err();
    assert_eq!(
        err.to_string(),
        "900 is out of range for jbc1.air_temperature_setpoint (Selected air temperature): 150 to 450 °C"
    );
    assert!(matches!(
        spec.check_write(&Value::Number(300.5)),
        Err(ValueError::NotWhole { .. })
    ));
    assert!(matches!(
        spec.check_write(&Value::Number(f64::NAN)),
        Err(ValueError::OutOfRange { .. })
    ));
    assert!(matches!(
        spec.check_write(&Value::Text("hot".into())),
        Err(ValueError::WrongType { .. })
    ));
}

#[test]
fn values_between_the_devices_steps_are_refused() {
    let mut spec = setpoint();
    Arc::make_mut(&mut spec.description).writable = Some(WriteRange {
        min: 0.0,
        max: 99.9,
        integer: false,
        step: Some(0.1),
    });
    assert_eq!(
        spec.check_write(&Value::Number(12.3))
            .map(Checked::into_value),
        Ok(Value::Number(12.3))
    );
    let err = spec.check_write(&Value::Number(12.34)).unwrap_err();
    assert!(matches!(err, ValueError::NotAStep { step, .. } if step == 0.1));
    assert!(
        err.to_string().contains("not a multiple of 0.1 °C"),
        "{err}"
    );
}

#[test]
fn enumerations_accept_labels_and_numbers_and_list_their_states_when_refusing() {
    let spec = tool_on();
    assert_eq!(
        spec.check_write(&Value::Text("ON".into()))
            .map(Checked::into_value),
        Ok(Value::Number(1.0))
    );
    assert_eq!(
        spec.check_write(&Value::Number(0.0))
            .map(Checked::into_value),
        Ok(Value::Number(0.0))
    );
    let err = spec.check_write(&Value::Number(2.0)).unwrap_err();
    assert!(err.to_string().contains("0 (off), 1 (on)"), "{err}");
    assert_eq!(spec.label(&Value::Number(1.0)), Some("on"));
}

#[test]
fn read_only_points_refuse_every_write() {
    let mut spec = setpoint();
    Arc::make_mut(&mut spec.description).writable = None;
    assert!(matches!(
        spec.check_write(&Value::Number(300.0)),
        Err(ValueError::ReadOnly { .. })
    ));
}

#[test]
fn a_deadband_lets_through_moves_at_least_as_big_as_its_band() {
    assert!(!Deadband::Absolute(0.5).passes(230.0, 230.4));
    assert!(Deadband::Absolute(0.5).passes(230.0, 229.5));
    assert!(!Deadband::Percent(1.0).passes(200.0, 201.9));
    assert!(Deadband::Percent(1.0).passes(-200.0, -202.0));
    assert!(Deadband::Percent(1.0).passes(0.0, 0.001));
}

#[test]
fn alarm_rules_judge_numbers_and_text_by_their_kind() {
    assert!(AlarmRule::NotEqual(0.0).is_alarm(&Value::Number(3.0)));
    assert!(!AlarmRule::NotEqual(0.0).is_alarm(&Value::Number(0.0)));
    assert!(AlarmRule::Above(400.0).is_alarm(&Value::Number(401.0)));
    assert!(AlarmRule::Below(10.0).is_alarm(&Value::Number(9.0)));
    assert!(!AlarmRule::Above(1.0).is_alarm(&Value::Text("x".into())));
    assert!(AlarmRule::NotText("none").is_alarm(&Value::Text("S1 failure".into())));
    assert!(!AlarmRule::NotText("none").is_alarm(&Value::Text("none".into())));
    assert!(!AlarmRule::NotText("none").is_alarm(&Value::Number(1.0)));
}
