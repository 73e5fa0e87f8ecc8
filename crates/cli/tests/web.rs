//! The gateway's web page in a real browser: headless Chromium, driven by playwright-core
//! (both installed by `scripts/test`: Debian's `chromium`, and `npm install` in tests/web).

mod common;

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

use common::{Gateway, Sim};

#[test]
fn the_page_shows_every_demo_device_a_value_changing_by_itself_and_the_mqtt_link() {
    let broker = testkit::Mosquitto::start();
    let seen = open_the_page(None, Some(&broker.url()));
    assert_eq!(seen["asked"], 0, "no prompt without a read token");
    assert_eq!(seen["mqtt"], "MQTT", "the MQTT link shows as up");
}

#[test]
fn a_gateway_with_a_read_token_is_asked_for_it_once_and_then_shows_the_cell() {
    let seen = open_the_page(Some("look-only"), None);
    assert_eq!(seen["asked"], 1, "one prompt");
    assert_eq!(
        seen["mqtt"],
        serde_json::Value::Null,
        "no MQTT, no MQTT badge"
    );
}

/// 1,000 JBC stations, 20 on each of 50 TCP lines to one `cellbus sim jbc` (each line its
/// own connection, so its own station at address 01): on every line `jbc…` at address 01
/// answers with live values and the 19 others time out and are backed off, as on a bus
/// with unplugged stations. The page must show a line at a time and take only that.
#[test]
fn a_cell_of_a_thousand_devices_shows_one_line_at_a_time_and_streams_only_what_is_shown() {
    const LINES: usize = 50;
    const PER_LINE: usize = 20;
    let browser = browser();
    let sim = Sim::start(&["jbc", "--listen", "127.0.0.1:0"]);
    let data = tempfile::tempdir().unwrap();
    // The script writes one setpoint, so that a value on the page changes.
    const TOKEN: &str = "big-cell-token";
    let mut config = format!("# 1,000 stations for the page's test.\ntoken = \"{TOKEN}\"\n");
    for line in 1..=LINES {
        let _ = write!(
            config,
            "\n[[line]]\nname = \"line{line:02}\"\nendpoint = \"{}\"\n",
            sim.endpoint
        );
        for address in 1..=PER_LINE {
            let n = (line - 1) * PER_LINE + address;
            let _ = write!(
                config,
                "\n[[line.device]]\nid = \"jbc{n}\"\nprotocol = \"jbc\"\naddress = {address}\n\
                 timeout = \"100ms\"\nretries = 0\n"
            );
        }
    }
    let path = data.path().join("cell.toml");
    std::fs::write(&path, config).unwrap();
    let gateway = Gateway::start_with(
        data.path(),
        &["--config", path.to_str().unwrap(), "--allow-writes"],
    );

    // The API's filtered and slim listings of a cell this size stay small and quick.
    let slim = gateway.get_json("/api/devices?fields=line,status");
    assert_eq!(slim["total"], LINES * PER_LINE);
    let page: Vec<String> = (951..=1000).map(|n| format!("jbc{n}")).collect();
    let (status, listed) = gateway.get(&format!("/api/devices?device={}", page.join(",")));
    assert_eq!(
        status, 200,
        "fifty devices by id fit in one request: {listed}"
    );
    let listed: serde_json::Value = serde_json::from_str(&listed).unwrap();
    assert_eq!(listed["total"], 50);

    let screenshot = data.path().join("page.png");
    let seen = what_the_page_saw(
        browser
            .script("big.mjs", &gateway, &screenshot)
            .env("TOKEN", TOKEN),
    );
    assert_eq!(seen["devices"], LINES * PER_LINE);
    assert_eq!(
        seen["dom"]["cards"], PER_LINE,
        "only the first line's cards"
    );
    assert!(screenshot.exists());

    // Measured, not asserted: what a page costs with 1,000 devices.
    let refresh = &seen["refresh"];
    let seconds = refresh["seconds"].as_f64().unwrap();
    let whole = &seen["whole_cell_stream"];
    let kb = |v: &serde_json::Value| v.as_f64().unwrap_or(0.0) / 1000.0;
    eprintln!(
        "web page with {} devices on {} lines: first card {} ms, first line's {} cards {} ms \
         ({} elements, {} points); search to jbc987 {} ms",
        seen["devices"],
        seen["lines"],
        seen["first_card_ms"],
        seen["dom"]["cards"],
        seen["first_line_ms"],
        seen["dom"]["elements"],
        seen["dom"]["points"],
        seen["search_ms"]
    );
    eprintln!(
        "per second with a line shown: stream {:.1} kB ({:.1} messages), other requests \
         {:.1} kB ({} in {seconds} s); the line's snapshot {:.1} kB",
        kb(&refresh["stream_bytes"]) / seconds,
        refresh["stream_messages"].as_f64().unwrap_or(0.0) / seconds,
        kb(&refresh["other_bytes"]) / seconds,
        refresh["other_requests"],
        kb(&seen["line_snapshot_bytes"])
    );
    eprintln!(
        "the whole cell's stream for comparison: snapshot {:.1} kB, then {:.1} kB/s \
         ({:.1} messages/s)",
        kb(&whole["snapshot_bytes"]),
        (kb(&whole["bytes"]) - kb(&whole["snapshot_bytes"])) / whole["seconds"].as_f64().unwrap(),
        whole["messages"].as_f64().unwrap_or(0.0) / whole["seconds"].as_f64().unwrap()
    );
    eprintln!("{seen}");
}

