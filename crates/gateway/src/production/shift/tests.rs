use super::*;

fn utc(text: &str) -> Timestamp {
    let t: jiff::Timestamp = text.parse().unwrap();
    Timestamp(t.as_millisecond())
}

fn hm(text: &str) -> Time {
    clock(text).unwrap()
}

fn night() -> Shift {
    Shift {
        name: "night".into(),
        days: EVERY_DAY.to_vec(),
        start: hm("22:00"),
        end: hm("06:00"),
        breaks: vec![(hm("02:00"), hm("02:30"))],
    }
}

#[test]
fn without_shifts_the_cell_plans_every_hour_of_every_day() {
    let shifts = Shifts::new(Some("UTC"), Vec::new()).unwrap();
    let planned = shifts.planned(utc("2026-11-02T05:00:00Z"), utc("2026-11-03T07:00:00Z"));
    assert_eq!(planned.millis(), 26 * 3600 * 1000);
    let now = shifts.at(utc("2026-11-02T13:00:00Z")).unwrap();
    assert_eq!(now.name, "day");
    assert_eq!(now.start, utc("2026-11-02T00:00:00Z"));
    assert_eq!(now.end, utc("2026-11-03T00:00:00Z"));
}

#[test]
fn a_night_shift_crosses_midnight_and_its_break_after_midnight_is_not_planned() {
    let shifts = Shifts::new(Some("UTC"), vec![night()]).unwrap();
    let w = shifts.on("night", "2026-11-02".parse().unwrap()).unwrap();
    assert_eq!(w.start, utc("2026-11-02T22:00:00Z"));
    assert_eq!(w.end, utc("2026-11-03T06:00:00Z"));
    assert_eq!(
        w.breaks,
        [(utc("2026-11-03T02:00:00Z"), utc("2026-11-03T02:30:00Z"))]
    );
    let planned = shifts.planned(w.start, w.end);
    assert_eq!(planned.millis(), (7 * 60 + 30) * 60 * 1000);
    assert_eq!(planned.work.len(), 2);
    // Three in the morning belongs to the shift that started the evening before.
    let at = shifts.at(utc("2026-11-03T03:00:00Z")).unwrap();
    assert_eq!(at.day.to_string(), "2026-11-02");
}

#[test]
fn a_shift_works_only_on_its_days() {
    let mut early = night();
    early.name = "early".into();
    early.start = hm("06:00");
    early.end = hm("14:00");
    early.breaks.clear();
    early.days = vec![Weekday::Monday, Weekday::Tuesday];
    let shifts = Shifts::new(Some("UTC"), vec![early]).unwrap();
    // 2026-11-07 is a Saturday.
    assert!(shifts.on("early", "2026-11-07".parse().unwrap()).is_none());
    let week = shifts.planned(utc("2026-11-02T00:00:00Z"), utc("2026-11-09T00:00:00Z"));
    assert_eq!(week.millis(), 2 * 8 * 3600 * 1000);
}

#[test]
fn a_night_shift_on_the_night_the_clocks_go_forward_is_an_hour_shorter() {
    let shifts = Shifts::new(Some("Europe/Berlin"), vec![night()]).unwrap();
    // Central European Summer Time begins on 2026-03-29 at 02:00.
    let w = shifts.on("night", "2026-03-28".parse().unwrap()).unwrap();
    assert_eq!(w.start, utc("2026-03-28T21:00:00Z"));
    assert_eq!(w.end, utc("2026-03-29T04:00:00Z"));
}

#[test]
fn a_day_runs_from_midnight_to_midnight_and_is_23_hours_when_the_clocks_go_forward() {
    let shifts = Shifts::new(Some("Europe/Berlin"), Vec::new()).unwrap();
    let (from, to) = shifts.day("2026-03-29".parse().unwrap()).unwrap();
    assert_eq!(from, utc("2026-03-28T23:00:00Z"));
    assert_eq!(to, utc("2026-03-29T22:00:00Z"));
}

#[test]
fn a_range_that_cuts_a_shift_plans_only_its_part_of_it() {
    let shifts = Shifts::new(Some("UTC"), vec![night()]).unwrap();
    let planned = shifts.planned(utc("2026-11-03T01:00:00Z"), utc("2026-11-03T03:00:00Z"));
    assert_eq!(planned.millis(), 90 * 60 * 1000);
    assert_eq!(planned.breaks.len(), 1);
}

#[test]
fn days_and_times_are_read_as_people_write_them() {
    assert_eq!(weekday("mon"), Some(Weekday::Monday));
    assert_eq!(weekday("Sunday"), Some(Weekday::Sunday));
    assert_eq!(weekday("mo"), None);
    assert_eq!(clock("06:00"), Some(Time::new(6, 0, 0, 0).unwrap()));
    assert_eq!(clock("24:00"), Some(Time::midnight()));
    assert_eq!(clock("25:00"), None);
    assert_eq!(clock("6"), None);
}

#[test]
fn an_unknown_time_zone_is_refused_with_examples() {
    let error = Shifts::new(Some("Mars/Olympus"), Vec::new()).unwrap_err();
    assert!(error.contains("Europe/Berlin"), "{error}");
}
