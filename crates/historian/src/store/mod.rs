//! The historian's PostgreSQL store.
//!
//! [`Store::connect`] opens one connection (without TLS: PostgreSQL on the historian's
//! host or a trusted plant network; TLS is not offered yet) and brings the schema to its
//! version. [`Store::write`] commits a [`Batch`] of points, samples and events in one
//! transaction: samples go by binary `COPY` into a temporary staging table, then into
//! `samples` with `ON CONFLICT DO NOTHING`, so a batch written twice (a backlog replayed
//! after an outage, or the same batch retried after a lost connection) is stored once.
//!
//! # Schema
//!
//! - `points(id, node, device, point, datatype, unit, description, writable, write_min,
//!   write_max, group_id)`, unique by (node, device, point, group_id): the same edge node id
//!   in two Sparkplug groups is two nodes. A node's own metrics have device `''`. Points
//!   stored by schema version 1 have group `''` until their node's next birth claims them
//!   ([`adopt_ungrouped`]).
//! - `samples(point_id, t, value, text, quality)`, primary key (point_id, t), partitioned
//!   by range on `t`, one partition per UTC day (`samples_2026_01_31`) created before the
//!   first batch that needs it; or, when TimescaleDB can be used, a hypertable with one-day
//!   chunks. `quality` is 0 good, 1 stale, 2 bad. No foreign key to `points` (it would cost
//!   a lookup per row on ingest; the store writes only ids it got from `points`).
//! - `events(id, t, node, device, point, line, kind, severity, message, group_id)`, unique
//!   by (node, device, point, t, kind, md5(message), group_id).
//! - The views users and Grafana query, whose shape stays: `cellbus_samples(node, device,
//!   point, t, value, text, quality, group_id)` with quality as `good`/`stale`/`bad`,
//!   `cellbus_events(t, node, device, point, line, kind, severity, message, group_id)` and
//!   `cellbus_points(node, device, point, unit, description, datatype, writable, write_min,
//!   write_max, group_id)` (columns are only ever added at the end); since version 4
//!   `cellbus_states(node, device, start, "end", state, code, category, reason, group_id)`,
//!   each device's machine states as intervals made from its `machine_state`,
//!   `machine_state_code` and `machine_state_reason` samples (`schema::version_4`).
//!
//! Samples dated before 2000, more than a day ahead of the historian's clock, or older
//! than the maximum age ([`Store::set_max_age`]; the historian's `--max-age`, 31 days by
//! default) are refused and counted ([`Written::refused_samples`]), never written: they
//! would create partitions for a wrong clock's dates, and a rogue birth dated a day apart
//! per metric would create thousands (each a table PostgreSQL plans and locks for every
//! query of `samples`).
//!
//! Durability is PostgreSQL's: a write returns after its commit is flushed. For a faster,
//! less durable ingest add `options=-c%20synchronous_commit%3Doff` to the URL.

mod days;
mod error;
mod query;
mod rows;
mod schema;

use std::collections::{HashMap, HashSet};
use std::time::{Duration, SystemTime};

use futures_util::pin_mut;
use tokio_postgres::binary_copy::BinaryCopyInWriter;
use tokio_postgres::types::Type;
use tokio_postgres::{Client, Config, NoTls, Statement, Transaction};

pub use error::StoreError;
pub use query::FoundPoint;
pub use rows::{
    Batch, Bucket, EARLIEST_UNIX_SECS, EventRow, MAX_AHEAD, PointRow, Quality, Refusal,
    RefusalReason, SampleRow, StoredSample, UNKNOWN_DATATYPE, Written, check_time,
};
pub use schema::{SCHEMA_VERSION, SamplesLayout};

/// How long a connection attempt may take when the URL does not say
/// (`connect_timeout=`).
/// Point ids a connection keeps by default: the Sparkplug host's default limit of points
/// (`--max-points`).
pub const DEFAULT_POINT_CACHE: usize = 250_000;

const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// The staging table of a connection's samples: temporary (never in the WAL), emptied by
/// every commit.
const CREATE_STAGING: &str = "CREATE TEMP TABLE IF NOT EXISTS cellbus_staging (
        point_id integer NOT NULL,
        t timestamptz NOT NULL,
        value double precision,
        text text,
        quality smallint NOT NULL
    ) ON COMMIT DELETE ROWS";

