//! The fewest reads that fetch a set of wanted registers and bits, and what to do when a
//! device refuses one of them.
//!
//! A [`Plan`] takes the [`Item`]s a poll wants (a table, a first address, a length) and
//! merges them into [`Read`]s: items taken in address order join the read before them
//! while the read stays within the table's maximum ([`PlanOptions::max_registers`], 125,
//! or [`PlanOptions::max_bits`], 2000, unless the device accepts less) and the unwanted
//! addresses bridged between them are at most [`PlanOptions::register_gap`] (10
//! registers) or [`PlanOptions::bit_gap`] (100 bits). Reading a few unwanted registers is
//! cheaper than another round trip: at 9600 baud 10 registers are 21 ms on the wire, a
//! request and its answer's header about 20 ms plus the device's turnaround. Items that
//! overlap or repeat share a read. [`Plan::locate`] says where each item's values are in
//! the answers.
//!
//! [`PlanOptions::one_request_per_item`] is for devices that refuse any range with a hole:
//! each item is read alone (identical items still share a read; the registers of one
//! item, a 32-bit value's two, always go together, or the value could tear).
//!
//! A device with holes in its map answers a merged read with exception 2 (illegal data
//! address). [`Plan::split`] then cuts that read's items in two, at the widest run of
//! unwanted addresses between them (the likeliest hole), or, when its items touch or
//! overlap, between the first and second half of them in address order; each half is
//! merged again as above (usually one read each; two when half of a run of overlapping
//! items holds a gap wider than a read bridges). The plan keeps the split for
//! every later poll, and each refusal splits again, so a read converges to one item at
//! most after as many refusals as it had items, less one. A read of one item (or of
//! identical items) that is refused is the device's refusal of that item:
//! [`Split::Refused`], nothing to split. A split happens once per read, so logging each
//! [`Split`] logs it once.

use std::fmt;

use crate::rtu::request::Addr;
use crate::rtu::{ADDRESS_SPACE, ReadBitCount, ReadRegisterCount, Request};
use crate::slave::Table;

/// Unwanted registers a read may bridge between two items unless told otherwise.
pub const DEFAULT_REGISTER_GAP: u16 = 10;

/// Unwanted bits a read may bridge between two items unless told otherwise.
pub const DEFAULT_BIT_GAP: u16 = 100;

/// A block of registers or bits a poll wants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Item {
    /// The table.
    pub table: Table,
    /// The first address.
    pub address: u16,
    /// How many registers (or bits): at least 1, at most one read's maximum.
    pub length: u16,
}

impl Item {
    /// `length` registers or bits of `table` from `address`.
    pub const fn new(table: Table, address: u16, length: u16) -> Self {
        Self {
            table,
            address,
            length,
        }
    }

    /// One past the last address.
    const fn end(&self) -> u32 {
        self.address as u32 + self.length as u32
    }

    /// Whether two items cover the same addresses of the same table.
    fn same_range(&self, other: &Self) -> bool {
        self.table == other.table && self.address == other.address && self.length == other.length
    }
}

impl fmt::Display for Item {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {} from {}",
            self.length,
            self.table,
            Addr(self.address)
        )
    }
}

/// How to merge items into reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlanOptions {
    /// The most registers one read asks for (default 125).
    pub max_registers: ReadRegisterCount,
    /// The most coils or discrete inputs one read asks for (default 2000).
    pub max_bits: ReadBitCount,
    /// The most unwanted registers a read bridges between two items (default 10).
    pub register_gap: u16,
    /// The most unwanted bits a read bridges between two items (default 100).
    pub bit_gap: u16,
    /// Read each item alone, for devices that refuse ranges containing holes.
    pub one_request_per_item: bool,
}

impl Default for PlanOptions {
    fn default() -> Self {
        Self {
            max_registers: ReadRegisterCount::new(ReadRegisterCount::MAX)
                .expect("the maximum is a count"),
            max_bits: ReadBitCount::new(ReadBitCount::MAX).expect("the maximum is a count"),
            register_gap: DEFAULT_REGISTER_GAP,
            bit_gap: DEFAULT_BIT_GAP,
            one_request_per_item: false,
        }
    }
}

impl PlanOptions {
    /// The longest read of `table`.
    pub fn max(&self, table: Table) -> u16 {
        if table.holds_bits() {
            self.max_bits.get()
        } else {
            self.max_registers.get()
        }
    }

    /// The widest gap a read of `table` bridges.
    pub fn gap(&self, table: Table) -> u16 {
        if table.holds_bits() {
            self.bit_gap
        } else {
            self.register_gap
        }
    }
}

