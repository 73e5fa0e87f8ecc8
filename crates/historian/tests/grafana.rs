//! The Grafana pack (`deploy/grafana`): its dashboards are valid dashboard JSON on the
//! provisioned data sources; every SQL query of theirs runs, as Grafana would send it, on a
//! real PostgreSQL holding the historian's schema and a day of a cell's data, read by a role
//! that may only read the `cellbus_*` views (as the pack's README sets it up), and answers
//! with the columns its panel shows; every PromQL expression parses (Prometheus's own
//! `promtool`) and names only metrics the gateway registers.
//!
//! Here rather than in a crate of its own: the historian's schema and store write the test
//! data, and testkit's PostgreSQL is at hand.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use historian::{Batch, EventRow, PointRow, Quality, SampleRow, Store};
use serde_json::Value;
use testkit::Postgres;
use tokio_postgres::{NoTls, SimpleQueryMessage};

/// The pack, from this crate's directory.
fn pack() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/grafana")
}

/// The data sources the provisioning file defines: uid → type.
fn provisioned_sources() -> BTreeMap<String, String> {
    let path = pack().join("provisioning/datasources/cellbus.yaml");
    let yaml: serde_yaml::Value = read_yaml(&path);
    assert_eq!(yaml["apiVersion"].as_u64(), Some(1), "{}", path.display());
    let sources = yaml["datasources"]
        .as_sequence()
        .unwrap_or_else(|| panic!("{}: no datasources list", path.display()));
    sources
        .iter()
        .map(|source| {
            let text = |key: &str| {
                source[key]
                    .as_str()
                    .unwrap_or_else(|| panic!("{}: a source without {key}", path.display()))
                    .to_owned()
            };
            (text("uid"), text("type"))
        })
        .collect()
}

fn read_yaml(path: &Path) -> serde_yaml::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_yaml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every dashboard of the pack: file name and JSON.
fn dashboards() -> Vec<(String, Value)> {
    let dir = pack().join("dashboards");
    let mut found: Vec<(String, Value)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|entry| entry.expect("a directory entry").path())
        .filter(|path| path.extension().is_some_and(|e| e == "json"))
        .map(|path| {
            let text = std::fs::read_to_string(&path).expect("a dashboard file");
            let json = serde_json::from_str(&text)
                .unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()));
            let name = path.file_name().expect("a file name").to_string_lossy();
            (name.into_owned(), json)
        })
        .collect();
    found.sort_by(|a, b| a.0.cmp(&b.0));
    let names: Vec<&str> = found.iter().map(|(name, _)| name.as_str()).collect();
    assert_eq!(names, ["cell-overview.json", "gateway-health.json"]);
    found
}

/// Every panel of a dashboard, those inside collapsed rows included.
fn panels(dashboard: &Value) -> Vec<&Value> {
    let mut all = Vec::new();
    for panel in dashboard["panels"].as_array().expect("a panels list") {
        all.push(panel);
        if let Some(inner) = panel["panels"].as_array() {
            all.extend(inner);
        }
    }
    all
}

/// One query of a dashboard.
#[derive(Debug)]
struct Query {
    /// The dashboard's file.
    dashboard: String,
    /// What it belongs to: a panel's title, `variable NAME` or `annotation NAME`.
    owner: String,
    /// The data source's uid.
    source: String,
    /// The SQL (`rawSql`) or the PromQL (`expr`), as written in the dashboard.
    text: String,
}

impl Query {
    fn place(&self) -> String {
        format!("{}: {}", self.dashboard, self.owner)
    }
}

/// The data source uid a `datasource` object names.
fn uid_of(datasource: &Value, place: &str) -> String {
    datasource["uid"]
        .as_str()
        .unwrap_or_else(|| panic!("{place}: no data source uid in {datasource}"))
        .to_owned()
}

/// The uid of the provisioned source `datasource` names, whose type it gives too.
fn provisioned(sources: &BTreeMap<String, String>, datasource: &Value, place: &str) -> String {
    let uid = uid_of(datasource, place);
    let kind = sources
        .get(&uid)
        .unwrap_or_else(|| panic!("{place}: {uid} is not a provisioned source"));
    assert_eq!(datasource["type"].as_str(), Some(kind.as_str()), "{place}");
    uid
}

