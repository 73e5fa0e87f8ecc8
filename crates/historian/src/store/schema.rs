//! The schema and its versioned migrations.
//!
//! `cellbus_schema` lists the versions applied. Each migration runs in its own transaction
//! with its row in `cellbus_schema`, so it is applied whole or not at all. Historians that
//! start at once serialise on a session advisory lock: the first migrates, the others then
//! find the versions applied and run nothing.

use tokio_postgres::Client;

use super::StoreError;

/// The newest schema version this build writes.
pub const SCHEMA_VERSION: i32 = 5;

/// The advisory lock (per database) held while migrating: "cellbus" and 1.
const MIGRATION_LOCK: i64 = 0x6365_6c6c_6275_7301;

/// The advisory lock (per database) held while creating a day partition: "cellbus" and 2.
pub(crate) const PARTITION_LOCK: i64 = 0x6365_6c6c_6275_7302;

/// How the samples are split by time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SamplesLayout {
    /// Native range partitions of one UTC day each (`samples_2026_01_31`), created by the
    /// store before a batch that needs them.
    DayPartitions,
    /// A TimescaleDB hypertable with one-day chunks, which TimescaleDB creates itself.
    Hypertable,
}

/// One step of the schema.
struct Migration {
    version: i32,
    what: &'static str,
    statements: fn(SamplesLayout) -> Vec<&'static str>,
}

/// Every migration, oldest first. Never edit one that has shipped: add the next.
const MIGRATIONS: &[Migration] = &[
    Migration {
        version: 1,
        what: "points, samples by day, events and the cellbus_* views",
        statements: version_1,
    },
    Migration {
        version: 2,
        what: "the Sparkplug group in the identity of points and events",
        statements: version_2,
    },
    Migration {
        version: 3,
        what: "events keep their fields (the facts beside the words)",
        statements: version_3,
    },
    Migration {
        version: 4,
        what: "the cellbus_states view: each device's machine states as intervals",
        statements: version_4,
    },
    Migration {
        version: 5,
        what: "the cellbus_alarms view: the gateways' alarm journals",
        statements: version_5,
    },
];

fn version_1(layout: SamplesLayout) -> Vec<&'static str> {
    let samples = match layout {
        SamplesLayout::DayPartitions => {
            "CREATE TABLE samples (
                point_id integer NOT NULL,
                t timestamptz NOT NULL,
                value double precision,
                text text,
                quality smallint NOT NULL,
                PRIMARY KEY (point_id, t)
            ) PARTITION BY RANGE (t)"
        }
        SamplesLayout::Hypertable => {
            "CREATE TABLE samples (
                point_id integer NOT NULL,
                t timestamptz NOT NULL,
                value double precision,
                text text,
                quality smallint NOT NULL,
                PRIMARY KEY (point_id, t)
            )"
        }
    };
    let mut statements = vec![
        "CREATE TABLE points (
            id integer GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
            node text NOT NULL,
            device text NOT NULL,
            point text NOT NULL,
            datatype text NOT NULL DEFAULT 'unknown',
            unit text,
            description text,
            writable boolean NOT NULL DEFAULT false,
            write_min double precision,
            write_max double precision,
            UNIQUE (node, device, point)
        )",
        samples,
    ];
    if layout == SamplesLayout::Hypertable {
        statements.push(
            "SELECT create_hypertable('samples', 't', chunk_time_interval => INTERVAL '1 day')",
        );
    }
    statements.extend([
        "CREATE TABLE events (
            id bigint GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
            t timestamptz NOT NULL,
            node text NOT NULL,
            device text,
            point text,
            line text,
            kind text NOT NULL,
            severity integer NOT NULL,
            message text NOT NULL
        )",
        // An event replayed from a backlog is the same node, device, point, time, kind and
        // message; the message is compared by its hash (a long one would not fit a b-tree
        // entry). NULLS NOT DISTINCT (PostgreSQL 15): an event without a device is still
        // one event.
        "CREATE UNIQUE INDEX events_once ON events (node, device, point, t, kind, md5(message))
            NULLS NOT DISTINCT",
        "CREATE INDEX events_by_time ON events (t)",
        "CREATE VIEW cellbus_samples AS
            SELECT p.node, p.device, p.point, s.t, s.value, s.text,
                (CASE s.quality WHEN 0 THEN 'good' WHEN 1 THEN 'stale' ELSE 'bad' END)::text
                    AS quality
            FROM samples s JOIN points p ON p.id = s.point_id",
        "CREATE VIEW cellbus_events AS
            SELECT t, node, device, point, line, kind, severity, message FROM events",
        "CREATE VIEW cellbus_points AS
            SELECT node, device, point, unit, description, datatype, writable, write_min,
                write_max
            FROM points",
    ]);
    statements
}

