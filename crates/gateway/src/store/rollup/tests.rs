use super::*;

#[test]
fn an_exact_sum_is_correctly_rounded_whatever_the_order() {
    let values = [1e16, 1.0, -1e16, 0.1, 0.2, 0.3, 1e-20, 3.5e15, -7.25];
    let mut forward = ExactSum::default();
    values.iter().for_each(|v| forward.add(*v));
    let mut backward = ExactSum::default();
    values.iter().rev().for_each(|v| backward.add(*v));
    // Split in two halves and merged, as two batches or two minutes would be.
    let (mut a, mut b) = (ExactSum::default(), ExactSum::default());
    values[..4].iter().for_each(|v| a.add(*v));
    values[4..].iter().for_each(|v| b.add(*v));
    a.merge(&b);
    // 1 + 0.1 + 0.2 + 0.3 + 3.5e15 - 7.25 (+ 1e-20), rounded once.
    let expected = 3_500_000_000_000_000.0 - 7.25 + 1.0 + 0.6;
    assert_eq!(forward.total(), expected);
    assert_eq!(backward.total(), expected);
    assert_eq!(a.total(), expected);
    let naive: f64 = values.iter().sum();
    assert_ne!(naive, expected, "the naive sum loses the 1.0 next to 1e16");
}

#[test]
fn an_exact_sum_survives_its_stored_form_and_keeps_infinities() {
    let mut sum = ExactSum::default();
    [0.1, 1e300, -1e300, 0.7].iter().for_each(|v| sum.add(*v));
    let back = ExactSum::from_bytes(&sum.to_bytes()).unwrap();
    assert_eq!(back.total(), sum.total());
    assert_eq!(ExactSum::from_bytes(&[1, 2, 3]), None);
    sum.add(f64::INFINITY);
    assert_eq!(sum.total(), f64::INFINITY);
    let back = ExactSum::from_bytes(&sum.to_bytes()).unwrap();
    assert_eq!(back.total(), f64::INFINITY);
    sum.add(f64::NEG_INFINITY);
    assert!(sum.total().is_nan());
    let mut huge = ExactSum::default();
    huge.add(f64::MAX);
    huge.add(f64::MAX);
    assert_eq!(huge.total(), f64::INFINITY);
}

/// The sum as it was kept before the largest partial moved inline: every partial in
/// one list, the infinities beside it.
#[derive(Default)]
struct ListSum {
    partials: Vec<f64>,
    special: f64,
}

impl ListSum {
    fn add(&mut self, x: f64) {
        if !x.is_finite() {
            self.special += x;
            return;
        }
        let mut x = x;
        let mut kept = 0;
        for j in 0..self.partials.len() {
            let (hi, lo) = two_sum(x, self.partials[j]);
            if lo != 0.0 {
                self.partials[kept] = lo;
                kept += 1;
            }
            x = hi;
        }
        self.partials.truncate(kept);
        if x.is_finite() {
            self.partials.push(x);
        } else {
            self.special += x;
            self.partials.clear();
        }
    }

    fn total(&self) -> f64 {
        if self.special != 0.0 || self.special.is_nan() {
            return self.special;
        }
        let mut sum = ExactSum::default();
        if let Some((&top, rest)) = self.partials.split_last() {
            sum.top = top;
            if !rest.is_empty() {
                sum.rest = Some(Box::new(Partials(rest.to_vec())));
            }
        }
        sum.total()
    }
}

