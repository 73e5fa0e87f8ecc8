//! A device kind the gateway does not ship, registered from this test alone: it is read
//! from the config, polled, and shown in `/api/devices` without a line of the gateway
//! changed (DESIGN.md, "Adding a device kind").

use std::borrow::Cow;
use std::time::Duration;

mod running;

use gateway::cell::LiveMessage;
use gateway::config::{ConfigError, Scratch, Settings, Table};
use gateway::driver::{
    BoxFuture, DeviceContext, DeviceError, DeviceKind, Driver, DriverConfig, Kind, PollGroup,
    Reading, WriteError,
};
use gateway::point::{Checked, PointDescription, PointId, PointKind, PointSpec, Value};
use gateway::{Gateway, ServeOptions};
use link::{SerialSettings, SharedLine};
use serde::Deserialize;
use testkit::get_response;

/// A counter that counts up by its `step` at every poll.
#[derive(Debug)]
struct Counter;

/// The counter's own key.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Step(f64);

const GROUPS: [(&str, Duration); 1] = [("live", Duration::from_millis(50))];

impl DeviceKind for Counter {
    fn name(&self) -> &'static str {
        "counter"
    }

    fn default_serial(&self) -> SerialSettings {
        SerialSettings::new_8n1(9600)
    }

    fn default_address(&self) -> Option<i64> {
        None
    }

    fn check_address(&self, address: Option<i64>) -> Result<(), String> {
        match address {
            None => Ok(()),
            Some(a) => Err(format!("a counter has no address (given {a})")),
        }
    }

    fn groups(&self) -> &'static [(&'static str, Duration)] {
        &GROUPS
    }

    fn owns_connections(&self) -> Option<&'static str> {
        Some("tcp://host:1 (nothing is opened)")
    }

    fn keys(&self) -> &'static [&'static str] {
        &["step"]
    }

    fn read_keys(
        &self,
        table: &Table<'_>,
        _device: &DeviceContext,
        _scratch: &mut Scratch,
    ) -> Result<Settings, ConfigError> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Raw {
            step: Option<f64>,
        }
        let raw: Raw = table.read()?;
        Ok(Settings::new(Step(raw.step.unwrap_or(1.0))))
    }

    fn build(&self, config: &DriverConfig) -> Result<Box<dyn Driver>, String> {
        let step = config.settings.get::<Step>().map_or(1.0, |s| s.0);
        let point = PointId::new(&config.id, "count").map_err(|e| e.to_string())?;
        Ok(Box::new(CounterDriver {
            point,
            step,
            count: 0.0,
        }))
    }
}

struct CounterDriver {
    point: PointId,
    step: f64,
    count: f64,
}

impl Driver for CounterDriver {
    fn points(&self) -> Vec<PointSpec> {
        vec![PointSpec::new(
            self.point.clone(),
            PointDescription {
                name: Cow::Borrowed("Count"),
                unit: None,
                kind: PointKind::Numeric,
                group: Cow::Borrowed("live"),
                writable: None,
                alarm: None,
            },
        )]
    }

    fn groups(&self) -> Vec<PollGroup> {
        GROUPS
            .iter()
            .map(|&(name, period)| PollGroup {
                name: name.to_owned(),
                period,
            })
            .collect()
    }

    fn attach(&mut self, _line: SharedLine) {}

    fn poll<'a>(&'a mut self, _group: &'a str) -> BoxFuture<'a, Result<Vec<Reading>, DeviceError>> {
        self.count += self.step;
        let reading = Reading {
            point: self.point.clone(),
            value: Ok(Value::Number(self.count)),
        };
        Box::pin(async move { Ok(vec![reading]) })
    }

    fn write<'a>(
        &'a mut self,
        _point: &'a PointSpec,
        _value: &'a Checked,
    ) -> BoxFuture<'a, Result<(), WriteError>> {
        Box::pin(async { Ok(()) })
    }
}

const CELL: &str = r#"
[[line]]
name = "bench"
endpoint = "tcp://127.0.0.1:1"

[[line.device]]
id = "counter1"
protocol = "counter"
step = 2.5
"#;

#[tokio::test]
async fn a_kind_registered_by_a_test_is_configured_polled_and_listed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(&path, CELL).unwrap();
    let mut registry = gateway::plugins::builtin();
    registry.config = registry.config.with_kind(Kind::new(&Counter));
    let options = ServeOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        data_dir: dir.path().join("data"),
        config: Some(path.clone()),
        ..ServeOptions::default()
    };
    let gateway = Gateway::start_with(options, &registry).await.unwrap();
    let mut live = gateway.cell().subscribe();
    let addr = gateway.local_addr();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let running = tokio::spawn(gateway.run(async {
        let _ = stopped.await;
    }));
    let value = tokio::time::timeout(Duration::from_secs(30), async {
        loop {
            if let Ok(LiveMessage::Value(view)) = live.recv().await
                && view.id.as_str() == "counter1.count"
            {
                return view.value.clone();
            }
        }
    })
    .await
    .expect("the counter is polled");
    let Some(Value::Number(count)) = value else {
        panic!("the count is a number: {value:?}");
    };
    assert_eq!(count % 2.5, 0.0, "counted in steps of 2.5: {count}");

    let devices = get(addr, "/api/devices").await;
    let counter = devices["devices"]
        .as_array()
        .unwrap()
        .iter()
        .find(|d| d["id"] == "counter1")
        .expect("the counter is listed");
    assert_eq!(counter["protocol"], "counter");
    assert!(counter["points"][0]["value"].as_f64().unwrap() >= 2.5);

    // The gateway's own kinds know neither the kind nor its key.
    let refused = gateway::check_config(&path).unwrap_err().to_string();
    assert!(refused.contains("unknown field `step`"), "{refused}");
    std::fs::write(&path, CELL.replace("step = 2.5\n", "")).unwrap();
    let refused = gateway::check_config(&path).unwrap_err().to_string();
    assert!(
        refused.contains("protocol \"counter\" is not one the gateway speaks"),
        "{refused}"
    );

    stop.send(()).unwrap();
    running.await.unwrap().unwrap();
}

/// GETs `path` and returns the JSON body.
async fn get(addr: std::net::SocketAddr, path: &str) -> serde_json::Value {
    let response = get_response(addr, path).await;
    let (_, body) = response.split_once("\r\n\r\n").unwrap();
    serde_json::from_str(body).unwrap()
}
