//! Heap bytes a point, by component: what the gateway keeps for each point of a cell of
//! Modbus meters (100 `float32` registers each), measured by counting the heap in use
//! (the `cap` crate wraps the system allocator) before and after each part is built.
//!
//! ```text
//! cargo bench -p gateway --bench memory     # 500 and 1,000 meters
//! cargo test -p gateway --bench memory      # the smoke run: 20 and 40 meters, with the bounds checked
//! ```
//!
//! Each component is built for two cells, of N and 2N meters, in this one process, one
//! after the other: the difference between the two, divided by the N × 100 points more,
//! is the component's cost a point (its slope), and what is left at N is its fixed cost.
//! The components:
//!
//! - **drivers, plans and point state**: [`Cell::new`] (each meter's driver with its read
//!   plan, its entry, the live state of its points) with the alarm book;
//! - **Sparkplug B tables**: an edge node's births of every meter
//!   ([`sparkplug::node::EdgeNode::device_birth`] with the metrics the MQTT interface makes,
//!   [`device_metrics`]): the alias tables and each metric's last reading kept for report
//!   by exception (the birth payloads are dropped, as they are once sent);
//! - **OPC UA server**: [`cellbus_opcua::start`] on loopback over that cell (its in-memory
//!   objects of devices and alarms; the points, the devices' `Status` and `Error` and the
//!   alarms' variables are made when asked).
//!
//! The history's buffers depend on the flow of changes, not on the cell: the load bench
//! (`--mix modbus=1`) and a heap profile of it give those.
//!
//! The smoke run fails when a component costs more than [`BOUNDS`] a point, the figures
//! of 2026-11-30 with 25 % to spare: a change that makes points dearer fails CI, and
//! one that makes them cheaper should lower the bound.

use std::alloc::System;
use std::fmt::Write as _;
use std::process::ExitCode;
use std::sync::Arc;

use cap::Cap;
use gateway::cell::Cell;
use gateway::metrics::Metrics;
use gateway::northbound::mqtt::mapping::device_metrics;
use gateway::store::{Store, StoreOptions};
use gateway::time::Timestamp;
use sparkplug::node::{BdSeq, EdgeNode};
use sparkplug::topic::Id;

#[global_allocator]
static HEAP: Cap<System> = Cap::new(System, usize::MAX);

/// Points of each meter.
const POINTS: usize = 100;

/// The most bytes a point each component may cost before the smoke run fails: the
/// figures of 2026-11-30 (the larger of the smoke run's and the bench's: 165, 230 and
/// 50 B) and 25 % more.
const BOUNDS: [(&str, f64); 3] = [(PLANS, 206.0), (SPARKPLUG, 288.0), (OPCUA, 63.0)];

const PLANS: &str = "drivers, plans and point state";
const SPARKPLUG: &str = "Sparkplug B tables";
const OPCUA: &str = "OPC UA server";