/// Version 2: the same edge node id in two Sparkplug groups is two nodes. Points and events
/// get `group_id` (`''` for the rows of version 1, whose group was not recorded: the next
/// birth of their node claims them, see `store::adopt_ungrouped`), the views show it as
/// their last column, and a point's unique key leads with its node (the plant API looks
/// points up by node). The rows still without a group have partial indexes of their own,
/// so the claim every birth asks for reads none of a node's grouped rows (a gateway's
/// events number millions).
fn version_2(_: SamplesLayout) -> Vec<&'static str> {
    vec![
        "ALTER TABLE points ADD COLUMN group_id text NOT NULL DEFAULT ''",
        "ALTER TABLE points DROP CONSTRAINT points_node_device_point_key",
        "ALTER TABLE points ADD CONSTRAINT points_identity UNIQUE (node, device, point, group_id)",
        "CREATE INDEX points_ungrouped ON points (node) WHERE group_id = ''",
        "ALTER TABLE events ADD COLUMN group_id text NOT NULL DEFAULT ''",
        "CREATE INDEX events_ungrouped ON events (node) WHERE group_id = ''",
        "DROP INDEX events_once",
        "CREATE UNIQUE INDEX events_once
            ON events (node, device, point, t, kind, md5(message), group_id) NULLS NOT DISTINCT",
        "CREATE OR REPLACE VIEW cellbus_samples AS
            SELECT p.node, p.device, p.point, s.t, s.value, s.text,
                (CASE s.quality WHEN 0 THEN 'good' WHEN 1 THEN 'stale' ELSE 'bad' END)::text
                    AS quality,
                p.group_id
            FROM samples s JOIN points p ON p.id = s.point_id",
        "CREATE OR REPLACE VIEW cellbus_events AS
            SELECT t, node, device, point, line, kind, severity, message, group_id FROM events",
        "CREATE OR REPLACE VIEW cellbus_points AS
            SELECT node, device, point, unit, description, datatype, writable, write_min,
                write_max, group_id
            FROM points",
    ]
}

/// Version 3: an event's facts for programs (`{"feeder":7}`), as the gateways send them in
/// the `Event` metric's `fields` property; NULL for events without any and for older rows.
/// The events view shows them as its last column.
fn version_3(_: SamplesLayout) -> Vec<&'static str> {
    vec![
        "ALTER TABLE events ADD COLUMN fields jsonb",
        "CREATE OR REPLACE VIEW cellbus_events AS
            SELECT t, node, device, point, line, kind, severity, message, group_id, fields
            FROM events",
    ]
}