const COPY_STAGING: &str = "COPY cellbus_staging (point_id, t, value, text, quality) \
    FROM STDIN (FORMAT binary)";

/// The column types of [`COPY_STAGING`].
const STAGING_TYPES: [Type; 5] = [
    Type::INT4,
    Type::TIMESTAMPTZ,
    Type::FLOAT8,
    Type::TEXT,
    Type::INT2,
];

/// A connection to the historian's database, with the ids of the points it has seen.
///
/// One `Store` writes; it is not shared. A lost connection is not repaired: connect a new
/// `Store` and write the same batch again (see [`StoreError::is_connection_lost`]).
#[derive(Debug)]
pub struct Store {
    client: Client,
    layout: SamplesLayout,
    statements: Statements,
    /// Point ids by [`point_key`]; at most `point_cache` of them.
    point_ids: HashMap<String, i32>,
    /// Most point ids kept: past it the cache starts again empty (births and churned
    /// node names cannot grow it without bound; ids are read again as needed).
    point_cache: usize,
    /// Days whose partition this connection has made sure of.
    days: HashSet<i64>,
    /// Reused for building keys.
    scratch: String,
    migrated: Vec<i32>,
    /// Rows older than this are refused (`None`: any age after 2000).
    max_age: Option<Duration>,
}

/// The statements of the write path, prepared once per connection.
#[derive(Debug)]
struct Statements {
    adopt_ungrouped: Statement,
    adopt_ungrouped_events: Statement,
    upsert_points: Statement,
    insert_bare_points: Statement,
    point_ids: Statement,
    insert_samples: Statement,
    insert_events: Statement,
}

/// Reads a PostgreSQL connection string (a `postgres://` or `postgresql://` URL, or
/// libpq's `key=value` form); never echoes it, since it may hold a password.
///
/// # Errors
///
/// [`StoreError::NotPostgres`] for another URL scheme, else [`StoreError::BadUrl`].
pub fn parse_url(url: &str) -> Result<Config, StoreError> {
    if let Some((scheme, _)) = url.split_once("://")
        && !matches!(scheme, "postgres" | "postgresql")
    {
        return Err(StoreError::NotPostgres {
            scheme: scheme.to_owned(),
        });
    }
    url.parse().map_err(|source| StoreError::BadUrl { source })
}

impl Store {
    /// Connects to `url` (`postgres://USER@HOST:PORT/DB`, any libpq-style option; no
    /// TLS; the password from the URL, else from `PGPASSWORD`), brings the schema to [`SCHEMA_VERSION`] and prepares the write path.
    ///
    /// Must run inside a tokio runtime: the connection is driven by a spawned task.
    ///
    /// # Errors
    ///
    /// [`StoreError::BadUrl`], [`StoreError::Connect`] (transient when the server is not
    /// up yet), [`StoreError::SchemaTooNew`], or the failing step of the migration.
    pub async fn connect(url: &str) -> Result<Store, StoreError> {
        let mut config = parse_url(url)?;
        if config.get_password().is_none()
            && let Ok(password) = std::env::var("PGPASSWORD")
        {
            config.password(password);
        }
        if config.get_connect_timeout().is_none() {
            config.connect_timeout(CONNECT_TIMEOUT);
        }
        if config.get_application_name().is_none() {
            config.application_name("cellbus historian");
        }
        let target = describe_target(&config);
        let (mut client, connection) = config
            .connect(NoTls)
            .await
            .map_err(|e| StoreError::connect(target.clone(), e))?;
        tokio::spawn(async move {
            if let Err(e) = connection.await {
                tracing::warn!("the connection to PostgreSQL at {target} ended: {e}");
            }
        });
        let migrated = schema::migrate(&mut client).await?;
        let layout = schema::layout(&client).await?;
        client
            .batch_execute(CREATE_STAGING)
            .await
            .map_err(|e| StoreError::statement("creating the staging table", e))?;
        let statements = Statements::prepare(&client).await?;
        Ok(Store {
            client,
            layout,
            statements,
            point_ids: HashMap::new(),
            point_cache: DEFAULT_POINT_CACHE,
            days: HashSet::new(),
            scratch: String::new(),
            migrated,
            max_age: None,
        })
    }

    /// Refuses samples and events older than `max_age` from then on (`None`: any age after
    /// 2000, the default).
    pub fn set_max_age(&mut self, max_age: Option<Duration>) {
        self.max_age = max_age;
    }

