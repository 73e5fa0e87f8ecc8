use super::*;
use crate::point::PointDescription;

#[test]
#[cfg(target_pointer_width = "64")]
fn a_point_state_takes_64_bytes_one_is_kept_per_point() {
    assert_eq!(std::mem::size_of::<PointState>(), 64);
}

#[test]
fn a_point_state_records_numbers_only_and_a_nan_as_nothing_held_back() {
    let mut point = PointState::default();
    assert_eq!(point.recorded(), None);
    let mut record = |value: Option<Value>| {
        point.value = value;
        point.set_recorded();
        point.recorded()
    };
    assert_eq!(record(Some(Value::Number(20.5))), Some(20.5));
    assert_eq!(record(Some(Value::Text("JTSE".into()))), None);
    assert_eq!(
        record(Some(Value::Number(f64::NAN))),
        None,
        "a NaN is never held back"
    );
    assert_eq!(record(None), None);
    assert_eq!(
        point,
        PointState::default(),
        "no number recorded is equal to none"
    );
}

#[test]
fn every_point_is_found_by_its_name_and_no_other_name_is() {
    let device = DeviceId::new("dev1").unwrap();
    let names = ["zeta", "alpha", "mid_point", "alpha2", "b", "alpha-1"];
    let points: Vec<PointSpec> = names
        .iter()
        .map(|n| {
            PointSpec::new(
                PointId::new(&device, n).unwrap(),
                PointDescription {
                    name: (*n).into(),
                    unit: None,
                    kind: PointKind::Numeric,
                    group: "live".into(),
                    writable: None,
                    alarm: None,
                },
            )
        })
        .collect();
    let (writes, _queued) = mpsc::channel(1);
    let entry = DeviceEntry {
        id: device,
        name: "a device".into(),
        protocol: crate::driver::jbc::KIND,
        line: "line1".into(),
        address: None,
        deadbands: vec![None; points.len()],
        groups: Vec::new(),
        by_name: sorted_by_name(&points),
        state: RwLock::new(DeviceState::connecting(Timestamp(0), points.len())),
        points,
        writes,
    };
    for (i, name) in names.iter().enumerate() {
        assert_eq!(entry.point_index(name), Some(i), "{name}");
    }
    for name in ["", "alph", "alpha3", "zz", "dev1.zeta", "ZETA"] {
        assert_eq!(entry.point_index(name), None, "{name}");
    }
}

#[test]
fn good_values_turn_stale_after_three_periods_and_two_seconds() {
    let t = Some(Timestamp(10_000));
    let period = Duration::from_secs(1);
    assert_eq!(
        judge_staleness(Quality::Good, t, period, Timestamp(15_000)),
        Quality::Good
    );
    assert_eq!(
        judge_staleness(Quality::Good, t, period, Timestamp(15_001)),
        Quality::Stale
    );
    assert_eq!(
        judge_staleness(Quality::Bad, t, period, Timestamp(99_000)),
        Quality::Bad
    );
}