/// Every query of a dashboard: its panels' targets, its variables', its annotations'.
fn queries(name: &str, dashboard: &Value) -> Vec<Query> {
    let mut all = Vec::new();
    for panel in panels(dashboard) {
        let title = panel["title"].as_str().unwrap_or_default();
        for target in panel["targets"].as_array().into_iter().flatten() {
            let place = format!("{name}: {title}");
            let text = target["rawSql"]
                .as_str()
                .or(target["expr"].as_str())
                .unwrap_or_else(|| panic!("{place}: a target without rawSql or expr"));
            all.push(Query {
                dashboard: name.to_owned(),
                owner: title.to_owned(),
                source: uid_of(&target["datasource"], &place),
                text: text.to_owned(),
            });
        }
    }
    for variable in dashboard["templating"]["list"]
        .as_array()
        .expect("variables")
    {
        if variable["type"] != "query" {
            continue;
        }
        let owner = format!("variable {}", variable["name"].as_str().unwrap_or_default());
        let place = format!("{name}: {owner}");
        let text = variable["query"]
            .as_str()
            .or(variable["query"]["rawSql"].as_str())
            .or(variable["query"]["query"].as_str())
            .unwrap_or_else(|| panic!("{place}: no query"));
        all.push(Query {
            dashboard: name.to_owned(),
            source: uid_of(&variable["datasource"], &place),
            owner,
            text: text.to_owned(),
        });
    }
    for annotation in dashboard["annotations"]["list"]
        .as_array()
        .expect("annotations")
    {
        if annotation["builtIn"] == 1 {
            continue;
        }
        let owner = format!(
            "annotation {}",
            annotation["name"].as_str().unwrap_or_default()
        );
        let place = format!("{name}: {owner}");
        let text = annotation["target"]["rawSql"]
            .as_str()
            .unwrap_or_else(|| panic!("{place}: no rawSql"));
        all.push(Query {
            dashboard: name.to_owned(),
            source: uid_of(&annotation["datasource"], &place),
            owner,
            text: text.to_owned(),
        });
    }
    all
}

/// The names of the variables a query uses (`$node`, `${node}`), Grafana's own (`$__…`)
/// left out.
fn variables_used(text: &str) -> BTreeSet<String> {
    let mut used = BTreeSet::new();
    let mut rest = text;
    while let Some(at) = rest.find('$') {
        rest = &rest[at + 1..];
        let braced = rest.starts_with('{');
        let name: String = rest[usize::from(braced)..]
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        if !name.is_empty() && !name.starts_with("__") {
            used.insert(name);
        }
    }
    used
}