/// Where the browser test's scripts live and the Chromium they drive.
struct Browser {
    web: std::path::PathBuf,
    chromium: String,
}

impl Browser {
    /// `node tests/web/SCRIPT http://GATEWAY SCREENSHOT`, driving this Chromium.
    fn script(&self, script: &str, gateway: &Gateway, screenshot: &Path) -> Command {
        let mut node = Command::new("node");
        node.arg(self.web.join(script))
            .arg(format!("http://{}", gateway.addr))
            .arg(screenshot)
            .env("CHROMIUM", &self.chromium);
        node
    }
}

/// Where the browser test's scripts live and the Chromium they drive, both checked.
fn browser() -> Browser {
    let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/web");
    assert!(
        web.join("node_modules/playwright-core").is_dir(),
        "playwright-core is missing: run scripts/test once, or `npm install --prefix {}`",
        web.display()
    );
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".to_owned());
    assert!(
        Path::new(&chromium).exists(),
        "no Chromium at {chromium}: run scripts/test once, or `apt-get install chromium`"
    );
    Browser { web, chromium }
}

/// Runs a page script (`node …`) that prints one JSON line: what it saw.
fn what_the_page_saw(node: &mut Command) -> serde_json::Value {
    let out = node
        .output()
        .expect("node runs (install Node.js: it comes with npm)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.trim()).expect("one JSON line")
}

/// Starts the demo gateway (with `read_token` if given, publishing to the MQTT broker
/// `mqtt` if given), opens its page in Chromium and checks a card for every device and a
/// value that changes; returns what the page saw.
fn open_the_page(read_token: Option<&str>, mqtt: Option<&str>) -> serde_json::Value {
    let browser = browser();
    let data = tempfile::tempdir().unwrap();
    let mut args: Vec<&str> = read_token.map_or(vec![], |t| vec!["--read-token", t]);
    if let Some(url) = mqtt {
        args.extend(["--mqtt", url]);
    }
    let gateway = Gateway::start_with(data.path(), &args);
    let screenshot = data.path().join("page.png");
    let seen = what_the_page_saw(
        browser
            .script("page.mjs", &gateway, &screenshot)
            .env("READ_TOKEN", read_token.unwrap_or(""))
            .env("MQTT", if mqtt.is_some() { "1" } else { "" }),
    );
    let (status, body) = gateway.get("/api/devices");
    if read_token.is_some() {
        assert_eq!(status, 401, "the API needs the token: {body}");
    } else {
        assert_eq!(status, 200);
        let api: serde_json::Value = serde_json::from_str(&body).unwrap();
        let ids: Vec<_> = api["devices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| d["id"].clone())
            .collect();
        assert_eq!(
            seen["devices"].as_array().unwrap(),
            &ids,
            "a card for every device"
        );
    }
    assert!(!seen["devices"].as_array().unwrap().is_empty());
    assert_ne!(seen["change"]["before"], seen["change"]["after"]);
    assert!(screenshot.exists());
    let summary = seen["summary"].as_str().unwrap();
    assert!(
        summary.contains(&format!(
            " of {} devices up",
            seen["devices"].as_array().unwrap().len()
        )),
        "the header counts the devices up: {summary}"
    );
    for (unit, decimals) in seen["formats"].as_object().unwrap() {
        assert_eq!(
            decimals.as_array().unwrap().len(),
            1,
            "one number format for {unit}: {seen}"
        );
    }
    assert!(
        seen["phone"]["overflow"].as_i64().unwrap() <= 0,
        "nothing wider than a 360 px phone: {}",
        seen["phone"]
    );
    seen
}
