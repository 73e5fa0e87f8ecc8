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
    let seen = open_the_page(None, Some(&broker.url()), &[]);
    assert_eq!(seen["asked"], 0, "no prompt without a read token");
    assert_eq!(seen["mqtt"], "MQTT", "the MQTT link shows as up");
    assert_eq!(seen["cfx"], serde_json::Value::Null, "no IPC-CFX, no badge");
}

// It shows an IPC-CFX link too (`serve --cfx`).
#[cfg(feature = "cfx")]
#[test]
fn a_gateway_with_a_read_token_is_asked_for_it_once_and_then_shows_the_cell() {
    // An IPC-CFX receiver that is not there: its link shows as down.
    let nobody = format!("amqp://127.0.0.1:{}/cfx", testkit::free_port());
    let seen = open_the_page(Some("look-only"), None, &["--cfx", &nobody]);
    assert_eq!(seen["asked"], 1, "one prompt");
    assert_eq!(
        seen["mqtt"],
        serde_json::Value::Null,
        "no MQTT, no MQTT badge"
    );
    assert!(
        seen["cfx"]
            .as_str()
            .is_some_and(|b| b.starts_with("CFX down")),
        "{}",
        seen["cfx"]
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

/// The trend view on the demo cell: two points picked by typing, a zoom by dragging, moves
/// by button, shift-drag and finger, each asking `/api/history` for exactly the span then
/// shown, in buckets that fit the chart; the CSV holds exactly the series the zoom's answers
/// make; the address brings the same view back after a reload.
#[test]
fn a_trend_asks_for_each_span_it_shows_downloads_it_as_csv_and_comes_back_from_its_address() {
    let browser = browser();
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(data.path());
    let screenshot = data.path().join("trend.png");
    let seen = what_the_page_saw(&mut browser.script("trend.mjs", &gateway, &screenshot));
    let points = ["sealer0.temperature", "cross1.load_power"];
    assert_eq!(seen["picked"]["chosen"], serde_json::json!(points));
    assert_eq!(
        seen["picked"]["address"],
        "#view=trend&points=sealer0.temperature,cross1.load_power&range=10m"
    );
    let legend = seen["legend"].to_string();
    assert!(
        legend.contains("Current temperature (°C)") && legend.contains("Load power (kVA)"),
        "both series are drawn, with their units: {legend}"
    );

    // The last 10 minutes, asked for as such: the gateway says when now is.
    for asked in seen["first"]["asked"].as_array().unwrap() {
        assert_eq!(
            (&asked["from"], &asked["to"]),
            (&"-10m".into(), &"now".into())
        );
    }
    let first = shown(&seen["first"]);
    assert!(
        (600_000..=601_000).contains(&(first.1 - first.0)),
        "{first:?}"
    );

    // The zoom asked for the newest tenth of it, and shows what it asked for.
    let zoom = asked_span(&seen["zoom"], &points);
    assert_eq!(zoom, shown(&seen["zoom"]));
    assert!(
        first.0 <= zoom.0 && zoom.1 <= first.1,
        "{zoom:?} within {first:?}"
    );
    let span = zoom.1 - zoom.0;
    assert!(
        (50_000..=70_000).contains(&span),
        "a tenth of 10 minutes: {span} ms"
    );
    let address = seen["zoom"]["address"].as_str().unwrap();
    assert!(
        address.contains("&from=") && address.contains("&to="),
        "{address}"
    );

    // ◀ moved it earlier by half, a shift-drag later, a finger earlier again: each move
    // asked for the span it then showed, as long as before.
    let earlier = asked_span(&seen["earlier"], &points);
    assert_eq!(earlier, shown(&seen["earlier"]));
    assert!(
        (earlier.0 - (zoom.0 - span / 2)).abs() <= 2,
        "{earlier:?} {zoom:?}"
    );
    let dragged = asked_span(&seen["dragged"], &points);
    assert_eq!(dragged, shown(&seen["dragged"]));
    assert!(
        dragged.0 > earlier.0,
        "shift-drag to the left shows later: {dragged:?}"
    );
    let touched = asked_span(&seen["touched"], &points);
    assert_eq!(touched, shown(&seen["touched"]));
    assert!(
        touched.0 < dragged.0,
        "a finger to the right shows earlier: {touched:?}"
    );
    for moved in [earlier, dragged, touched] {
        assert!(
            ((moved.1 - moved.0) - span).abs() <= 2,
            "{moved:?} as long as {span}"
        );
    }

    // The CSV: a time column and one per point with its unit, a row per time the answers
    // hold a bucket (and the span's two ends), each point's value held from its last bucket.
    let csv = &seen["csv"];
    assert!(csv["name"].as_str().unwrap().ends_with(".csv"));
    let text = csv["text"].as_str().unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("time,sealer0.temperature (°C),cross1.load_power (kVA)")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let answers = seen["zoom"]["answers"].as_array().unwrap();
    // Times are RFC 3339 with milliseconds in UTC, the page's as the gateway's: they sort
    // as text.
    let (from, to) = (
        answers[0]["from"].as_str().unwrap(),
        answers[0]["to"].as_str().unwrap(),
    );
    let mut times: Vec<&str> = answers
        .iter()
        .flat_map(|a| a["buckets"].as_array().unwrap())
        .map(|b| b["t"].as_str().unwrap())
        .filter(|t| (from..to).contains(t))
        .chain([from, to])
        .collect();
    times.sort_unstable();
    times.dedup();
    assert_eq!(
        rows.iter().map(|r| r[0]).collect::<Vec<_>>(),
        times,
        "a row per bucket's time and the span's ends"
    );
    for (column, answer) in answers.iter().enumerate() {
        let buckets = answer["buckets"].as_array().unwrap();
        assert!(
            !buckets.is_empty(),
            "{} has history: {answer}",
            points[column]
        );
        let mut held = answer["before"]["value"].as_f64();
        let mut next = buckets.iter().peekable();
        for row in &rows {
            while let Some(b) = next.next_if(|b| b["t"].as_str().unwrap() <= row[0]) {
                held = b["avg"].as_f64();
            }
            let shown = row[column + 1];
            match held {
                Some(value) => assert_eq!(shown.parse::<f64>().ok(), Some(value), "{row:?}"),
                None => assert_eq!(shown, "", "{row:?}"),
            }
        }
    }
    assert!(screenshot.exists());

    // The address keeps the view: the reload shows the same points over the same span, and
    // asks for just that.
    let reloaded = &seen["reloaded"];
    assert_eq!(reloaded["address"], seen["address"]);
    assert_eq!(reloaded["chosen"], serde_json::json!(points));
    assert_eq!(
        shown(&serde_json::json!({ "shown": reloaded["span"] })),
        touched
    );
    assert_eq!(asked_span(reloaded, &points), touched);

    assert!(
        seen["phone"]["overflow"].as_i64().unwrap() <= 0,
        "nothing wider than a 360 px phone: {}",
        seen["phone"]
    );
}

/// The production view on the demo, as a supervisor opens it (the Production tab): the
/// placement machine's state bars hold one segment per interval of the `/api/states`
/// answer they were drawn from, in place and in their category's colour (the legend's);
/// pointing at one names it; OEE, availability, performance and quality are the
/// `/api/production` answer's, as percentages with one decimal; the stops are its stops,
/// the feeder that ran out named; the page asks again by itself.
#[test]
fn the_production_view_shows_the_placement_machines_states_oee_and_stops_as_the_api_says() {
    let browser = browser();
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(data.path());
    let screenshot = data.path().join("production.png");
    let seen = what_the_page_saw(&mut browser.script("production.mjs", &gateway, &screenshot));
    let first = &seen["first"];
    assert_eq!(
        first["device"], "placer1",
        "the demo's placement machine first"
    );
    let answers = seen["answers"].as_array().unwrap();
    let answer = |path: &str, query: &str, to: &serde_json::Value| -> serde_json::Value {
        answers
            .iter()
            .find(|a| a["path"] == path && a["query"] == query && &a["body"]["to"] == to)
            .unwrap_or_else(|| panic!("no answer of {path}{query} to {to}: {answers:?}"))["body"]
            .clone()
    };

    // The legend: a colour per category, none alike.
    let legend = first["legend"].as_object().unwrap();
    let categories = gateway::production::Category::ALL;
    assert_eq!(legend.keys().collect::<Vec<_>>().len(), categories.len());
    let mut colours: Vec<&str> = legend.values().map(|c| c.as_str().unwrap()).collect();
    colours.sort_unstable();
    colours.dedup();
    assert_eq!(colours.len(), categories.len(), "{legend:?}");

    // Each bar: the answer it was drawn from, a segment per interval, in place and colour.
    for (bar, query) in [
        ("shift", "?device=placer1"),
        ("hour", "?device=placer1&from=-1h&to=now"),
    ] {
        let drawn = &first[bar];
        let states = answer("/api/states", query, &drawn["answered"]);
        let intervals = states["intervals"].as_array().unwrap();
        let segments = drawn["segments"].as_array().unwrap();
        assert_eq!(segments.len(), intervals.len(), "{bar}: {drawn}");
        assert!(
            intervals.iter().any(|i| i["category"] != "unknown"),
            "{bar}: the machine's states: {states}"
        );
        let (from, to) = (
            drawn["from"].as_f64().unwrap(),
            drawn["to"].as_f64().unwrap(),
        );
        let width = drawn["width"].as_f64().unwrap();
        let x = |t: &serde_json::Value| {
            let t = humantime::parse_rfc3339(t.as_str().unwrap()).unwrap();
            let ms = t.duration_since(std::time::UNIX_EPOCH).unwrap().as_millis() as f64;
            (ms - from) / (to - from) * width
        };
        for (segment, interval) in segments.iter().zip(intervals) {
            for field in ["start", "end", "state", "category"] {
                assert_eq!(segment[field], interval[field], "{bar}: {segment}");
            }
            assert_eq!(segment["code"], interval["code"].to_string());
            assert_eq!(segment["reason"], interval["reason"].as_str().unwrap_or(""));
            let (left, right) = (x(&interval["start"]), x(&interval["end"]));
            let shown = segment["left"].as_f64().unwrap();
            assert!((shown - left).abs() < 1.5, "{bar}: {segment} at {left}");
            let wide = segment["width"].as_f64().unwrap();
            assert!((wide - (right - left)).abs() < 1.5, "{bar}: {segment}");
            let category = interval["category"].as_str().unwrap();
            assert_eq!(segment["colour"], legend[category], "{bar}: {segment}");
        }
        if bar == "shift" {
            // The whole shift, now inside it.
            let production = answer("/api/production", "?device=placer1", &first["answered"]);
            let shift = &production["shift"];
            assert_eq!(x(&shift["start"]), 0.0);
            assert!((x(&shift["end"]) - width).abs() < 0.5, "{shift} {drawn}");
        }
    }

    // Pointing at a segment names its interval.
    let pointed = &seen["pointed"];
    assert_eq!(pointed["start"], pointed["segment"]["start"]);
    let words = pointed["text"].as_str().unwrap();
    assert!(
        words.contains(pointed["segment"]["state"].as_str().unwrap()),
        "{pointed}"
    );

    // The figures: the production answer's, rounded to one decimal of a percent (the
    // script waited for a finished board, which makes the OEE a number).
    let production = answer("/api/production", "?device=placer1", &first["answered"]);
    assert!(production["oee"].is_number(), "{production}");
    let stops = first["stops"].to_string();
    assert!(
        stops.contains("parts exhausted: feeder 7"),
        "the stop names its feeder: {stops}"
    );
    for shown in [first, &seen["later"]] {
        let production = answer("/api/production", "?device=placer1", &shown["answered"]);
        for (figure, field) in [
            ("oee", "oee"),
            ("availability", "availability"),
            ("performance", "performance"),
            ("quality", "quality"),
        ] {
            let text = shown["figures"][figure].as_str().unwrap();
            match production[field].as_f64() {
                None => assert_eq!(text, "—", "{figure}: {production}"),
                Some(ratio) => {
                    let number = text.strip_suffix(" %").unwrap_or_else(|| panic!("{text}"));
                    assert_eq!(number.split('.').nth(1).map(str::len), Some(1), "{text}");
                    let percent: f64 = number.parse().unwrap();
                    assert!(
                        (percent - ratio * 100.0).abs() <= 0.05 + 1e-9,
                        "{figure}: {text} for {ratio}"
                    );
                }
            }
        }
        let boards = production["boards"].as_f64().unwrap();
        assert!(
            shown["figures"]["boards"]
                .as_str()
                .unwrap()
                .starts_with(&boards.to_string()),
            "{shown}"
        );
        for (figure, field) in [("mtbf", "mtbf_s"), ("mttr", "mttr_s")] {
            let text = shown["figures"][figure].as_str().unwrap();
            assert_eq!(text == "—", production[field].is_null(), "{figure}: {text}");
        }
        // The stops, longest first.
        let stops: Vec<&serde_json::Value> =
            production["stops"].as_array().unwrap().iter().collect();
        let listed = shown["stops"].as_array().unwrap();
        assert_eq!(listed.len(), stops.len(), "{shown}");
        for (row, stop) in listed.iter().zip(&stops) {
            assert_eq!(row["reason"], stop["reason"]);
            assert_eq!(row["count"], stop["count"].to_string());
            // Minutes to a tenth, or whole seconds under a minute.
            let text = row["text"].as_str().unwrap();
            let seconds = stop["seconds"].as_f64().unwrap();
            let (shown, exact, within) = match text.split_once(" min") {
                Some((minutes, _)) => (minutes, seconds / 60.0, 0.05),
                None => (text.split(" s").next().unwrap(), seconds, 0.5),
            };
            let shown: f64 = shown.parse().unwrap();
            assert!((shown - exact).abs() <= within + 1e-9, "{row}: {stop}");
            assert_eq!(seconds < 60.0, !text.contains(" min"), "{row}");
        }
    }
    // Asked again by itself: a later answer, drawn.
    assert!(seen["later"]["answered"].as_str() > first["answered"].as_str());
    assert!(screenshot.exists());
    assert!(
        seen["phone"]["overflow"].as_i64().unwrap() <= 0,
        "nothing wider than a 360 px phone: {}",
        seen["phone"]
    );
}

/// The alarm view on the demo, as an operator works with it: the header's banner opens the
/// alarm list; once the demo's devices have raised two alarms of their own, the operator
/// acknowledges one (a wrong token first, whose refusal the page shows) and shelves the
/// other for an hour after confirming, giving a name and a comment each time; the banner's
/// counts change, and the journal, on the page and from the API, says who did what and why.
/// On a phone the view and its dialog fit the screen, and the shelving is undone there.
#[test]
fn an_operator_acknowledges_one_demo_alarm_shelves_another_and_the_journal_says_who_and_why() {
    const TOKEN: &str = "alarm-desk-token";
    const OPERATOR: &str = "Ann Operator";
    let browser = browser();
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start_with(data.path(), &["--allow-writes", "--token", TOKEN]);

    // The demo's devices raise their own alarms within about a minute (a JBC tool error, a
    // sealer's fault, the placement machine's error stop): wait for two waiting for an
    // acknowledgement, neither shelved (a chattering alarm shelves itself) nor out of service.
    let started = std::time::Instant::now();
    loop {
        let list = gateway.get_json("/api/alarms?limit=50");
        let waiting = list["alarms"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|a| {
                a["acknowledged"] == false
                    && a["shelved_until"].is_null()
                    && a["out_of_service"] == false
            })
            .count();
        if waiting >= 2 {
            break;
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(240),
            "the demo raised no two alarms in 4 minutes: {list}"
        );
        std::thread::sleep(std::time::Duration::from_millis(500));
    }

    let screenshot = data.path().join("alarms.png");
    let seen = what_the_page_saw(
        browser
            .script("alarms.mjs", &gateway, &screenshot)
            .env("TOKEN", TOKEN)
            .env("OPERATOR", OPERATOR),
    );
    assert_eq!(seen["opened"]["address"], "#view=alarms", "{seen}");
    assert_eq!(seen["opened"]["tab"], "tab-alarms");

    // Each row says what the API says of an alarm, in words.
    for row in seen["listed"].as_array().unwrap() {
        for column in [
            "Priority",
            "Device",
            "Message",
            "State",
            "Value",
            "First active",
            "Last active",
            "Count",
            "Shelved until",
        ] {
            let text = row["cells"][column].as_str().unwrap_or_default();
            assert!(!text.is_empty(), "{column} of {row}");
        }
        assert!(
            ["low", "medium", "high", "urgent"].contains(&row["priority"].as_str().unwrap()),
            "{row}"
        );
    }
    let (acked, shelved) = (
        seen["acked"].as_str().unwrap(),
        seen["shelved"].as_str().unwrap(),
    );
    assert_ne!(acked, shelved);

    // The acknowledgement: a wrong token is refused in the API's words, the dialog stays.
    assert_eq!(seen["ack_dialog"]["open"], true);
    assert_eq!(seen["ack_dialog"]["title"], format!("Acknowledge {acked}?"));
    assert_eq!(seen["ack_dialog"]["duration_hidden"], true);
    let refused = seen["refused"]["text"].as_str().unwrap();
    assert!(
        refused.contains("wrong token") && refused.contains("401"),
        "{refused}"
    );
    assert_eq!(seen["refused"]["still_open"], true);
    assert!(
        seen["ack_done"].as_str().unwrap().contains(OPERATOR),
        "{seen}"
    );

    // The banner followed: after the acknowledgement it shows the API's counts.
    for priority in ["urgent", "high", "medium", "low"] {
        assert_eq!(
            seen["banner_after"][priority]["unacknowledged"], seen["api_after"][priority],
            "{priority}: {seen}"
        );
    }

    // The shelving: asked how long and why, confirmed by a button that says it.
    let dialog = &seen["shelve_dialog"];
    assert_eq!(dialog["title"], format!("Shelve {shelved}?"));
    assert_eq!(dialog["durations"], serde_json::json!(["15m", "1h", "8h"]));
    assert_eq!(dialog["duration_hidden"], false);
    assert_eq!(dialog["operator"], OPERATOR, "the name is remembered");
    assert_eq!(dialog["token_kept"], true, "the token is remembered");
    assert_eq!(dialog["confirm"], "Shelve for 1 hour");
    assert_eq!(
        dialog["open_without_comment"], true,
        "no shelving without a comment"
    );
    let until = seen["shelved_row"]["shelvedUntil"].as_str().unwrap();
    let hour = common::rfc3339_ms(until) - common::now_ms();
    assert!(
        (50 * 60_000..=3_600_000).contains(&hour),
        "shelved for an hour: until {until}"
    );
    assert!(
        seen["shelved_row"]["actions"]
            .as_array()
            .unwrap()
            .contains(&"unshelve".into()),
        "{seen}"
    );

    // The journal: on the page and from the API (each alarm's own: a chattering one fills
    // the cell's), who did what and why.
    let entry = |alarm: &str, change: &str| -> serde_json::Value {
        let journal = gateway.get_json(&format!(
            "/api/alarms/journal?alarm={}&from=-1h&limit=100",
            alarm.replace(':', "%3A")
        ));
        journal["entries"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| {
                e["changes"]
                    .as_array()
                    .is_some_and(|c| c.contains(&change.into()))
            })
            .cloned()
            .unwrap_or_else(|| panic!("no {change} of {alarm} in the journal: {journal}"))
    };
    for (alarm, change, comment) in [
        (acked, "acknowledged", "Checked the air hose"),
        (shelved, "shelved", "Known supply sag, electrician called"),
        (shelved, "unshelved", "Supply fixed"),
    ] {
        let e = entry(alarm, change);
        assert!(
            e["by"]
                .as_str()
                .unwrap()
                .starts_with(&format!("{OPERATOR} (http ")),
            "{e}"
        );
        assert_eq!(e["comment"], comment, "{e}");
    }
    let shown = seen["journal"].as_array().unwrap();
    for (alarm, change, comment) in [
        (acked, "acknowledged", "Checked the air hose"),
        (shelved, "shelved", "Known supply sag, electrician called"),
    ] {
        let row = shown
            .iter()
            .find(|r| {
                r["alarm"] == alarm
                    && r["changes"]
                        .as_str()
                        .unwrap()
                        .split(' ')
                        .any(|c| c == change)
            })
            .unwrap_or_else(|| panic!("the page's journal has no {change} of {alarm}: {seen}"));
        assert!(
            row["cells"]["By"].as_str().unwrap().contains(OPERATOR),
            "{row}"
        );
        assert_eq!(row["cells"]["Comment"], comment, "{row}");
    }
    assert!(screenshot.exists());

    let phone = &seen["phone"];
    assert!(
        phone["overflow"].as_i64().unwrap() <= 0,
        "nothing wider than a 360 px phone: {phone}"
    );
    assert!(phone["dialog_right"].as_f64().unwrap() <= 360.0, "{phone}");
    assert!(
        phone["unshelved"].as_str().unwrap().contains("unshelved"),
        "{phone}"
    );
}

/// The span (ms since the epoch) a trend step of `trend.mjs` says it shows.
fn shown(step: &serde_json::Value) -> (i64, i64) {
    let shown = &step["shown"];
    (
        shown["from"].as_i64().unwrap(),
        shown["to"].as_i64().unwrap(),
    )
}

/// The span a trend step asked `/api/history` for: one query per point, all for the same
/// span (RFC 3339) in the same buckets, from 50 to 10,000 of them.
fn asked_span(step: &serde_json::Value, points: &[&str]) -> (i64, i64) {
    let asked = step["asked"].as_array().unwrap();
    let named: Vec<&str> = asked.iter().map(|a| a["point"].as_str().unwrap()).collect();
    assert_eq!(named, points, "{step}");
    let first = &asked[0];
    for other in asked {
        for field in ["from", "to", "step"] {
            assert_eq!(other[field], first[field], "{step}");
        }
    }
    let from = first["from_ms"].as_i64().expect("from is a time");
    let to = first["to_ms"].as_i64().expect("to is a time");
    let bucket = humantime::parse_duration(first["step"].as_str().unwrap()).unwrap();
    let buckets = u128::try_from(to - from).unwrap() / bucket.as_millis();
    assert!(
        (50..=10_000).contains(&buckets),
        "{buckets} buckets: {step}"
    );
    (from, to)
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
/// `mqtt` if given, with `more` arguments), opens its page in Chromium and checks a card
/// for every device and a value that changes; returns what the page saw.
fn open_the_page(read_token: Option<&str>, mqtt: Option<&str>, more: &[&str]) -> serde_json::Value {
    let browser = browser();
    let data = tempfile::tempdir().unwrap();
    let mut args: Vec<&str> = read_token.map_or(vec![], |t| vec!["--read-token", t]);
    if let Some(url) = mqtt {
        args.extend(["--mqtt", url]);
    }
    args.extend(more);
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