#[test]
fn the_dashboards_are_valid_dashboard_json_on_the_provisioned_data_sources() {
    let sources = provisioned_sources();
    assert_eq!(
        sources,
        BTreeMap::from([
            (
                "cellbus-historian".to_owned(),
                "grafana-postgresql-datasource".to_owned()
            ),
            ("cellbus-prometheus".to_owned(), "prometheus".to_owned()),
        ])
    );
    let datasources = read_yaml(&pack().join("provisioning/datasources/cellbus.yaml"));
    let password = datasources["datasources"]
        .as_sequence()
        .and_then(|s| s.iter().find(|d| d["uid"] == "cellbus-historian"))
        .and_then(|d| d["secureJsonData"]["password"].as_str())
        .expect("the historian's password");
    assert!(
        password.starts_with('$'),
        "the password comes from Grafana's environment, never the file: {password:?}"
    );
    let providers = read_yaml(&pack().join("provisioning/dashboards/cellbus.yaml"));
    assert_eq!(providers["apiVersion"].as_u64(), Some(1));
    let provider = &providers["providers"][0];
    assert_eq!(provider["type"].as_str(), Some("file"));
    assert!(
        provider["options"]["path"]
            .as_str()
            .is_some_and(|p| p.starts_with('/')),
        "the dashboards' folder: {provider:?}"
    );

    let dashboards = dashboards();
    let uids: BTreeSet<&str> = dashboards
        .iter()
        .map(|(name, d)| {
            d["uid"]
                .as_str()
                .filter(|uid| !uid.is_empty() && uid.len() <= 40)
                .unwrap_or_else(|| panic!("{name}: a uid of 1 to 40 characters"))
        })
        .collect();
    assert_eq!(uids.len(), dashboards.len(), "the dashboards' uids differ");
    for (name, dashboard) in &dashboards {
        assert_eq!(dashboard["schemaVersion"].as_u64(), Some(39), "{name}");
        assert!(
            dashboard["title"].as_str().is_some_and(|t| !t.is_empty()),
            "{name}"
        );
        // Links between the dashboards go to dashboards of the pack.
        for link in dashboard["links"].as_array().expect("a links list") {
            let url = link["url"].as_str().unwrap_or_default();
            let target = url.strip_prefix("/d/").unwrap_or(url);
            assert!(uids.contains(target), "{name}: a link to {url}");
        }
        let variables: BTreeMap<&str, &Value> = dashboard["templating"]["list"]
            .as_array()
            .expect("a templating list")
            .iter()
            .map(|v| (v["name"].as_str().expect("a variable's name"), v))
            .collect();
        let mut ids = BTreeSet::new();
        for panel in panels(dashboard) {
            let title = panel["title"].as_str().unwrap_or_default();
            let place = format!("{name}: panel {title:?}");
            let id = panel["id"]
                .as_u64()
                .unwrap_or_else(|| panic!("{place}: no id"));
            assert!(ids.insert(id), "{place}: the id {id} is taken");
            assert!(panel["type"].as_str().is_some(), "{place}: no type");
            let grid = &panel["gridPos"];
            let [h, w, x, _y] = ["h", "w", "x", "y"].map(|k| {
                grid[k]
                    .as_u64()
                    .unwrap_or_else(|| panic!("{place}: gridPos.{k}"))
            });
            assert!(h > 0 && w > 0 && x + w <= 24, "{place}: gridPos {grid}");
            if let Some(repeat) = panel["repeat"].as_str() {
                let variable = variables
                    .get(repeat)
                    .unwrap_or_else(|| panic!("{place}: repeats over ${repeat}, not defined"));
                assert_eq!(
                    variable["multi"], true,
                    "{place}: repeats over a single value"
                );
            }
            let Some(targets) = panel["targets"].as_array() else {
                assert_eq!(panel["type"], "row", "{place}: a panel without queries");
                continue;
            };
            let source = provisioned(&sources, &panel["datasource"], &place);
            let mut refs = BTreeSet::new();
            for target in targets {
                assert_eq!(
                    provisioned(&sources, &target["datasource"], &place),
                    source,
                    "{place}"
                );
                let reference = target["refId"].as_str().expect("a refId");
                assert!(refs.insert(reference), "{place}: refId {reference} twice");
            }
        }
        assert!(!ids.is_empty(), "{name}: no panels");
        let sourced = variables
            .values()
            .map(|v| (format!("variable {}", v["name"]), &v["datasource"]))
            .filter(|(_, source)| !source.is_null())
            .chain(
                dashboard["annotations"]["list"]
                    .as_array()
                    .expect("an annotations list")
                    .iter()
                    .filter(|a| a["builtIn"] != 1)
                    .map(|a| (format!("annotation {}", a["name"]), &a["datasource"])),
            );
        for (owner, source) in sourced {
            provisioned(&sources, source, &format!("{name}: {owner}"));
        }
        for query in queries(name, dashboard) {
            for used in variables_used(&query.text) {
                assert!(
                    variables.contains_key(used.as_str()),
                    "{}: uses ${used}, which the dashboard does not define",
                    query.place()
                );
            }
        }
    }
}

// --- SQL -------------------------------------------------------------------------------

/// 2025-03-10T00:00:00Z in milliseconds (a Monday; Berlin is UTC+1 that day).
const MIDNIGHT_MS: u64 = 20_157 * 86_400_000;

/// `hh:mm` UTC on that day.
fn at(h: u64, m: u64) -> SystemTime {
    UNIX_EPOCH + Duration::from_millis(MIDNIGHT_MS + h * 3_600_000 + m * 60_000)
}

/// The time range of the dashboards in this test: 04:00 to 16:00 UTC.
fn range() -> (SystemTime, SystemTime) {
    (at(4, 0), at(16, 0))
}