/// One read of the plan: a block of one table, and the items it fetches.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Read {
    table: Table,
    address: u16,
    count: u16,
    /// Indices into the plan's items, in address order.
    items: Vec<usize>,
}

impl Read {
    /// The table.
    pub const fn table(&self) -> Table {
        self.table
    }

    /// The first address.
    pub const fn address(&self) -> u16 {
        self.address
    }

    /// How many registers or bits: 1 to the table's maximum, not past 0xFFFF.
    pub const fn count(&self) -> u16 {
        self.count
    }

    /// The items it fetches (indices into [`Plan::items`]), in address order.
    pub fn items(&self) -> &[usize] {
        &self.items
    }

    /// The request to send (function 1, 2, 3 or 4).
    pub fn request(&self) -> Request {
        let (address, count) = (self.address, self.count);
        match self.table {
            Table::Coils => Request::read_coils(address, count),
            Table::DiscreteInputs => Request::read_discrete_inputs(address, count),
            Table::HoldingRegisters => Request::read_holding_registers(address, count),
            Table::InputRegisters => Request::read_input_registers(address, count),
        }
        .expect("a planned read is within its table's maximum and the address space")
    }
}

impl fmt::Display for Read {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {} from {}",
            self.count,
            self.table,
            Addr(self.address)
        )
    }
}

/// Where an item's values are: in the answer to read `read`, from `offset` on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Location {
    /// The read's index in [`Plan::reads`].
    pub read: usize,
    /// The item's first value in that read's answer.
    pub offset: u16,
    /// How many values.
    pub length: u16,
}

impl Location {
    /// The item's values in the read's answer (`None` if the answer is too short).
    pub fn slice<'a, T>(&self, answer: &'a [T]) -> Option<&'a [T]> {
        let start = usize::from(self.offset);
        answer.get(start..start + usize::from(self.length))
    }
}

/// What [`Plan::split`] did with a refused read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Split {
    /// The read was replaced by `parts` (two, rarely more), from the refused read's index
    /// on; later reads moved up accordingly.
    Into {
        /// The refused read.
        refused: Read,
        /// Its parts, in address order.
        parts: Vec<Read>,
    },
    /// The read fetches one item (or identical ones): the device refuses that item. The
    /// plan keeps the read.
    Refused {
        /// The read, unchanged.
        read: Read,
    },
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Into { refused, parts } => {
                write!(
                    f,
                    "the device refused a read of {refused} (illegal data address): reading it as "
                )?;
                for (index, part) in parts.iter().enumerate() {
                    match index {
                        0 => {}
                        i if i + 1 == parts.len() => f.write_str(" and ")?,
                        _ => f.write_str(", ")?,
                    }
                    write!(f, "{part}")?;
                }
                f.write_str(" from now on")
            }
            Self::Refused { read } => write!(
                f,
                "the device refuses a read of {read} (illegal data address) on its own: \
                 it does not have these addresses"
            ),
        }
    }
}

/// An item that no read can fetch.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    /// A length of 0.
    #[error("item {index} ({item}) is empty: its length must be at least 1")]
    Empty {
        /// Its index in the list given.
        index: usize,
        /// The item.
        item: Item,
    },
    /// Longer than one read may be.
    #[error("item {index} ({item}) is longer than one read: at most {max}")]
    TooLong {
        /// Its index in the list given.
        index: usize,
        /// The item.
        item: Item,
        /// The longest read of its table.
        max: u16,
    },
    /// Running past address 0xFFFF.
    #[error("item {index} ({item}) runs past the last address 65535 (0xFFFF)")]
    PastLastAddress {
        /// Its index in the list given.
        index: usize,
        /// The item.
        item: Item,
    },
}

/// The reads that fetch a set of items, kept across polls with the splits the device
/// asked for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Plan {
    items: Vec<Item>,
    options: PlanOptions,
    reads: Vec<Read>,
    locations: Vec<Location>,
}

impl Plan {
    /// The fewest reads, for items taken in address order, that fetch `items` under
    /// `options`; an item that no read can fetch is an error naming it.
    pub fn new(items: &[Item], options: PlanOptions) -> Result<Self, PlanError> {
        for (index, item) in items.iter().enumerate() {
            let item = *item;
            if item.length == 0 {
                return Err(PlanError::Empty { index, item });
            }
            let max = options.max(item.table);
            if item.length > max {
                return Err(PlanError::TooLong { index, item, max });
            }
            if item.end() > ADDRESS_SPACE as u32 {
                return Err(PlanError::PastLastAddress { index, item });
            }
        }
        let mut order: Vec<usize> = (0..items.len()).collect();
        order.sort_by_key(|&i| (items[i].table, items[i].address, items[i].end()));
        let reads = merge(items, &order, &options);
        let mut plan = Self {
            items: items.to_vec(),
            options,
            reads,
            locations: Vec::new(),
        };
        plan.locate_all();
        Ok(plan)
    }