    /// Keeps at most `points` point ids in memory from then on (the default is
    /// [`DEFAULT_POINT_CACHE`]): when a batch would pass it, the cache is emptied first and
    /// the ids are read again by the batches that need them.
    pub fn set_point_cache(&mut self, points: usize) {
        self.point_cache = points;
    }

    /// How many point ids this connection keeps in memory.
    pub fn cached_points(&self) -> usize {
        self.point_ids.len()
    }

    /// How the samples are split by time in this database.
    pub fn layout(&self) -> SamplesLayout {
        self.layout
    }

    /// The schema versions this connection applied (empty when the schema was current).
    pub fn migrated(&self) -> &[i32] {
        &self.migrated
    }

    /// Whether the connection is known to be closed (then every call fails with
    /// [`StoreError::ConnectionLost`]).
    pub fn is_closed(&self) -> bool {
        self.client.is_closed()
    }

    /// Commits `batch` in one transaction and says what it stored, what was already
    /// stored and what it refused. The partitions the samples need are created first, each
    /// in its own short transaction.
    ///
    /// # Errors
    ///
    /// [`StoreError::ConnectionLost`] (connect again and retry the same batch) or
    /// [`StoreError::Refused`]; either way nothing of the batch is committed.
    pub async fn write(&mut self, batch: &Batch) -> Result<Written, StoreError> {
        let result = self.write_at(batch, SystemTime::now()).await;
        if result.is_err() {
            // A partition may have been dropped behind our back: check again next time.
            self.days.clear();
        }
        result
    }

    async fn write_at(&mut self, batch: &Batch, now: SystemTime) -> Result<Written, StoreError> {
        let mut written = Written::default();
        let accepted = Accepted::sort(batch, now, self.max_age, &mut written);
        if accepted.is_empty() {
            return Ok(written);
        }
        if self.layout == SamplesLayout::DayPartitions {
            self.ensure_partitions(&accepted.samples).await?;
        }
        let tx = self
            .client
            .transaction()
            .await
            .map_err(|e| StoreError::statement("starting the batch's transaction", e))?;
        let mut new_ids = HashMap::new();
        written.points =
            upsert_points(&tx, &self.statements, &accepted.points, &mut new_ids).await?;
        let missing = missing_points(&accepted.samples, &self.point_ids, &new_ids);
        written.bare_points =
            insert_bare_points(&tx, &self.statements, &missing, &mut new_ids).await?;
        let staged = copy_samples(
            &tx,
            &accepted.samples,
            &self.point_ids,
            &new_ids,
            &mut self.scratch,
        )
        .await?;
        written.samples = if staged > 0 {
            tx.execute(&self.statements.insert_samples, &[])
                .await
                .map_err(|e| StoreError::statement("moving samples from staging", e))?
        } else {
            0
        };
        written.duplicate_samples = staged.saturating_sub(written.samples);
        written.events = insert_events(&tx, &self.statements, &accepted.events).await?;
        written.duplicate_events = (accepted.events.len() as u64).saturating_sub(written.events);
        tx.commit()
            .await
            .map_err(|e| StoreError::statement("committing the batch", e))?;
        if self.point_ids.len() + new_ids.len() > self.point_cache {
            self.point_ids.clear();
            self.point_ids.shrink_to(new_ids.len());
        }
        self.point_ids.extend(new_ids);
        Ok(written)
    }

    /// Creates the day partitions `samples` need that this connection has not seen yet,
    /// each in its own transaction under an advisory lock (two historians creating the
    /// same partition at once would otherwise collide in the catalog).
    async fn ensure_partitions(&mut self, samples: &[&SampleRow]) -> Result<(), StoreError> {
        let mut needed: Vec<i64> = samples
            .iter()
            .map(|s| days::day_of(s.t))
            .filter(|day| !self.days.contains(day))
            .collect();
        needed.sort_unstable();
        needed.dedup();
        for day in needed {
            let tx = self
                .client
                .transaction()
                .await
                .map_err(|e| StoreError::statement("starting a partition's transaction", e))?;
            tx.execute(
                "SELECT pg_advisory_xact_lock($1)",
                &[&schema::PARTITION_LOCK],
            )
            .await
            .map_err(|e| StoreError::statement("taking the partition lock", e))?;
            tx.batch_execute(&days::create_partition_sql(day))
                .await
                .map_err(|e| StoreError::statement("creating a day partition of samples", e))?;
            tx.commit()
                .await
                .map_err(|e| StoreError::statement("committing a day partition", e))?;
            self.days.insert(day);
        }
        Ok(())
    }
}