/// A time as Grafana's macros write it (RFC 3339, UTC).
fn rfc3339(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).expect("after 1970").as_secs();
    let (days, secs) = (secs / 86_400, secs % 86_400);
    assert_eq!(days, 20_157, "the test's times are on 2025-03-10");
    format!(
        "2025-03-10T{:02}:{:02}:{:02}Z",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// A dashboard variable's value, as the test sets it.
enum VariableValue {
    /// A single value: Grafana puts it in raw, each `'` doubled.
    One(&'static str),
    /// A multi-value or All variable: Grafana puts in each value quoted, joined by commas.
    Many(&'static [&'static str]),
}

/// The values of the cell overview's variables in this test.
fn sql_variables() -> BTreeMap<&'static str, VariableValue> {
    use VariableValue::{Many, One};
    BTreeMap::from([
        ("node", One("cell1")),
        ("device", Many(&["jbc1", "placer1", "placer2"])),
        ("point", Many(&["air_temperature"])),
        ("state_device", Many(&["placer1"])),
        ("oee_device", Many(&["placer1"])),
        ("shifts", One("06:00 14:00 22:00")),
        ("plant_tz", One("Europe/Berlin")),
    ])
}

/// Replaces each `$name` / `${name}` of `text` by `value(name)`; Grafana's own (`$__…`)
/// are left for [`expand_macros`].
fn replace_variables(text: &str, value: impl Fn(&str) -> String) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find('$') {
        out.push_str(&rest[..at]);
        let after = &rest[at + 1..];
        let braced = after.starts_with('{');
        let body = &after[usize::from(braced)..];
        let len = body
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(body.len());
        let name = &body[..len];
        if name.is_empty() || name.starts_with("__") {
            out.push('$');
            rest = after;
            continue;
        }
        out.push_str(&value(name));
        let consumed = usize::from(braced) + len + usize::from(braced);
        rest = &after[consumed..];
    }
    out.push_str(rest);
    out
}

/// What Grafana sends PostgreSQL for `sql` over `range` with the bucket `interval`: the
/// dashboard's variables, then the global `$__interval`, then the PostgreSQL data source's
/// macros (`pkg/tsdb/grafana-postgresql-datasource/macros.go`). An unknown macro fails, as
/// it does in Grafana.
fn as_grafana_sends(sql: &str, (from, to): (SystemTime, SystemTime), interval: &str) -> String {
    let variables = sql_variables();
    let sql = replace_variables(sql, |name| match variables.get(name) {
        Some(VariableValue::One(v)) => v.replace('\'', "''"),
        Some(VariableValue::Many(vs)) => vs
            .iter()
            .map(|v| format!("'{}'", v.replace('\'', "''")))
            .collect::<Vec<_>>()
            .join(","),
        None => panic!("no value for ${name} in this test"),
    });
    let sql = sql.replace("$__interval", interval);
    let mut out = String::with_capacity(sql.len());
    let mut rest = sql.as_str();
    while let Some(at) = rest.find("$__") {
        out.push_str(&rest[..at]);
        let after = &rest[at + 1..];
        let open = after
            .find('(')
            .unwrap_or_else(|| panic!("a macro without arguments: {after}"));
        let close = after[open..].find(')').expect("a macro's closing bracket") + open;
        let name = &after[..open];
        let args: Vec<&str> = after[open + 1..close].split(',').map(str::trim).collect();
        out.push_str(&expand_macro(name, &args, from, to));
        rest = &after[close + 1..];
    }
    out.push_str(rest);
    out
}

fn expand_macro(name: &str, args: &[&str], from: SystemTime, to: SystemTime) -> String {
    let seconds = |interval: &str| -> u64 {
        let (number, unit) = interval.split_at(interval.len() - 1);
        let n: u64 = number.parse().expect("an interval like 5m");
        n * match unit {
            "s" => 1,
            "m" => 60,
            "h" => 3600,
            other => panic!("an interval unit {other}"),
        }
    };
    match name {
        "__timeFilter" => format!(
            "{} BETWEEN '{}' AND '{}'",
            args[0],
            rfc3339(from),
            rfc3339(to)
        ),
        "__timeFrom" => format!("'{}'", rfc3339(from)),
        "__timeTo" => format!("'{}'", rfc3339(to)),
        "__timeGroup" => {
            let s = seconds(args[1]);
            format!("floor(extract(epoch from {})/{s})*{s}", args[0])
        }
        "__timeGroupAlias" => {
            let s = seconds(args[1]);
            format!("floor(extract(epoch from {})/{s})*{s} AS \"time\"", args[0])
        }
        other => panic!("Grafana's PostgreSQL data source has no macro {other}"),
    }
}

