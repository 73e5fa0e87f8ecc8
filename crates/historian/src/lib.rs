//! The plant historian of cellbus: what `cellbus historian` stores in PostgreSQL.
//!
//! A historian is a Sparkplug B primary host that takes every gateway's data off the
//! plant's MQTT broker. This crate is its PostgreSQL side, in [`store`]: the versioned
//! schema, the day partitions of the samples (or a TimescaleDB hypertable), batch writes
//! by binary `COPY` that never store a replayed sample twice, the views with a stable shape
//! that users and Grafana query (`cellbus_samples`, `cellbus_events`, `cellbus_points`), and
//! the queries of the plant's history API.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod store;

pub use store::{
    Batch, Bucket, EventRow, PointRow, Quality, Refusal, RefusalReason, SampleRow, SamplesLayout,
    Store, StoreError, StoredSample, Written,
};