impl Statements {
    async fn prepare(client: &Client) -> Result<Self, StoreError> {
        let prepare = |sql: &'static str| async move {
            client
                .prepare(sql)
                .await
                .map_err(|e| StoreError::statement("preparing the write statements", e))
        };
        Ok(Statements {
            // A point of a node's version-1 rows (group '') goes to the group now seen
            // with that node, unless that group has the point already.
            adopt_ungrouped: prepare(
                "UPDATE points p SET group_id = k.group_id \
                 FROM (SELECT DISTINCT * FROM unnest($1::text[], $2::text[])) \
                 AS k(group_id, node) \
                 WHERE p.group_id = '' AND k.group_id <> '' AND p.node = k.node \
                 AND NOT EXISTS (SELECT 1 FROM points q WHERE q.node = p.node \
                 AND q.device = p.device AND q.point = p.point AND q.group_id = k.group_id)",
            )
            .await?,
            // The same for events, so one resent across the upgrade is still a duplicate.
            adopt_ungrouped_events: prepare(
                "UPDATE events e SET group_id = k.group_id \
                 FROM (SELECT DISTINCT * FROM unnest($1::text[], $2::text[])) \
                 AS k(group_id, node) \
                 WHERE e.group_id = '' AND k.group_id <> '' AND e.node = k.node \
                 AND NOT EXISTS (SELECT 1 FROM events f WHERE f.node = e.node \
                 AND f.device IS NOT DISTINCT FROM e.device \
                 AND f.point IS NOT DISTINCT FROM e.point AND f.t = e.t AND f.kind = e.kind \
                 AND md5(f.message) = md5(e.message) AND f.group_id = k.group_id)",
            )
            .await?,
            upsert_points: prepare(
                "INSERT INTO points (group_id, node, device, point, datatype, unit, \
                 description, writable, write_min, write_max) \
                 SELECT * FROM unnest($1::text[], $2::text[], $3::text[], $4::text[], \
                 $5::text[], $6::text[], $7::text[], $8::bool[], $9::float8[], $10::float8[]) \
                 ON CONFLICT (node, device, point, group_id) DO UPDATE SET \
                 datatype = EXCLUDED.datatype, unit = EXCLUDED.unit, \
                 description = EXCLUDED.description, writable = EXCLUDED.writable, \
                 write_min = EXCLUDED.write_min, write_max = EXCLUDED.write_max \
                 RETURNING id, group_id, node, device, point",
            )
            .await?,
            insert_bare_points: prepare(
                "INSERT INTO points (group_id, node, device, point) \
                 SELECT * FROM unnest($1::text[], $2::text[], $3::text[], $4::text[]) \
                 ON CONFLICT (node, device, point, group_id) DO NOTHING",
            )
            .await?,
            point_ids: prepare(
                "SELECT p.id, p.group_id, p.node, p.device, p.point FROM points p \
                 JOIN unnest($1::text[], $2::text[], $3::text[], $4::text[]) \
                 AS k(group_id, node, device, point) USING (group_id, node, device, point)",
            )
            .await?,
            insert_samples: prepare(
                "INSERT INTO samples (point_id, t, value, text, quality) \
                 SELECT point_id, t, value, text, quality FROM cellbus_staging \
                 ON CONFLICT (point_id, t) DO NOTHING",
            )
            .await?,
            insert_events: prepare(
                "INSERT INTO events (t, node, device, point, line, kind, severity, message, \
                 group_id, fields) \
                 SELECT t, node, device, point, line, kind, severity, message, group_id, \
                 fields::jsonb FROM unnest($1::timestamptz[], $2::text[], $3::text[], \
                 $4::text[], $5::text[], $6::text[], $7::int4[], $8::text[], $9::text[], \
                 $10::text[]) AS e(t, node, device, point, line, kind, severity, message, \
                 group_id, fields) \
                 ON CONFLICT (node, device, point, t, kind, md5(message), group_id) DO NOTHING",
            )
            .await?,
        })
    }
}

