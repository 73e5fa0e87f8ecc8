//! Model-based property tests of `jbus::plan`: for random items and options, every item
//! is fetched by exactly one read that contains it, no read breaks the device's limits,
//! and splitting refused reads converges to one read per item.

use jbus::plan::{Item, Plan, PlanOptions, Split};
use jbus::rtu::{ADDRESS_SPACE, ReadBitCount, ReadRegisterCount};
use jbus::slave::Table;
use proptest::prelude::*;

fn options() -> impl Strategy<Value = PlanOptions> {
    (
        1u16..=125,
        1u16..=2000,
        0u16..=20,
        0u16..=200,
        prop::bool::weighted(0.2),
    )
        .prop_map(
            |(registers, bits, register_gap, bit_gap, one_request_per_item)| PlanOptions {
                max_registers: ReadRegisterCount::new(registers).expect("1-125"),
                max_bits: ReadBitCount::new(bits).expect("1-2000"),
                register_gap,
                bit_gap,
                one_request_per_item,
            },
        )
}

/// The default options, but reads of at most `max` registers (1–125) that never bridge
/// a gap.
fn without_gaps(max: u16) -> PlanOptions {
    PlanOptions {
        max_registers: ReadRegisterCount::new(max).expect("1 to 125 registers"),
        register_gap: 0,
        ..PlanOptions::default()
    }
}

fn table() -> impl Strategy<Value = Table> {
    prop::sample::select(Table::ALL.to_vec())
}

/// Items that fit `options`: mostly short and close together, some at the top of the
/// address space.
fn items(options: PlanOptions) -> impl Strategy<Value = Vec<Item>> {
    let item = (
        table(),
        prop_oneof![4 => 0u32..400, 1 => 0xFF00u32..0x1_0000],
        1u32..=40,
    )
        .prop_map(move |(table, address, length)| {
            let length = length.min(u32::from(options.max(table)));
            let length = length.min(ADDRESS_SPACE as u32 - address);
            Item::new(table, address as u16, length as u16)
        });
    prop::collection::vec(item, 0..40)
}

fn options_and_items() -> impl Strategy<Value = (PlanOptions, Vec<Item>)> {
    options().prop_flat_map(|options| (Just(options), items(options)))
}