/// Version 4: `cellbus_states(node, device, start, "end", state, code, category, reason,
/// group_id)`, each device's machine states as intervals, made from the three points a
/// gateway publishes for a device that reports its state: `machine_state` (the device's
/// word), `machine_state_code` (the SEMI E10 / IPC-CFX code) and `machine_state_reason`
/// (text, empty when none). The rules are the gateway's own (`production::states`):
///
/// - every instant one of the three has a sample is a moment; at each moment each point
///   holds its latest sample at or before it (a point that did not change sent nothing);
/// - a stale sample changes nothing: the gateway still had the reading (late on a busy
///   line, or not sent while the historian was offline, whose changes come later with
///   their own times), and the gateway's own rule keeps a stale value; Sparkplug carries
///   no value with it, so the view passes over it;
/// - the state is unknown (code 0, category `unknown`, no reason) when the state or the
///   code holds no value: a bad sample (the device not answering, its gateway dead) or no
///   sample yet;
/// - the category is the code's thousands (1 productive … 6 non_scheduled); a code off the
///   scale (not 1000–6999, or not whole) is 0 and `unknown`, with the device's word kept;
/// - an empty reason is NULL;
/// - a moment that holds the same state, code and reason as the one before (a rebirth
///   sending the values again) continues its interval;
/// - an interval ends where the device's next one starts; the last one's end is NULL (it
///   is still open).
///
/// The view is computed from the samples of the device's three points each time it is
/// read: a condition on node and device reaches the samples (they are the partitions of
/// every window), a condition on time does not (an interval's end is the next start), so a
/// query reads the whole state history of the devices it names. Run-length counts carry
/// each point's last sample forward (`state_run` and its kin number the point's samples so
/// far; within one run the first row holds the sample).
fn version_4(_: SamplesLayout) -> Vec<&'static str> {
    vec![
        r#"CREATE VIEW cellbus_states AS
            SELECT node, device, start, lead(start) OVER device_time AS "end", state, code,
                category, reason, group_id
            FROM (
                SELECT group_id, node, device, start, state, code, category, reason,
                    state IS DISTINCT FROM lag(state) OVER device_time
                        OR code IS DISTINCT FROM lag(code) OVER device_time
                        OR reason IS DISTINCT FROM lag(reason) OVER device_time AS changed
                FROM (
                    SELECT group_id, node, device, t AS start,
                        CASE WHEN known THEN state ELSE 'unknown' END AS state,
                        CASE WHEN known THEN code ELSE 0 END AS code,
                        CASE WHEN known THEN
                            CASE code / 1000
                                WHEN 1 THEN 'productive'
                                WHEN 2 THEN 'standby'
                                WHEN 3 THEN 'engineering'
                                WHEN 4 THEN 'scheduled_down'
                                WHEN 5 THEN 'unscheduled_down'
                                WHEN 6 THEN 'non_scheduled'
                                ELSE 'unknown'
                            END
                        ELSE 'unknown' END AS category,
                        CASE WHEN known THEN nullif(reason, '') END AS reason
                    FROM (
                        SELECT group_id, node, device, t, state, reason,
                            state IS NOT NULL AND code_value IS NOT NULL AS known,
                            CASE WHEN code_value >= 1000 AND code_value < 7000
                                    AND code_value = trunc(code_value)
                                THEN code_value::integer ELSE 0 END AS code
                        FROM (
                            SELECT group_id, node, device, t,
                                first_value(state) OVER (PARTITION BY group_id, node,
                                    device, state_run ORDER BY t) AS state,
                                first_value(code) OVER (PARTITION BY group_id, node,
                                    device, code_run ORDER BY t) AS code_value,
                                first_value(reason) OVER (PARTITION BY group_id, node,
                                    device, reason_run ORDER BY t) AS reason
                            FROM (
                                SELECT group_id, node, device, t, state, code, reason,
                                    count(*) FILTER (WHERE has_state) OVER device_time
                                        AS state_run,
                                    count(*) FILTER (WHERE has_code) OVER device_time
                                        AS code_run,
                                    count(*) FILTER (WHERE has_reason) OVER device_time
                                        AS reason_run
                                FROM (
                                    SELECT p.group_id, p.node, p.device, s.t,
                                        bool_or(p.point = 'machine_state') AS has_state,
                                        bool_or(p.point = 'machine_state_code') AS has_code,
                                        bool_or(p.point = 'machine_state_reason')
                                            AS has_reason,
                                        max(s.text) FILTER (WHERE p.point = 'machine_state')
                                            AS state,
                                        max(s.value)
                                            FILTER (WHERE p.point = 'machine_state_code')
                                            AS code,
                                        max(s.text)
                                            FILTER (WHERE p.point = 'machine_state_reason')
                                            AS reason
                                    FROM samples s JOIN points p ON p.id = s.point_id
                                    WHERE p.point IN ('machine_state', 'machine_state_code',
                                        'machine_state_reason')
                                        AND s.quality <> 1
                                    GROUP BY p.group_id, p.node, p.device, s.t
                                ) moments
                                WINDOW device_time AS (PARTITION BY group_id, node, device
                                    ORDER BY t)
                            ) runs
                        ) held
                    ) coded
                ) worded
                WINDOW device_time AS (PARTITION BY group_id, node, device ORDER BY start)
            ) compared
            WHERE changed
            WINDOW device_time AS (PARTITION BY group_id, node, device ORDER BY start)"#,
    ]
}

/// Version 5: `cellbus_alarms(t, node, device, point, alarm, kind, changes, state,
/// acknowledged, priority, who, comment, value, message, group_id)`, the gateways' alarm
/// journals: their alarm events (`alarm_raised`, `alarm_cleared`, `alarm_changed`) with
/// the facts each carries in its fields (`alarm` id, what changed, the state after, the
/// operator and the comment of an acknowledgement or shelving). Older alarm events (from a
/// gateway before the journal) have no `alarm` field and are not shown.
fn version_5(_: SamplesLayout) -> Vec<&'static str> {
    vec![
        "CREATE INDEX events_alarms ON events (t) WHERE kind IN ('alarm_raised', \
            'alarm_cleared', 'alarm_changed')",
        "CREATE VIEW cellbus_alarms AS
            SELECT t, node, device, point, fields->>'alarm' AS alarm, kind,
                ARRAY(SELECT jsonb_array_elements_text(
                    CASE jsonb_typeof(fields->'changes') WHEN 'array' THEN fields->'changes'
                        ELSE '[]'::jsonb END)) AS changes,
                fields->>'state' AS state,
                (fields->>'acknowledged')::boolean AS acknowledged,
                fields->>'priority' AS priority,
                fields->>'by' AS who,
                fields->>'comment' AS comment,
                fields->'value' AS value,
                message, group_id
            FROM events
            WHERE kind IN ('alarm_raised', 'alarm_cleared', 'alarm_changed')
                AND fields ? 'alarm'",
    ]
}