/// The rows of a batch the store may write (times in range, no NUL in any text); points
/// named twice keep their last definition.
struct Accepted<'a> {
    points: Vec<&'a PointRow>,
    samples: Vec<&'a SampleRow>,
    events: Vec<&'a EventRow>,
}

impl<'a> Accepted<'a> {
    fn sort(
        batch: &'a Batch,
        now: SystemTime,
        max_age: Option<Duration>,
        written: &mut Written,
    ) -> Self {
        let mut refuse = |row: String, t: SystemTime, reason: RefusalReason| {
            written
                .first_refusal
                .get_or_insert(Refusal { row, t, reason });
        };
        let mut by_key: HashMap<String, usize> = HashMap::new();
        let mut points: Vec<&PointRow> = Vec::new();
        for p in &batch.points {
            let texts = [&p.group, &p.node, &p.device, &p.point, &p.datatype];
            let optional = [&p.unit, &p.description];
            if texts.iter().any(|t| has_nul(t)) || optional.iter().any(|t| has_nul_opt(t)) {
                written.refused_points += 1;
                refuse(
                    format!("point {}", display_point(&p.node, &p.device, &p.point)),
                    SystemTime::UNIX_EPOCH,
                    RefusalReason::NulCharacter,
                );
                continue;
            }
            let mut key = String::new();
            point_key(&mut key, &p.group, &p.node, &p.device, &p.point);
            match by_key.get(&key) {
                Some(&i) => points[i] = p,
                None => {
                    by_key.insert(key, points.len());
                    points.push(p);
                }
            }
        }
        // In one order everywhere, so two historians upserting the same points lock their
        // rows in the same order and cannot deadlock.
        points.sort_by(|a, b| {
            (&a.node, &a.device, &a.point, &a.group).cmp(&(&b.node, &b.device, &b.point, &b.group))
        });
        let mut samples = Vec::with_capacity(batch.samples.len());
        for s in &batch.samples {
            let texts = [&s.group, &s.node, &s.device, &s.point];
            match verdict(&texts, &[&s.text], s.t, now, max_age) {
                Ok(()) => samples.push(s),
                Err(reason) => {
                    written.refused_samples += 1;
                    let row = format!("sample {}", display_point(&s.node, &s.device, &s.point));
                    refuse(row, s.t, reason);
                }
            }
        }
        let mut events = Vec::with_capacity(batch.events.len());
        for e in &batch.events {
            let texts = [&e.group, &e.node, &e.kind, &e.message];
            let optional = [&e.device, &e.point, &e.line];
            match verdict(&texts, &optional, e.t, now, max_age) {
                Ok(()) => events.push(e),
                Err(reason) => {
                    written.refused_events += 1;
                    refuse(format!("event {} {}", e.node, e.kind), e.t, reason);
                }
            }
        }
        Accepted {
            points,
            samples,
            events,
        }
    }

    fn is_empty(&self) -> bool {
        self.points.is_empty() && self.samples.is_empty() && self.events.is_empty()
    }
}

/// Inserts or updates the batch's points; records their ids in `ids`.
async fn upsert_points(
    tx: &Transaction<'_>,
    statements: &Statements,
    points: &[&PointRow],
    ids: &mut HashMap<String, i32>,
) -> Result<u64, StoreError> {
    if points.is_empty() {
        return Ok(0);
    }
    adopt_ungrouped(
        tx,
        statements,
        points.iter().map(|p| (p.group.as_str(), p.node.as_str())),
    )
    .await?;
    let column = |f: fn(&PointRow) -> &str| points.iter().map(|p| f(p)).collect::<Vec<_>>();
    let optional =
        |f: fn(&PointRow) -> Option<&str>| points.iter().map(|p| f(p)).collect::<Vec<_>>();
    let limit = |f: fn(&PointRow) -> Option<f64>| points.iter().map(|p| f(p)).collect::<Vec<_>>();
    let rows = tx
        .query(
            &statements.upsert_points,
            &[
                &column(|p| &p.group),
                &column(|p| &p.node),
                &column(|p| &p.device),
                &column(|p| &p.point),
                &column(|p| &p.datatype),
                &optional(|p| p.unit.as_deref()),
                &optional(|p| p.description.as_deref()),
                &points.iter().map(|p| p.writable).collect::<Vec<_>>(),
                &limit(|p| p.write_min),
                &limit(|p| p.write_max),
            ],
        )
        .await
        .map_err(|e| StoreError::statement("inserting or updating points", e))?;
    record_ids(&rows, ids);
    Ok(rows.len() as u64)
}