    /// The items, as given.
    pub fn items(&self) -> &[Item] {
        &self.items
    }

    /// The options.
    pub fn options(&self) -> &PlanOptions {
        &self.options
    }

    /// The reads, in table and address order (splits keep that order).
    pub fn reads(&self) -> &[Read] {
        &self.reads
    }

    /// Where item `item` (an index into [`items`](Self::items)) is read.
    pub fn locate(&self, item: usize) -> Option<Location> {
        self.locations.get(item).copied()
    }

    /// Replaces read `read` (an index into [`reads`](Self::reads)), which the device
    /// refused with exception 2, by smaller reads (see the [module](self)
    /// documentation), or says that the device refuses its only item. `None` if there
    /// is no such read.
    pub fn split(&mut self, read: usize) -> Option<Split> {
        let refused = self.reads.get(read)?.clone();
        let items = &self.items;
        let first_item = &items[refused.items[0]];
        if refused
            .items
            .iter()
            .all(|&i| items[i].same_range(first_item))
        {
            return Some(Split::Refused { read: refused });
        }
        let cut = self.cut(&refused);
        // Each part is merged again: half of a run of overlapping items may hold a gap
        // wider than a read may bridge, which then stays apart.
        let mut parts = merge(&self.items, &refused.items[..cut], &self.options);
        parts.extend(merge(&self.items, &refused.items[cut..], &self.options));
        self.reads.splice(read..=read, parts.iter().cloned());
        self.locate_all();
        Some(Split::Into { refused, parts })
    }

    /// Where to cut a read's items (in address order) in two: at the widest gap between
    /// them (the middlemost of equally wide ones), or in the middle when they touch.
    fn cut(&self, read: &Read) -> usize {
        let items = &read.items;
        let middle = items.len() / 2;
        let mut end = self.items[items[0]].end();
        let mut best: Option<(u32, usize)> = None;
        for (position, &index) in items.iter().enumerate().skip(1) {
            let item = &self.items[index];
            let gap = u32::from(item.address).saturating_sub(end);
            let better = match best {
                None => gap > 0,
                Some((widest, at)) => {
                    gap > widest
                        || (gap == widest && position.abs_diff(middle) < at.abs_diff(middle))
                }
            };
            if better {
                best = Some((gap, position));
            }
            end = end.max(item.end());
        }
        match best {
            Some((_, position)) => position,
            // Touching or overlapping: halves, each at least one item.
            None => middle.max(1),
        }
    }

    fn locate_all(&mut self) {
        let mut locations = vec![
            Location {
                read: 0,
                offset: 0,
                length: 0
            };
            self.items.len()
        ];
        for (index, read) in self.reads.iter().enumerate() {
            for &item in &read.items {
                locations[item] = Location {
                    read: index,
                    offset: self.items[item].address - read.address,
                    length: self.items[item].length,
                };
            }
        }
        self.locations = locations;
    }
}

/// The greedy merge: `order` (indices into `items`, sorted by table, address and end)
/// joins the read before while the read stays within the maximum and bridges no wider
/// gap than allowed.
fn merge(items: &[Item], order: &[usize], options: &PlanOptions) -> Vec<Read> {
    let mut reads: Vec<Read> = Vec::new();
    for &index in order {
        let item = &items[index];
        let joins = reads.last().is_some_and(|read| {
            read.table == item.table
                && if options.one_request_per_item {
                    items[read.items[0]].same_range(item)
                } else {
                    let start = u32::from(read.address);
                    let end = start + u32::from(read.count);
                    let gap = u32::from(item.address).saturating_sub(end);
                    gap <= u32::from(options.gap(item.table))
                        && end.max(item.end()) - start <= u32::from(options.max(item.table))
                }
        });
        match reads.last_mut() {
            Some(read) if joins => {
                let end = (u32::from(read.address) + u32::from(read.count)).max(item.end());
                read.count = count_between(read.address, end);
                read.items.push(index);
            }
            _ => reads.push(Read {
                table: item.table,
                address: item.address,
                count: item.length,
                items: vec![index],
            }),
        }
    }
    reads
}

/// The count from `address` to `end` (exclusive), which the planner keeps within a read's
/// maximum.
fn count_between(address: u16, end: u32) -> u16 {
    u16::try_from(end - u32::from(address)).expect("a read is at most 2000 long")
}

#[cfg(test)]
mod tests {
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
}