fn main() -> ExitCode {
    let benching = std::env::args().any(|a| a == "--bench");
    let meters = if benching { 500 } else { 20 };
    match measure(meters) {
        Ok(costs) => {
            print!("{}", report(meters, &costs));
            if benching {
                return ExitCode::SUCCESS;
            }
            let over: Vec<String> = costs
                .iter()
                .filter_map(|c| {
                    let bound = BOUNDS.iter().find(|(name, _)| *name == c.name)?.1;
                    (c.per_point > bound).then(|| {
                        format!(
                            "{} cost {:.0} B a point, more than the bound of {bound:.0} B \
                             (benches/memory.rs, BOUNDS)",
                            c.name, c.per_point
                        )
                    })
                })
                .collect();
            if over.is_empty() {
                ExitCode::SUCCESS
            } else {
                eprintln!("memory: {}", over.join("; "));
                ExitCode::FAILURE
            }
        }
        Err(e) => {
            eprintln!("memory: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// One component's cost.
struct Cost {
    name: &'static str,
    /// Bytes a point (the slope between the two cells).
    per_point: f64,
    /// Bytes at `meters` meters beyond `meters × POINTS × per_point`.
    fixed: f64,
}

fn report(meters: usize, costs: &[Cost]) -> String {
    let mut text = format!(
        "memory: heap bytes a point, by component (between {meters} and {} Modbus meters of \
         {POINTS} float32 points)\n",
        2 * meters
    );
    for c in costs {
        let _ = writeln!(
            text,
            "  {:<32} {:>7.0} B a point, fixed {:>6.1} MiB",
            c.name,
            c.per_point,
            c.fixed / (1024.0 * 1024.0)
        );
    }
    text
}

/// Heap bytes in use now.
fn heap() -> f64 {
    HEAP.allocated() as f64
}

/// The bytes each component holds for cells of `meters` and `2 × meters` meters.
fn measure(meters: usize) -> anyhow::Result<Vec<Cost>> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let small = runtime.block_on(components(meters))?;
    let large = runtime.block_on(components(2 * meters))?;
    Ok(small
        .iter()
        .zip(&large)
        .map(|(&(name, at_n), &(_, at_2n))| {
            let per_point = (at_2n - at_n) / (meters * POINTS) as f64;
            Cost {
                name,
                per_point,
                fixed: at_n - per_point * (meters * POINTS) as f64,
            }
        })
        .collect())
}

/// Builds each component for a cell of `meters` meters; the bytes each holds.
async fn components(meters: usize) -> anyhow::Result<Vec<(&'static str, f64)>> {
    let dir = tempfile::tempdir()?;
    std::fs::write(dir.path().join("registers.csv"), registers_csv())?;
    let config =
        gateway::plugins::parse_config(&config_text(meters), &dir.path().join("cell.toml"))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    let store = Store::open(&dir.path().join("data"), StoreOptions::default())?;

    let before = heap();
    let (cell, plans) = Cell::new(&config, store.handle(), Arc::new(Metrics::new()))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let plans_bytes = heap() - before;

    let before = heap();
    let now = Timestamp::now();
    let mut node = EdgeNode::new(Id::new("plant")?, Id::new("gateway")?, BdSeq::new(0));
    node.on_connect();
    drop(node.node_birth(&[], sparkplug_time(now))?);
    for device in cell.roster().devices() {
        let metrics = device_metrics(&device.view(now), now);
        drop(node.device_birth(&Id::new(device.id.as_str())?, &metrics, sparkplug_time(now))?);
    }
    let sparkplug_bytes = heap() - before;

    let before = heap();
    let (stop_tx, stop) = tokio::sync::watch::channel(false);
    let started = cellbus_opcua::start(
        Arc::clone(&cell),
        cellbus_opcua::config::OpcuaConfig::at("127.0.0.1", 0),
        cellbus_opcua::Options {
            data_dir: dir.path().join("data"),
            allow_writes: false,
            users: Vec::new(),
            anonymous: true,
        },
        stop,
    )
    .await?;
    let opcua_bytes = heap() - before;
    let _ = stop_tx.send(true);
    let _ = started.task.await;

    drop((node, plans, cell));
    Ok(vec![
        (PLANS, plans_bytes),
        (SPARKPLUG, sparkplug_bytes),
        (OPCUA, opcua_bytes),
    ])
}

fn sparkplug_time(t: Timestamp) -> sparkplug::Timestamp {
    gateway::northbound::mqtt::mapping::sparkplug_time(t)
}

/// `meters` Modbus meters, 20 a line, each naming `registers.csv`; the lines are never
/// opened.
fn config_text(meters: usize) -> String {
    let mut text = String::new();
    for line in 0..meters.div_ceil(20) {
        let _ = write!(
            text,
            "\n[[line]]\nname = \"line{line:03}\"\nendpoint = \"modbus-tcp://127.0.0.1:{}\"\n",
            1 + line
        );
        for unit in 0..20.min(meters - 20 * line) {
            let _ = write!(
                text,
                "\n[[line.device]]\nid = \"m{line:03}-{unit:02}\"\nprotocol = \"modbus\"\n\
                 address = {}\nregisters_csv = \"registers.csv\"\n",
                unit + 1
            );
        }
    }
    text
}

/// [`POINTS`] `float32` input registers, `p00` at 0, `p01` at 2, … (as the load bench's).
fn registers_csv() -> String {
    let mut text = String::from("name,table,address,type,order\n");
    for point in 0..POINTS {
        let _ = writeln!(text, "p{point:02},input,{},float32,CDAB", point * 2);
    }
    text
}
