//! `cellbus serve` and `cellbus config`, end to end through the binary.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Stdio};
use std::time::Duration;

use common::{cellbus, run, stderr, stdout};

/// A running gateway, killed when dropped.
struct Gateway {
    child: Child,
    addr: String,
}

impl Gateway {
    fn start(data: &std::path::Path) -> Gateway {
        let mut child = cellbus()
            .args(["serve", "--listen", "127.0.0.1:0", "--data"])
            .arg(data)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cellbus runs");
        let mut first = String::new();
        BufReader::new(child.stdout.take().expect("piped"))
            .read_line(&mut first)
            .expect("a first line");
        let addr = first
            .trim_end()
            .strip_prefix("listening on http://")
            .unwrap_or_else(|| panic!("first line is `listening on http://…`, got {first:?}"))
            .to_owned();
        Gateway { child, addr }
    }

    /// A plain HTTP/1.1 GET; returns the status code and the body.
    fn get(&self, path: &str) -> (u16, String) {
        let mut stream = TcpStream::connect(&self.addr).expect("the gateway accepts connections");
        stream
            .set_read_timeout(Some(Duration::from_secs(30)))
            .expect("timeout set");
        write!(
            stream,
            "GET {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            self.addr
        )
        .expect("request sent");
        let mut response = String::new();
        stream.read_to_string(&mut response).expect("response read");
        let status = response
            .split(' ')
            .nth(1)
            .and_then(|s| s.parse().ok())
            .expect("a status line");
        let body = response
            .split_once("\r\n\r\n")
            .map(|(_, b)| b.to_owned())
            .unwrap_or_default();
        (status, body)
    }
}

impl Gateway {
    /// Reads `/api/events/stream` until an event of `kind` arrives; returns its data line.
    fn first_event(&self, kind: &str) -> String {
        let mut stream = TcpStream::connect(&self.addr).expect("the gateway accepts connections");
        stream
            .set_read_timeout(Some(Duration::from_secs(60)))
            .expect("timeout set");
        write!(
            stream,
            "GET /api/events/stream HTTP/1.1\r\nHost: {}\r\n\r\n",
            self.addr
        )
        .expect("request sent");
        let mut lines = BufReader::new(stream).lines();
        let wanted = format!("event: {kind}");
        while let Some(Ok(line)) = lines.next() {
            if line.trim_end() == wanted {
                return lines.next().and_then(Result::ok).unwrap_or_default();
            }
        }
        panic!("the event stream ended before a {kind} event");
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn serve_without_arguments_runs_the_demo_cell_and_answers_http() {
    let data = tempfile::tempdir().unwrap();
    let gateway = Gateway::start(data.path());
    let (status, body) = gateway.get("/healthz");
    assert_eq!(status, 200, "{body}");
    // The demo station is polled through the real client: its values arrive on the event
    // stream as they change (a blocking read, bounded by the socket's read timeout).
    let event = gateway.first_event("value");
    assert!(event.contains("jbc1."), "{event}");
    let (status, body) = gateway.get("/api/devices");
    assert_eq!(status, 200, "{body}");
    assert!(body.contains("\"quality\":\"good\""), "{body}");
    let (status, _) = gateway.get("/api/devices/no-such-device");
    assert_eq!(status, 404);
}

#[test]
fn serve_with_a_bad_configuration_exits_2_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(&path, "[[line]]\nname = \"a\"\nendpoint = \"bogus://x\"\n").unwrap();
    let out = run(&[
        "serve",
        "--config",
        path.to_str().unwrap(),
        "--listen",
        "127.0.0.1:0",
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("cell.toml:"), "{}", stderr(&out));
}

#[test]
fn the_example_configuration_passes_its_own_check() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    let example = run(&["config", "example"]);
    assert!(example.status.success());
    std::fs::write(&path, &example.stdout).unwrap();
    let out = run(&["config", "check", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains(": ok,"), "{}", stdout(&out));
}

#[test]
fn config_check_points_at_the_bad_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    let mut text = String::from_utf8(run(&["config", "example"]).stdout).unwrap();
    text.push_str("\nbogus = 1\n");
    let bad_line = text.lines().count();
    std::fs::write(&path, text).unwrap();
    let out = run(&["config", "check", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(&format!("cell.toml:{bad_line}:")),
        "{}",
        stderr(&out)
    );
    assert!(stderr(&out).contains("bogus"), "{}", stderr(&out));
}