#[test]
fn an_exact_sum_holds_the_same_partials_as_a_list_of_them() {
    let mut rng = fastrand::Rng::with_seed(15);
    let pick = |rng: &mut fastrand::Rng| match rng.u8(0..8) {
        0 => f64::from(rng.i32(-1000..1000)),
        1 => f64::from(rng.i32(-1000..1000)) / 10.0,
        2 => f64::from(rng.f32() * 400.0 - 100.0),
        3 => (rng.f64() - 0.5) * 1e16,
        4 => (rng.f64() - 0.5) * 1e-12,
        5 => (rng.f64() - 0.5) * 1e300,
        6 => [0.1, 0.2, 0.3, -0.6, 1e16, -1e16][rng.usize(0..6)],
        _ => rng.f64(),
    };
    for round in 0..2000 {
        let n = rng.usize(1..60);
        let values: Vec<f64> = (0..n).map(|_| pick(&mut rng)).collect();
        let (mut list, mut inline) = (ListSum::default(), ExactSum::default());
        for &x in &values {
            list.add(x);
            inline.add(x);
            let rest = inline.rest.as_ref().map_or(&[][..], |r| &r.0[..]);
            let held: Vec<f64> = rest.iter().copied().chain([inline.top]).collect();
            assert_eq!(held, list.partials, "round {round}: {values:?}");
        }
        assert_eq!(
            inline.total().to_bits(),
            list.total().to_bits(),
            "{values:?}"
        );
        // Split where a batch or a minute would split them, then merged.
        let cut = rng.usize(0..=n);
        let (mut a, mut b) = (ExactSum::default(), ExactSum::default());
        values[..cut].iter().for_each(|x| a.add(*x));
        values[cut..].iter().for_each(|x| b.add(*x));
        a.merge(&b);
        assert_eq!(
            a.total().to_bits(),
            list.total().to_bits(),
            "{values:?} cut {cut}"
        );
        let back = ExactSum::from_bytes(&inline.to_bytes()).expect("whole f64s");
        assert_eq!(back.total().to_bits(), list.total().to_bits(), "{values:?}");
    }
}

#[test]
fn a_sum_of_whole_or_float32_readings_needs_no_heap() {
    let mut sum = ExactSum::default();
    for i in 0..10_000 {
        sum.add(f64::from(i % 500) - 120.0);
        sum.add(f64::from(i as f32 * 0.25 + 0.1_f32));
    }
    assert!(sum.rest.is_none(), "{sum:?}");
    assert_eq!(std::mem::size_of::<ExactSum>(), 16);
    assert_eq!(std::mem::size_of::<Aggregate>(), 40);
    let mut tenths = ExactSum::default();
    [0.1, 0.2].iter().for_each(|x| tenths.add(*x));
    assert!(tenths.rest.is_some(), "0.1 + 0.2 is not exact in binary");
    tenths.add(-0.2);
    assert_eq!(tenths.total(), 0.1);
    tenths.add(-0.1);
    assert!(tenths.rest.is_none(), "back to one partial: {tenths:?}");
    assert_eq!(tenths.total(), 0.0);
}

/// Every open minute the table holds before `minute`, in a map.
fn held(table: &OpenTable, minute: i64) -> BTreeMap<(i64, i64), (u64, f64, f64, f64)> {
    table
        .before(minute)
        .map(|(id, m, a)| ((id, m), (a.count, a.sum.total(), a.min, a.max)))
        .collect()
}

#[test]
fn the_open_table_keeps_every_id_and_minute_whatever_their_range() {
    // Two points known at start; ids beyond them come as new points or stray.
    let mut table = OpenTable::new(2);
    let stray = 3 + DENSE_STEP + 1;
    let samples = [
        (1, 0, 5.0),
        (2, 0, -1.5),
        (1, MINUTE_MS, 7.0),
        (1, 0, 6.0),
        (3, MINUTE_MS, 1.0),
        (-4, 0, 2.0),
        (stray, MINUTE_MS, 3.0),
        (i64::MAX, 2 * MINUTE_MS, 4.0),
        (2, 5 * MINUTE_MS, 9.0),
    ];
    for (id, minute, x) in samples {
        table.add(id, minute, x);
    }
    assert!(table.more.contains_key(&(-4, 0)));
    assert!(table.more.contains_key(&(stray, MINUTE_MS)));
    assert!(table.more.contains_key(&(i64::MAX, 2 * MINUTE_MS)));
    assert_eq!(table.columns.len(), 3, "minutes 0, 1 and 5 in columns");
    let all = held(&table, i64::MAX);
    assert_eq!(all.len(), 8, "{all:?}");
    assert_eq!(all[&(1, 0)], (2, 11.0, 5.0, 6.0));
    assert_eq!(all[&(2, 0)], (1, -1.5, -1.5, -1.5));
    assert_eq!(all[&(3, MINUTE_MS)], (1, 1.0, 1.0, 1.0));
    assert_eq!(all[&(-4, 0)], (1, 2.0, 2.0, 2.0));

    table.close_before(MINUTE_MS);
    let left = held(&table, i64::MAX);
    assert!(left.keys().all(|&(_, m)| m >= MINUTE_MS), "{left:?}");
    assert_eq!(left.len(), 5, "{left:?}");
    // The closed minute's column is kept for the next minute, which fills it again.
    let spare = table.spare.slots.capacity();
    assert!(spare > 0);
    table.add(1, 6 * MINUTE_MS, 1.0);
    assert_eq!(table.columns[&(6 * MINUTE_MS)].slots.capacity(), spare);
    table.close_before(i64::MAX);
    assert!(held(&table, i64::MAX).is_empty());
}