/// A point's names: group, node, device, metric.
type Names<'a> = (&'a str, &'a str, &'a str, &'a str);

/// The distinct points of `samples` whose id is known neither before nor in this batch.
fn missing_points<'a>(
    samples: &[&'a SampleRow],
    known: &HashMap<String, i32>,
    new: &HashMap<String, i32>,
) -> Vec<Names<'a>> {
    let mut key = String::new();
    let mut seen = HashSet::new();
    let mut missing = Vec::new();
    for s in samples {
        point_key(&mut key, &s.group, &s.node, &s.device, &s.point);
        if !known.contains_key(&key) && !new.contains_key(&key) && seen.insert(key.clone()) {
            missing.push((
                s.group.as_str(),
                s.node.as_str(),
                s.device.as_str(),
                s.point.as_str(),
            ));
        }
    }
    // One lock order for every historian (see `Accepted::sort`).
    missing.sort_unstable_by_key(|&(group, node, device, point)| (node, device, point, group));
    missing
}

/// Gives the points and events of version-1 rows (group `''`) of each node to the group it
/// is now seen in, unless that group has the same point or event already: a database written before the group
/// was recorded keeps one history per point across the upgrade. Runs for the batches that
/// define points (births) or name points this connection has no id for; the partial
/// indexes of version 2 (`points_ungrouped`, `events_ungrouped`) keep it to the rows still
/// without a group, none once every node has been born.
async fn adopt_ungrouped<'a>(
    tx: &Transaction<'_>,
    statements: &Statements,
    pairs: impl Iterator<Item = (&'a str, &'a str)>,
) -> Result<(), StoreError> {
    let (groups, nodes): (Vec<&str>, Vec<&str>) = pairs.unzip();
    tx.execute(&statements.adopt_ungrouped, &[&groups, &nodes])
        .await
        .map_err(|e| StoreError::statement("giving points stored without a group theirs", e))?;
    tx.execute(&statements.adopt_ungrouped_events, &[&groups, &nodes])
        .await
        .map_err(|e| StoreError::statement("giving events stored without a group theirs", e))?;
    Ok(())
}

