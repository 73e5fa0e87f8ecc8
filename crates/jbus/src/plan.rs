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
mod tests;
