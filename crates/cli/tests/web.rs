//! The gateway's web page in a real browser: headless Chromium, driven by playwright-core
//! (both installed by `scripts/test`: Debian's `chromium`, and `npm install` in tests/web).

mod common;

use std::path::Path;
use std::process::Command;

use common::Gateway;

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

/// Starts the demo gateway (with `read_token` if given, publishing to the MQTT broker
/// `mqtt` if given), opens its page in Chromium and checks a card for every device and a
/// value that changes; returns what the page saw.
fn open_the_page(read_token: Option<&str>, mqtt: Option<&str>) -> serde_json::Value {
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

    let data = tempfile::tempdir().unwrap();
    let mut args: Vec<&str> = read_token.map_or(vec![], |t| vec!["--read-token", t]);
    if let Some(url) = mqtt {
        args.extend(["--mqtt", url]);
    }
    let gateway = Gateway::start_with(data.path(), &args);
    let screenshot = data.path().join("page.png");
    let out = Command::new("node")
        .arg(web.join("page.mjs"))
        .arg(format!("http://{}", gateway.addr))
        .arg(&screenshot)
        .env("CHROMIUM", &chromium)
        .env("READ_TOKEN", read_token.unwrap_or(""))
        .env("MQTT", if mqtt.is_some() { "1" } else { "" })
        .output()
        .expect("node runs (install Node.js: it comes with npm)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let seen: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
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
    seen
}