/// Gives points known only by name a bare row (unless another historian just did) and
/// records their ids; returns how many rows this created.
async fn insert_bare_points(
    tx: &Transaction<'_>,
    statements: &Statements,
    missing: &[Names<'_>],
    ids: &mut HashMap<String, i32>,
) -> Result<u64, StoreError> {
    if missing.is_empty() {
        return Ok(0);
    }
    adopt_ungrouped(tx, statements, missing.iter().map(|m| (m.0, m.1))).await?;
    let groups: Vec<&str> = missing.iter().map(|m| m.0).collect();
    let nodes: Vec<&str> = missing.iter().map(|m| m.1).collect();
    let devices: Vec<&str> = missing.iter().map(|m| m.2).collect();
    let names: Vec<&str> = missing.iter().map(|m| m.3).collect();
    let created = tx
        .execute(
            &statements.insert_bare_points,
            &[&groups, &nodes, &devices, &names],
        )
        .await
        .map_err(|e| StoreError::statement("inserting points known only by name", e))?;
    let rows = tx
        .query(&statements.point_ids, &[&groups, &nodes, &devices, &names])
        .await
        .map_err(|e| StoreError::statement("reading the ids of points", e))?;
    record_ids(&rows, ids);
    Ok(created)
}

fn record_ids(rows: &[tokio_postgres::Row], ids: &mut HashMap<String, i32>) {
    for row in rows {
        let mut key = String::new();
        point_key(&mut key, row.get(1), row.get(2), row.get(3), row.get(4));
        ids.insert(key, row.get(0));
    }
}

/// Copies the samples into the staging table; returns how many.
async fn copy_samples(
    tx: &Transaction<'_>,
    samples: &[&SampleRow],
    known: &HashMap<String, i32>,
    new: &HashMap<String, i32>,
    key: &mut String,
) -> Result<u64, StoreError> {
    if samples.is_empty() {
        return Ok(0);
    }
    const DURING: &str = "copying samples into the staging table";
    let sink = tx
        .copy_in(COPY_STAGING)
        .await
        .map_err(|e| StoreError::statement(DURING, e))?;
    let writer = BinaryCopyInWriter::new(sink, &STAGING_TYPES);
    pin_mut!(writer);
    for s in samples {
        point_key(key, &s.group, &s.node, &s.device, &s.point);
        // Every point got an id above: known, from the batch's points or bare (unless the
        // row was deleted meanwhile by hand).
        let Some(id) = known.get(key.as_str()).or_else(|| new.get(key.as_str())) else {
            tracing::warn!(
                "no points row for {}: its sample is not written",
                display_point(&s.node, &s.device, &s.point)
            );
            continue;
        };
        let quality = rows::stored_quality(s.quality);
        writer
            .as_mut()
            .write(&[id, &s.t, &s.value, &s.text, &quality])
            .await
            .map_err(|e| StoreError::statement(DURING, e))?;
    }
    writer
        .finish()
        .await
        .map_err(|e| StoreError::statement(DURING, e))
}

/// Inserts the events not stored yet; returns how many.
async fn insert_events(
    tx: &Transaction<'_>,
    statements: &Statements,
    events: &[&EventRow],
) -> Result<u64, StoreError> {
    if events.is_empty() {
        return Ok(0);
    }
    let text = |f: fn(&EventRow) -> &str| events.iter().map(|e| f(e)).collect::<Vec<_>>();
    let optional =
        |f: fn(&EventRow) -> Option<&str>| events.iter().map(|e| f(e)).collect::<Vec<_>>();
    tx.execute(
        &statements.insert_events,
        &[
            &events.iter().map(|e| e.t).collect::<Vec<_>>(),
            &text(|e| &e.node),
            &optional(|e| e.device.as_deref()),
            &optional(|e| e.point.as_deref()),
            &optional(|e| e.line.as_deref()),
            &text(|e| &e.kind),
            &events.iter().map(|e| e.severity).collect::<Vec<_>>(),
            &text(|e| &e.message),
            &text(|e| &e.group),
            &optional(|e| e.fields.as_deref()),
        ],
    )
    .await
    .map_err(|e| StoreError::statement("inserting events", e))
}

/// The cache key of a point: its four names joined by NUL (which no name holds: rows
/// with a NUL are refused).
fn point_key(key: &mut String, group: &str, node: &str, device: &str, point: &str) {
    key.clear();
    key.push_str(group);
    key.push('\0');
    key.push_str(node);
    key.push('\0');
    key.push_str(device);
    key.push('\0');
    key.push_str(point);
}

/// `node/device.point` (the plant API's point id), or `node/point` for a node's metric.
fn display_point(node: &str, device: &str, point: &str) -> String {
    if device.is_empty() {
        format!("{node}/{point}")
    } else {
        format!("{node}/{device}.{point}")
    }
}

/// Whether a row with `texts` and `optional` texts, read at `t`, can be stored: no NUL
/// character (PostgreSQL's text cannot hold one), and a time [`check_time`] takes.
fn verdict(
    texts: &[&String],
    optional: &[&Option<String>],
    t: SystemTime,
    now: SystemTime,
    max_age: Option<Duration>,
) -> Result<(), RefusalReason> {
    if texts.iter().any(|t| has_nul(t)) || optional.iter().any(|t| has_nul_opt(t)) {
        Err(RefusalReason::NulCharacter)
    } else {
        check_time(t, now, max_age)
    }
}

fn has_nul(text: &str) -> bool {
    text.contains('\0')
}

fn has_nul_opt(text: &Option<String>) -> bool {
    text.as_deref().is_some_and(has_nul)
}

/// `user@host:port/db` for messages (never the password).
fn describe_target(config: &Config) -> String {
    use tokio_postgres::config::Host;
    let host = match config.get_hosts().first() {
        Some(Host::Tcp(name)) => name.clone(),
        Some(Host::Unix(path)) => path.display().to_string(),
        None => "localhost".to_owned(),
    };
    let port = config.get_ports().first().copied().unwrap_or(5432);
    format!(
        "{}@{host}:{port}/{}",
        config.get_user().unwrap_or("?"),
        config.get_dbname().unwrap_or("(the user's database)")
    )
}

#[cfg(test)]
mod tests;