/// What each SQL query answers: its columns, in order.
const EXPECTED_COLUMNS: &[(&str, &[&str])] = &[
    ("Trends", &["time", "metric", "value"]),
    (
        "Machine state: $state_device",
        &["time", "category", "state"],
    ),
    (
        "OEE per shift: $oee_device",
        &["shift", "oee", "availability", "performance", "quality"],
    ),
    ("Stop Pareto: minutes", &["stop", "minutes"]),
    (
        "Stop Pareto",
        &["stop", "category", "minutes", "stops", "cumulative %"],
    ),
    (
        "Time per category",
        &[
            "device",
            "productive",
            "standby",
            "engineering",
            "scheduled_down",
            "unscheduled_down",
            "non_scheduled",
            "unknown",
        ],
    ),
    ("Events", &["time", "device", "kind", "severity", "message"]),
    ("variable node", &["node"]),
    ("variable device", &["device"]),
    ("variable point", &["point"]),
    ("variable state_device", &["device"]),
    ("variable oee_device", &["device"]),
    (
        "annotation Events (severity 700 and above)",
        &["time", "text", "tags"],
    ),
];

/// A day of cell1: a soldering station's temperature, two placement machines' states (one
/// with its OEE), events.
fn cell_day() -> Batch {
    let point = |device: &str, point: &str, datatype: &str| PointRow {
        datatype: datatype.into(),
        ..PointRow::bare("plant", "cell1", device, point)
    };
    let mut points = vec![point("jbc1", "air_temperature", "Double")];
    for device in ["placer1", "placer2"] {
        points.push(point(device, "machine_state", "String"));
        points.push(point(device, "machine_state_code", "Int32"));
        points.push(point(device, "machine_state_reason", "String"));
    }
    for name in ["oee", "oee_availability", "oee_performance", "oee_quality"] {
        points.push(point("placer1", name, "Double"));
    }
    let sample = |device: &str, point: &str, t: SystemTime| SampleRow {
        group: "plant".into(),
        node: "cell1".into(),
        device: device.into(),
        point: point.into(),
        t,
        value: None,
        text: None,
        quality: Quality::Good,
    };
    let mut samples = Vec::new();
    for i in 0..72u32 {
        samples.push(SampleRow {
            value: Some(300.0 + f64::from(i % 7)),
            ..sample(
                "jbc1",
                "air_temperature",
                at(4, 0) + Duration::from_secs(600 * u64::from(i)),
            )
        });
    }
    let state = |device: &str, t: SystemTime, word: Option<&str>, code: f64, reason: &str| {
        let quality = if word.is_some() {
            Quality::Good
        } else {
            Quality::Bad
        };
        [
            SampleRow {
                text: word.map(str::to_owned),
                quality,
                ..sample(device, "machine_state", t)
            },
            SampleRow {
                value: word.map(|_| code),
                quality,
                ..sample(device, "machine_state_code", t)
            },
            SampleRow {
                text: word.map(|_| reason.to_owned()),
                quality,
                ..sample(device, "machine_state_reason", t)
            },
        ]
    };
    samples.extend(state("placer1", at(4, 30), Some("run"), 1100.0, ""));
    samples.extend(state(
        "placer1",
        at(6, 0),
        Some("parts exhausted"),
        5500.0,
        "feeder 7",
    ));
    // The reason changes alone, then the machine runs again.
    samples.push(SampleRow {
        text: Some("feeder 8".into()),
        ..sample("placer1", "machine_state_reason", at(6, 10))
    });
    samples.extend(state("placer1", at(6, 20), Some("run"), 1100.0, ""));
    // The device stops answering, then comes back.
    samples.extend(state("placer1", at(8, 0), None, 0.0, ""));
    samples.extend(state("placer1", at(8, 5), Some("run"), 1100.0, ""));
    samples.extend(state("placer1", at(12, 0), Some("ready"), 2200.0, ""));
    samples.extend(state("placer1", at(12, 30), Some("run"), 1100.0, ""));
    // A stop that began before the range: only its part inside counts.
    samples.extend(state("placer2", at(3, 0), Some("ready"), 2200.0, ""));
    samples.extend(state("placer2", at(4, 30), Some("run"), 1100.0, ""));
    samples.extend(state(
        "placer2",
        at(10, 0),
        Some("error stop"),
        5300.0,
        "servo alarm 12",
    ));
    samples.extend(state("placer2", at(10, 45), Some("run"), 1100.0, ""));
    // OEE of the shift so far (shifts start at 06:00, 14:00 and 22:00 in Berlin, 05:00,
    // 13:00 and 21:00 UTC): the night shift's last value, the morning's rising to 0.72,
    // then the afternoon's from its reset.
    let mut oee = |t: SystemTime, parts: [f64; 4]| {
        for (name, value) in ["oee", "oee_availability", "oee_performance", "oee_quality"]
            .iter()
            .zip(parts)
        {
            samples.push(SampleRow {
                value: Some(value),
                ..sample("placer1", name, t)
            });
        }
    };
    oee(at(4, 30), [0.8, 0.9, 0.95, 0.94]);
    oee(at(6, 0), [0.5, 0.6, 0.9, 0.93]);
    oee(at(12, 59), [0.72, 0.85, 0.9, 0.94]);
    oee(at(13, 0), [0.0, 0.0, 0.0, 0.0]);
    oee(at(15, 0), [0.65, 0.8, 0.85, 0.96]);
    let event =
        |device: Option<&str>, t: SystemTime, kind: &str, severity: i32, message: &str| EventRow {
            group: "plant".into(),
            node: "cell1".into(),
            device: device.map(str::to_owned),
            point: None,
            line: None,
            t,
            kind: kind.into(),
            severity,
            message: message.into(),
            fields: None,
        };
    let events = vec![
        event(
            Some("placer1"),
            at(6, 0),
            "parts_exhausted",
            700,
            "parts exhausted at feeder 7",
        ),
        event(
            Some("placer1"),
            at(8, 0),
            "device_down",
            700,
            "placer1 did not answer",
        ),
        event(None, at(10, 0), "gateway_started", 500, "gateway started"),
    ];
    Batch {
        points,
        samples,
        events,
    }
}