#[test]
fn a_column_holds_an_aggregate_only_for_the_points_with_samples() {
    let mut table = OpenTable::new(10_000);
    for id in (1..=10_000).step_by(100) {
        table.add(id, 0, id as f64);
        table.add(id, 0, 1.5);
    }
    let column = &table.columns[&0];
    assert_eq!(column.aggregates.len(), 100);
    assert!(column.slots.len() > 9_900);
    let held = held(&table, i64::MAX);
    let ids: Vec<i64> = held.keys().map(|&(id, _)| id).collect();
    assert_eq!(
        ids,
        (1..=10_000).step_by(100).collect::<Vec<_>>(),
        "in id order"
    );
    assert_eq!(held[&(201, 0)], (2, 202.5, 1.5, 201.0));
}

#[test]
fn a_closed_first_minute_full_of_points_leaves_room_only_for_the_next_ones() {
    let mut table = OpenTable::new(20_000);
    // After a start every point is read for the first time...
    for id in 1..=20_000 {
        table.add(id, 0, 1.0);
    }
    // ...then only some of them change.
    for id in (1..=20_000).step_by(10) {
        table.add(id, MINUTE_MS, 2.0);
    }
    let first = &table.columns[&0];
    assert_eq!(
        first.aggregates.capacity(),
        0,
        "one sample each: no aggregate"
    );
    let singles = first.singles.capacity();
    assert!(
        (20_000..25_000).contains(&singles),
        "grown by quarters: {singles}"
    );
    table.close_before(MINUTE_MS);
    assert!(
        table.spare.singles.capacity() <= 2_000 + GROW_ENTRIES,
        "the spare keeps room for the open minute's 2,000, not 20,000: {}",
        table.spare.singles.capacity()
    );
    assert_eq!(held(&table, i64::MAX).len(), 2_000);
}

#[test]
fn a_point_sampled_once_in_a_minute_holds_one_number_and_a_second_sample_an_aggregate() {
    let mut table = OpenTable::new(4);
    table.add(1, 0, -0.0);
    table.add(2, 0, 3.5);
    table.add(3, 0, f64::INFINITY);
    table.add(2, 0, 0.1);
    table.add(2, 0, 0.2);
    let column = &table.columns[&0];
    assert_eq!(column.singles.len(), 3, "every point's first sample");
    assert_eq!(column.aggregates.len(), 1, "only point 2 has more");
    let held = held(&table, i64::MAX);
    let mut expected = Aggregate::of(3.5);
    expected.add(0.1);
    expected.add(0.2);
    assert_eq!(
        held[&(2, 0)],
        (3, expected.sum.total(), 0.1, 3.5),
        "the same aggregate as from three adds"
    );
    assert_eq!(
        held[&(1, 0)],
        (1, 0.0, 0.0, 0.0),
        "-0 kept as SQLite keeps it"
    );
    assert!(held[&(1, 0)].1.is_sign_positive());
    assert_eq!(
        held[&(3, 0)],
        (1, f64::INFINITY, f64::INFINITY, f64::INFINITY)
    );
}

#[test]
fn minutes_are_cut_at_whole_minutes() {
    assert_eq!(minute_of(59_999), 0);
    assert_eq!(minute_of(-1), -60_000);
    assert_eq!(minute_of(i64::MIN), i64::MIN);
    assert_eq!(minute_of(i64::MAX) % MINUTE_MS, 0);
    assert_eq!(minute_of(60_000), 60_000);
    assert_eq!(next_minute(0), 0);
    assert_eq!(next_minute(1), 60_000);
    assert_eq!(next_minute(60_000), 60_000);
    assert_eq!(next_minute(i64::MAX), minute_of(i64::MAX));
}
