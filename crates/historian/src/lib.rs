//! The plant historian of cellbus: `cellbus historian`.
//!
//! A historian is a Sparkplug B primary host that takes every gateway's data off the
//! plant's MQTT broker into PostgreSQL.
//!
//! - [`store`]: the PostgreSQL side: the versioned schema, the day partitions of the
//!   samples (or a TimescaleDB hypertable), batch writes by binary `COPY` that never store a
//!   replayed sample twice, the views with a stable shape that users and Grafana query
//!   (`cellbus_samples`, `cellbus_events`, `cellbus_points`, `cellbus_states`), and the
//!   plant API's queries.
//! - [`ingest`]: what the Sparkplug host ([`sparkplug::Host`]) made of a message, as rows.
//! - [`writer`]: the one writer task: batches every 100 ms or 10,000 samples, retries on a
//!   new connection, bounded memory, the database's state for the MQTT side.
//! - [`mqtt`]: the broker connection as the primary host (STATE, Will, persistent
//!   session, offline while PostgreSQL fails).
//! - [`http`]: the plant API (`/api/history`, `/api/points`, `/api/events`, `/healthz`,
//!   `/metrics`).
//! - [`run`]: the whole thing, from [`run::Options`] to a clean stop.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod http;
pub mod ingest;
pub mod metrics;
pub mod mqtt;
pub mod run;
pub mod store;
pub mod writer;

pub use run::{DEFAULT_HOST_ID, Historian, Options};
pub use store::{
    Batch, Bucket, EventRow, PointRow, Quality, Refusal, RefusalReason, SampleRow, SamplesLayout,
    Store, StoreError, StoredSample, Written,
};