/// The rows of `sql` (each column as text, NULL as `-`) and its column names.
async fn run(client: &tokio_postgres::Client, sql: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let messages = client
        .simple_query(sql)
        .await
        .unwrap_or_else(|e| panic!("{e:?}\nin:\n{sql}"));
    let mut columns = Vec::new();
    let mut rows = Vec::new();
    for message in messages {
        match message {
            SimpleQueryMessage::RowDescription(description) => {
                columns = description.iter().map(|c| c.name().to_owned()).collect();
            }
            SimpleQueryMessage::Row(row) => rows.push(
                (0..row.len())
                    .map(|i| row.get(i).unwrap_or("-").to_owned())
                    .collect(),
            ),
            _ => {}
        }
    }
    (columns, rows)
}

#[tokio::test]
async fn every_sql_query_of_the_dashboards_answers_with_the_columns_its_panel_shows() {
    let pg = Postgres::start();
    let url = pg.create_database("plant");
    let mut store = Store::connect(&url).await.expect("the historian's schema");
    let written = store.write(&cell_day()).await.expect("a day of cell1");
    assert_eq!(written.events, 3);
    // Grafana's role, as README.md makes it: it may read the views and nothing else.
    pg.psql(
        "plant",
        "CREATE ROLE grafana LOGIN; \
         GRANT SELECT ON cellbus_samples, cellbus_events, cellbus_points, cellbus_states \
             TO grafana",
    );
    let (grafana, connection) =
        tokio_postgres::connect(&pg.url_for("plant").replace("cellbus@", "grafana@"), NoTls)
            .await
            .expect("Grafana's role connects");
    tokio::spawn(connection);
    // Only for reading the times below; the queries name their time zones.
    grafana
        .batch_execute("SET TimeZone = 'UTC'")
        .await
        .expect("a time zone");
    let refused = grafana.simple_query("SELECT count(*) FROM samples").await;
    assert!(refused.is_err(), "Grafana's role reads only the views");

    let mut answers: BTreeMap<String, Vec<Vec<String>>> = BTreeMap::new();
    let mut unused: BTreeSet<&str> = EXPECTED_COLUMNS.iter().map(|(o, _)| *o).collect();
    let dashboards = dashboards();
    let sql_queries = dashboards
        .iter()
        .flat_map(|(name, d)| queries(name, d))
        .filter(|q| q.source == "cellbus-historian");
    for query in sql_queries {
        let sent = as_grafana_sends(&query.text, range(), "5m");
        let (columns, rows) = run(&grafana, &sent).await;
        let expected = EXPECTED_COLUMNS
            .iter()
            .find(|(owner, _)| *owner == query.owner)
            .unwrap_or_else(|| panic!("{}: no expected columns named", query.place()))
            .1;
        unused.remove(query.owner.as_str());
        assert_eq!(columns, expected, "{}:\n{sent}", query.place());
        assert!(!rows.is_empty(), "{}: no rows\n{sent}", query.place());
        answers.insert(query.owner, rows);
    }
    assert!(
        unused.is_empty(),
        "expected columns of no query: {unused:?}"
    );

    let rows =
        |owner: &str| -> Vec<String> { answers[owner].iter().map(|row| row.join(" | ")).collect() };
    assert_eq!(rows("variable node"), ["cell1"]);
    assert_eq!(rows("variable state_device"), ["placer1", "placer2"]);
    assert_eq!(rows("variable oee_device"), ["placer1"]);
    assert_eq!(
        rows("variable point"),
        [
            "air_temperature",
            "machine_state_code",
            "oee",
            "oee_availability",
            "oee_performance",
            "oee_quality"
        ]
    );
    // Each shift's last OEE: the night shift's (begun before the range), the morning's
    // final figure, the afternoon's so far.
    assert_eq!(
        rows("OEE per shift: $oee_device"),
        [
            "Sun 09 Mar 22:00 | 0.8 | 0.9 | 0.95 | 0.94",
            "Mon 10 Mar 06:00 | 0.72 | 0.85 | 0.9 | 0.94",
            "Mon 10 Mar 14:00 | 0.65 | 0.8 | 0.85 | 0.96",
        ]
    );
    // The state timeline of placer1 begins with its first state in the range.
    let timeline = rows("Machine state: $state_device");
    assert_eq!(timeline.len(), 8, "{timeline:#?}");
    assert_eq!(timeline[0], "2025-03-10 04:30:00+00 | productive | run");
    assert_eq!(
        timeline[1..5],
        [
            "2025-03-10 06:00:00+00 | unscheduled_down | parts exhausted (feeder 7)",
            "2025-03-10 06:10:00+00 | unscheduled_down | parts exhausted (feeder 8)",
            "2025-03-10 06:20:00+00 | productive | run",
            "2025-03-10 08:00:00+00 | unknown | unknown",
        ]
    );
    // Stops longest first, clipped to the range (placer2's ready began at 03:00).
    assert_eq!(
        rows("Stop Pareto"),
        [
            "placer2: error stop (servo alarm 12) | unscheduled_down | 45.0 | 1 | 34.6",
            "placer1: ready | standby | 30.0 | 1 | 57.7",
            "placer2: ready | standby | 30.0 | 1 | 80.8",
            "placer1: parts exhausted (feeder 7) | unscheduled_down | 10.0 | 1 | 88.5",
            "placer1: parts exhausted (feeder 8) | unscheduled_down | 10.0 | 1 | 96.2",
            "placer1: unknown | unknown | 5.0 | 1 | 100.0",
        ]
    );
    assert_eq!(rows("Stop Pareto: minutes").len(), 6);
    // Every minute of each device from its first state to the range's end, once.
    assert_eq!(
        rows("Time per category"),
        [
            "placer1 | 635.0 | 30.0 | 0.0 | 0.0 | 20.0 | 0.0 | 5.0",
            "placer2 | 645.0 | 30.0 | 0.0 | 0.0 | 45.0 | 0.0 | 0.0",
        ]
    );
    assert_eq!(rows("Events").len(), 3);
    assert_eq!(rows("annotation Events (severity 700 and above)").len(), 2);
    // 72 samples ten minutes apart in buckets of five: one row each.
    assert_eq!(rows("Trends").len(), 72);
}

