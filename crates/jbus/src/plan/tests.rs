use super::*;

const H: Table = Table::HoldingRegisters;

fn spans(plan: &Plan) -> Vec<(Table, u16, u16)> {
    plan.reads()
        .iter()
        .map(|r| (r.table(), r.address(), r.count()))
        .collect()
}

fn options(max_registers: u16, register_gap: u16) -> PlanOptions {
    PlanOptions {
        max_registers: ReadRegisterCount::new(max_registers).expect("1-125"),
        register_gap,
        ..PlanOptions::default()
    }
}

#[test]
fn adjacent_and_nearly_adjacent_items_share_a_read() {
    let items = [
        Item::new(H, 0x10, 2),
        Item::new(H, 0x12, 1),
        Item::new(H, 0x18, 2), // gap of 5 from 0x13
        Item::new(H, 0x30, 1), // gap of 22: a new read
        Item::new(Table::InputRegisters, 0x10, 1),
        Item::new(Table::Coils, 0, 1),
        Item::new(Table::Coils, 99, 1), // 98 bits bridged
    ];
    let plan = Plan::new(&items, PlanOptions::default()).expect("plans");
    assert_eq!(
        spans(&plan),
        [
            (Table::Coils, 0, 100),
            (H, 0x10, 10),
            (H, 0x30, 1),
            (Table::InputRegisters, 0x10, 1),
        ]
    );
    assert_eq!(
        plan.locate(2),
        Some(Location {
            read: 1,
            offset: 8,
            length: 2
        })
    );
    assert_eq!(
        plan.locate(2)
            .and_then(|l| l.slice(&[0, 1, 2, 3, 4, 5, 6, 7, 8, 9])),
        Some(&[8, 9][..])
    );
    assert_eq!(
        plan.reads()[0].request(),
        Request::read_coils(0, 100).unwrap()
    );
}

#[test]
fn a_read_never_exceeds_the_devices_maximum() {
    // 250 single registers, max 125: two reads; with a device maximum of 50: five.
    let items: Vec<Item> = (0..250).map(|a| Item::new(H, a, 1)).collect();
    let plan = Plan::new(&items, PlanOptions::default()).expect("plans");
    assert_eq!(spans(&plan), [(H, 0, 125), (H, 125, 125)]);
    let plan = Plan::new(&items, options(50, 10)).expect("plans");
    assert_eq!(plan.reads().len(), 5);
    // A 2-register value that would straddle the limit goes whole into the next read.
    let items = [Item::new(H, 0, 4), Item::new(H, 4, 2)];
    assert_eq!(
        spans(&Plan::new(&items, options(5, 10)).unwrap()),
        [(H, 0, 4), (H, 4, 2)]
    );
}

#[test]
fn overlapping_and_repeated_items_share_one_read() {
    let items = [
        Item::new(H, 10, 4),
        Item::new(H, 10, 4),
        Item::new(H, 12, 1),
        Item::new(H, 11, 6),
    ];
    let plan = Plan::new(&items, PlanOptions::default()).expect("plans");
    assert_eq!(spans(&plan), [(H, 10, 7)]);
    assert_eq!(plan.locate(3).map(|l| l.offset), Some(1));
    assert_eq!(plan.locate(1).map(|l| l.offset), Some(0));
}

#[test]
fn one_request_per_item_reads_each_item_alone_but_duplicates_once() {
    let items = [Item::new(H, 0, 2), Item::new(H, 2, 1), Item::new(H, 0, 2)];
    let plan = Plan::new(
        &items,
        PlanOptions {
            one_request_per_item: true,
            ..PlanOptions::default()
        },
    )
    .expect("plans");
    assert_eq!(spans(&plan), [(H, 0, 2), (H, 2, 1)]);
    assert_eq!(plan.locate(2).map(|l| l.read), Some(0));
}

#[test]
fn items_no_read_can_fetch_are_refused_by_name() {
    let error = Plan::new(
        &[Item::new(H, 0, 1), Item::new(H, 0x10, 126)],
        PlanOptions::default(),
    )
    .unwrap_err();
    assert_eq!(
        error.to_string(),
        "item 1 (126 holding registers from 16 (0x0010)) is longer than one read: at most 125"
    );
    assert!(matches!(
        Plan::new(&[Item::new(H, 0, 20)], options(16, 0)),
        Err(PlanError::TooLong { max: 16, .. })
    ));
    assert!(matches!(
        Plan::new(&[Item::new(Table::Coils, 0, 0)], PlanOptions::default()),
        Err(PlanError::Empty { index: 0, .. })
    ));
    assert!(matches!(
        Plan::new(&[Item::new(H, 0xFFFF, 2)], PlanOptions::default()),
        Err(PlanError::PastLastAddress { .. })
    ));
    assert!(Plan::new(&[Item::new(H, 0xFFFF, 1)], PlanOptions::default()).is_ok());
}

#[test]
fn a_refused_merged_read_splits_at_its_widest_gap_and_stays_split() {
    // 0..2, 2..3, [hole 3..8], 8..10, [gap 10..12], 12..13
    let items = [
        Item::new(H, 0, 2),
        Item::new(H, 2, 1),
        Item::new(H, 8, 2),
        Item::new(H, 12, 1),
        Item::new(Table::InputRegisters, 0, 1),
    ];
    let mut plan = Plan::new(&items, PlanOptions::default()).expect("plans");
    assert_eq!(spans(&plan), [(H, 0, 13), (Table::InputRegisters, 0, 1)]);
    let split = plan.split(0).expect("a read");
    assert!(matches!(split, Split::Into { .. }));
    assert_eq!(
        split.to_string(),
        "the device refused a read of 13 holding registers from 0 (0x0000) (illegal data \
         address): reading it as 3 holding registers from 0 (0x0000) and 5 holding \
         registers from 8 (0x0008) from now on"
    );
    assert_eq!(
        spans(&plan),
        [(H, 0, 3), (H, 8, 5), (Table::InputRegisters, 0, 1)]
    );
    assert_eq!(plan.locate(3).map(|l| (l.read, l.offset)), Some((1, 4)));
    assert_eq!(plan.locate(4).map(|l| l.read), Some(2));
    // The device also refuses 8..13: the gap 10..12 goes.
    plan.split(1);
    assert_eq!(
        spans(&plan),
        [
            (H, 0, 3),
            (H, 8, 2),
            (H, 12, 1),
            (Table::InputRegisters, 0, 1)
        ]
    );
    // A single item refused is the device's answer for it.
    assert!(matches!(plan.split(2), Some(Split::Refused { .. })));
    assert_eq!(plan.reads().len(), 4);
    assert_eq!(plan.split(9), None);
}

#[test]
fn touching_items_split_in_halves_until_each_is_alone() {
    let items: Vec<Item> = (0..5).map(|a| Item::new(H, a * 2, 2)).collect();
    let mut plan = Plan::new(&items, PlanOptions::default()).expect("plans");
    assert_eq!(spans(&plan), [(H, 0, 10)]);
    plan.split(0);
    assert_eq!(spans(&plan), [(H, 0, 4), (H, 4, 6)]);
    let mut refusals = 1;
    while let Some(index) = plan.reads().iter().position(|r| r.items().len() > 1) {
        plan.split(index);
        refusals += 1;
    }
    assert_eq!(refusals, 4, "n items need n - 1 splits");
    assert_eq!(plan.reads().len(), 5);
    for read in 0..5 {
        assert!(matches!(plan.split(read), Some(Split::Refused { .. })));
    }
}