/// Brings the schema to [`SCHEMA_VERSION`]; returns the versions it applied.
pub(crate) async fn migrate(client: &mut Client) -> Result<Vec<i32>, StoreError> {
    migrate_to(client, SCHEMA_VERSION).await
}

/// Brings the schema to `target` (an older version only in tests of a migration).
pub(crate) async fn migrate_to(client: &mut Client, target: i32) -> Result<Vec<i32>, StoreError> {
    client
        .execute("SELECT pg_advisory_lock($1)", &[&MIGRATION_LOCK])
        .await
        .map_err(|e| StoreError::statement("taking the migration lock", e))?;
    let result = migrate_locked(client, target).await;
    // Released with the session too, if this fails.
    let unlocked = client
        .execute("SELECT pg_advisory_unlock($1)", &[&MIGRATION_LOCK])
        .await
        .map_err(|e| StoreError::statement("releasing the migration lock", e));
    let applied = result?;
    unlocked?;
    Ok(applied)
}

async fn migrate_locked(client: &mut Client, target: i32) -> Result<Vec<i32>, StoreError> {
    client
        .batch_execute(
            "CREATE TABLE IF NOT EXISTS cellbus_schema (
                version integer PRIMARY KEY,
                what text NOT NULL,
                applied timestamptz NOT NULL DEFAULT now()
            )",
        )
        .await
        .map_err(|e| StoreError::statement("creating cellbus_schema", e))?;
    let found: i32 = client
        .query_one("SELECT coalesce(max(version), 0) FROM cellbus_schema", &[])
        .await
        .map_err(|e| StoreError::statement("reading the schema version", e))?
        .get(0);
    if found > SCHEMA_VERSION {
        return Err(StoreError::SchemaTooNew {
            found,
            known: SCHEMA_VERSION,
        });
    }
    let mut applied = Vec::new();
    for migration in MIGRATIONS
        .iter()
        .filter(|m| m.version > found && m.version <= target)
    {
        let tx = client
            .transaction()
            .await
            .map_err(|e| StoreError::statement("starting a migration", e))?;
        let layout = choose_layout(&tx).await?;
        for statement in (migration.statements)(layout) {
            tx.batch_execute(statement)
                .await
                .map_err(|e| StoreError::statement("migrating the schema", e))?;
        }
        tx.execute(
            "INSERT INTO cellbus_schema (version, what) VALUES ($1, $2)",
            &[&migration.version, &migration.what],
        )
        .await
        .map_err(|e| StoreError::statement("recording a migration", e))?;
        tx.commit()
            .await
            .map_err(|e| StoreError::statement("committing a migration", e))?;
        tracing::info!(
            version = migration.version,
            what = migration.what,
            ?layout,
            "schema migrated"
        );
        applied.push(migration.version);
    }
    Ok(applied)
}

/// A hypertable when TimescaleDB is installed or can be (`CREATE EXTENSION` fails when
/// the library is not preloaded or the user may not: then native partitions, logged).
async fn choose_layout(tx: &tokio_postgres::Transaction<'_>) -> Result<SamplesLayout, StoreError> {
    let available: bool = tx
        .query_one(
            "SELECT EXISTS (SELECT 1 FROM pg_available_extensions WHERE name = 'timescaledb')",
            &[],
        )
        .await
        .map_err(|e| StoreError::statement("looking for TimescaleDB", e))?
        .get(0);
    if !available {
        return Ok(SamplesLayout::DayPartitions);
    }
    tx.batch_execute("SAVEPOINT timescaledb")
        .await
        .map_err(|e| StoreError::statement("looking for TimescaleDB", e))?;
    match tx
        .batch_execute("CREATE EXTENSION IF NOT EXISTS timescaledb")
        .await
    {
        Ok(()) => Ok(SamplesLayout::Hypertable),
        Err(e) => {
            let e = StoreError::statement("creating the TimescaleDB extension", e);
            if e.is_connection_lost() {
                return Err(e);
            }
            tracing::warn!(
                "TimescaleDB is available but cannot be used ({e}); samples go to native day partitions"
            );
            tx.batch_execute("ROLLBACK TO SAVEPOINT timescaledb")
                .await
                .map_err(|e| StoreError::statement("looking for TimescaleDB", e))?;
            Ok(SamplesLayout::DayPartitions)
        }
    }
}

/// The layout of an existing `samples` table: partitioned (`relkind` p) or a hypertable.
pub(crate) async fn layout(client: &Client) -> Result<SamplesLayout, StoreError> {
    let kind: String = client
        .query_one(
            "SELECT relkind::text FROM pg_class WHERE oid = 'samples'::regclass",
            &[],
        )
        .await
        .map_err(|e| StoreError::statement("reading the samples table's kind", e))?
        .get(0);
    Ok(if kind == "p" {
        SamplesLayout::DayPartitions
    } else {
        SamplesLayout::Hypertable
    })
}