// --- PromQL ----------------------------------------------------------------------------

/// What Grafana puts in PromQL for the gateway dashboard's variables and its own.
fn as_grafana_sends_promql(expr: &str) -> String {
    replace_variables(expr, |name| match name {
        "instance" => "(gw1:8080|gw2:8080)".to_owned(),
        "line" => "(bench|rs485)".to_owned(),
        other => panic!("no value for ${other} in this test"),
    })
    .replace("$__rate_interval", "1m")
    .replace("$__interval", "30s")
    .replace("$__range", "6h")
}

/// Runs `promtool check rules` on one recording rule per expression; its output when it
/// refuses them.
fn promtool_check(exprs: &[(String, String)]) -> Result<(), String> {
    let groups: Vec<serde_json::Value> = exprs
        .iter()
        .enumerate()
        .map(|(i, (place, expr))| {
            serde_json::json!({
                "name": format!("{i}: {place}"),
                "rules": [{"record": format!("cellbus:dashboard_query_{i}"), "expr": expr}],
            })
        })
        .collect();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let file = dir.path().join("dashboards.rules.yaml");
    let yaml =
        serde_yaml::to_string(&serde_json::json!({ "groups": groups })).expect("rules as YAML");
    std::fs::write(&file, yaml).expect("the rules file");
    let out = Command::new("promtool")
        .args(["check", "rules"])
        .arg(&file)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run promtool ({e}): the PromQL of the dashboards is checked by \
                 Prometheus's promtool; install Debian's prometheus package \
                 (apt-get install prometheus; scripts/test does it)"
            )
        });
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ))
    }
}