/// The invariants every plan keeps, before and after splits.
fn check(plan: &Plan) -> Result<(), TestCaseError> {
    let options = plan.options();
    let mut fetched = vec![0usize; plan.items().len()];
    for (index, read) in plan.reads().iter().enumerate() {
        prop_assert!(
            read.count() >= 1 && read.count() <= options.max(read.table()),
            "{read}"
        );
        prop_assert!(usize::from(read.address()) + usize::from(read.count()) <= ADDRESS_SPACE);
        prop_assert!(!read.items().is_empty());
        let start = u32::from(read.address());
        let end = start + u32::from(read.count());
        // The read is exactly the hull of its items, and bridges no gap wider than allowed.
        let mut covered_to = start;
        let mut hull_end = start;
        for &item_index in read.items() {
            let item = plan.items()[item_index];
            prop_assert_eq!(item.table, read.table(), "a read stays in one table");
            let (a, b) = (
                u32::from(item.address),
                u32::from(item.address) + u32::from(item.length),
            );
            prop_assert!(start <= a && b <= end, "{read} contains item {item_index}");
            prop_assert!(
                a.saturating_sub(covered_to) <= u32::from(options.gap(read.table())),
                "gap before item {item_index} in {read}"
            );
            covered_to = covered_to.max(b);
            hull_end = hull_end.max(b);
            fetched[item_index] += 1;
            let location = plan.locate(item_index).expect("every item is located");
            prop_assert_eq!(location.read, index);
            prop_assert_eq!(u32::from(location.offset), a - start);
            prop_assert_eq!(location.length, item.length);
        }
        prop_assert_eq!(
            hull_end,
            end,
            "no unwanted addresses at the end of {}",
            read
        );
        prop_assert_eq!(plan.items()[read.items()[0]].address, read.address());
        if options.one_request_per_item {
            let first = plan.items()[read.items()[0]];
            prop_assert!(read.items().iter().all(|&i| plan.items()[i] == first));
        }
        let _ = read.request();
    }
    prop_assert!(
        fetched.iter().all(|&n| n == 1),
        "each item fetched exactly once: {fetched:?}"
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn every_item_is_fetched_once_by_a_read_within_the_limits((options, items) in options_and_items()) {
        let plan = Plan::new(&items, options).expect("every item fits");
        check(&plan)?;
    }

    #[test]
    fn splitting_refused_reads_keeps_the_invariants_and_ends_with_one_read_per_item(
        (options, items) in options_and_items(),
        picks in prop::collection::vec(any::<prop::sample::Index>(), 0..10),
    ) {
        let mut plan = Plan::new(&items, options).expect("every item fits");
        for pick in picks {
            if plan.reads().is_empty() {
                break;
            }
            let read = pick.index(plan.reads().len());
            let before = plan.reads().len();
            match plan.split(read).expect("the read exists") {
                Split::Into { parts, .. } => {
                    prop_assert!(parts.len() >= 2);
                    prop_assert_eq!(plan.reads().len(), before + parts.len() - 1);
                }
                Split::Refused { .. } => prop_assert_eq!(plan.reads().len(), before),
            }
            check(&plan)?;
        }
        // Refuse everything until only single items are left: at most one split per item.
        let mut splits = 0;
        while let Some(read) = plan.reads().iter().position(|r| {
            let first = plan.items()[r.items()[0]];
            r.items().iter().any(|&i| plan.items()[i] != first)
        }) {
            let split = plan.split(read);
            prop_assert!(matches!(split, Some(Split::Into { .. })), "{:?}", split);
            splits += 1;
            prop_assert!(splits <= items.len());
        }
        check(&plan)?;
        for read in 0..plan.reads().len() {
            let split = plan.split(read);
            prop_assert!(matches!(split, Some(Split::Refused { .. })), "{:?}", split);
        }
    }

    #[test]
    fn without_gaps_or_overlaps_reads_are_the_runs_cut_by_the_maximum(
        max in 1u16..=20,
        runs in prop::collection::vec((1u16..=60, 1u16..=5), 1..6),
    ) {
        // Runs of single registers separated by holes of 1–5: with gap 0 each run is read
        // in ceil(run / max) reads.
        let options = without_gaps(max);
        let mut items = Vec::new();
        let mut address = 0u16;
        let mut expected = 0;
        for (run, hole) in runs {
            items.extend((address..address + run).map(|a| Item::new(Table::InputRegisters, a, 1)));
            expected += run.div_ceil(max);
            address += run + hole;
        }
        let plan = Plan::new(&items, options).expect("plans");
        prop_assert_eq!(plan.reads().len(), usize::from(expected));
        check(&plan)?;
    }

    #[test]
    fn without_gaps_or_overlaps_no_two_touching_reads_could_be_one(
        max in 1u16..=30,
        lengths in prop::collection::vec((1u16..=30, 0u16..=2), 1..30),
    ) {
        let options = without_gaps(max);
        let mut items = Vec::new();
        let mut address = 0u16;
        for (length, hole) in lengths {
            let length = length.min(max);
            items.push(Item::new(Table::HoldingRegisters, address, length));
            address += length + hole;
        }
        let plan = Plan::new(&items, options).expect("plans");
        check(&plan)?;
        for pair in plan.reads().windows(2) {
            let touching = u32::from(pair[0].address()) + u32::from(pair[0].count()) == u32::from(pair[1].address());
            if touching {
                // The greedy read took as much as fits: the next item would overflow it.
                let next = plan.items()[pair[1].items()[0]];
                prop_assert!(pair[0].count() + next.length > max);
            }
        }
        let wanted: u32 = items.iter().map(|i| u32::from(i.length)).sum();
        let read: u32 = plan.reads().iter().map(|r| u32::from(r.count())).sum();
        prop_assert_eq!(wanted, read, "gap 0: nothing unwanted is read");
    }
}