/// The metric names the gateway registers (`registry.register("polls", …)` under the
/// prefix `cellbus`), read from its source.
fn gateway_metric_names() -> BTreeSet<String> {
    fn walk(dir: &Path, names: &mut BTreeSet<String>) {
        for entry in std::fs::read_dir(dir).expect("the gateway's sources") {
            let path = entry.expect("an entry").path();
            if path.is_dir() {
                walk(&path, names);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&path).expect("a source file");
                for (at, _) in text.match_indices(".register(") {
                    let rest = text[at + ".register(".len()..].trim_start();
                    if let Some(literal) = rest.strip_prefix('"') {
                        let name = literal.split('"').next().unwrap_or_default();
                        names.insert(format!("cellbus_{name}"));
                    }
                }
            }
        }
    }
    let mut names = BTreeSet::new();
    walk(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../gateway/src"),
        &mut names,
    );
    names
}

#[test]
fn every_promql_expression_of_the_dashboards_parses_and_names_gateway_metrics() {
    let mut exprs = Vec::new();
    for (name, dashboard) in dashboards() {
        for query in queries(&name, &dashboard) {
            if query.source != "cellbus-prometheus" {
                continue;
            }
            // A variable's `label_values(SELECTOR, label)`: the selector is PromQL.
            let text = match query.text.strip_prefix("label_values(") {
                Some(args) => args
                    .rsplit_once(',')
                    .map(|(selector, _)| selector.to_owned())
                    .expect("label_values(selector, label)"),
                None => query.text.clone(),
            };
            exprs.push((query.place(), as_grafana_sends_promql(&text)));
        }
    }
    assert!(exprs.len() >= 10, "{exprs:#?}");
    if let Err(refused) = promtool_check(&exprs) {
        panic!("promtool refuses a dashboard's PromQL:\n{refused}\n{exprs:#?}");
    }
    // The check sees a broken expression.
    let broken = [(
        "broken".to_owned(),
        "rate(cellbus_polls_total[1m]".to_owned(),
    )];
    assert!(
        promtool_check(&broken).is_err(),
        "promtool passed a broken expression"
    );

    let registered = gateway_metric_names();
    assert!(registered.contains("cellbus_polls"), "{registered:?}");
    for (place, expr) in &exprs {
        let mut rest = expr.as_str();
        while let Some(at) = rest.find("cellbus_") {
            rest = &rest[at..];
            let len = rest
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(rest.len());
            let used = &rest[..len];
            rest = &rest[len..];
            let family = ["_total", "_bucket", "_sum", "_count"]
                .iter()
                .find_map(|suffix| used.strip_suffix(suffix))
                .unwrap_or(used);
            assert!(
                registered.contains(family),
                "{place}: {used} is not a metric of the gateway"
            );
        }
    }
}
