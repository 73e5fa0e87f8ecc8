//! The cell on MQTT over TLS (`mqtts://`), against a real mosquitto with a TLS listener and
//! certificates made here (rcgen): the gateway's births arrive with the broker's CA in
//! `ca_file`; a broker the CA does not vouch for is refused with a clear status and the
//! gateway keeps trying; a broker that wants a client certificate takes `client_cert`.
//!
//! The test's subscriber uses the broker's plain listener.

use std::path::Path;

use gateway::ServeOptions;
use gateway::northbound::mqtt::MqttLink;
use rcgen::ExtendedKeyUsagePurpose;
use testkit::{Mosquitto, SparkplugMessage, Subscriber, TlsFiles};

mod certs;
mod running;
use certs::Ca;
use running::{LIMIT, Running};

/// Generous: a loaded 2-core machine.
const NODE: &str = "spBv1.0/cellbus/+/tls";

/// A mosquitto with a TLS listener whose certificate `broker_ca` signs; it trusts
/// `client_ca`'s client certificates, and requires one if `require_certificate`.
fn broker(
    dir: &Path,
    broker_ca: &Ca,
    client_ca: &Ca,
    require_certificate: bool,
) -> (Mosquitto, TlsFiles) {
    let (cert, key) = broker_ca.broker(dir);
    let files = TlsFiles {
        ca: client_ca.write(dir, "clients-ca"),
        cert,
        key,
        require_certificate,
    };
    (Mosquitto::start_tls(&files), files)
}

/// A gateway with a cell of one (absent) station whose `[mqtt]` table is `mqtt`, from a
/// config file in `dir`, so relative paths in `mqtt` are relative to `dir`.
async fn start(dir: &Path, mqtt: &str) -> Running {
    let nobody = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let config = dir.join("cell.toml");
    std::fs::write(
        &config,
        format!(
            "[[line]]\nname = \"bench\"\nendpoint = \"tcp://127.0.0.1:{nobody}\"\n\n\
             [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\n\n\
             [mqtt]\nedge_node_id = \"tls\"\n{mqtt}"
        ),
    )
    .unwrap();
    Running::start(ServeOptions {
        config: Some(config),
        data_dir: dir.join("data"),
        ..ServeOptions::default()
    })
    .await
}

/// A temporary directory with the gateway's CA, `cellbus test CA`, written to it as
/// `ca.pem`, what `ca_file` names.
fn our_ca() -> (tempfile::TempDir, Ca) {
    let dir = tempfile::tempdir().unwrap();
    let ca = Ca::new("cellbus test CA");
    ca.write(dir.path(), "ca");
    (dir, ca)
}

/// The next NBIRTH `node` sees (`what` names it if none comes).
async fn next_nbirth(node: &mut Subscriber, what: &str) -> SparkplugMessage {
    node.next_where(what, LIMIT, |m| m.kind() == "NBIRTH").await
}

/// The refusal reported in the cell's MQTT state, once there is one.
async fn refusal(gateway: &Running) -> String {
    gateway
        .wait_for_link(
            "reported the refused connection",
            |l| matches!(l, Some(MqttLink::Disconnected(why)) if why != "not connected yet"),
        )
        .await;
    match gateway::northbound::mqtt::link(&gateway.cell) {
        Some(MqttLink::Disconnected(why)) => why,
        other => panic!("not a refusal: {other:?}"),
    }
}

/// A gateway (as [`start`]) that reaches `broker` over TLS trusting `ca.pem`, with
/// `more` in its `[mqtt]` table.
async fn start_over_tls(dir: &Path, broker: &Mosquitto, more: &str) -> Running {
    let mqtt = format!(
        "broker = \"mqtts://127.0.0.1:{}\"\nca_file = \"ca.pem\"\n{more}",
        broker.tls_port()
    );
    start(dir, &mqtt).await
}

/// The refusal reported, once there is one; it says the TLS handshake with `broker`
/// failed.
async fn handshake_refusal(gateway: &Running, broker: &Mosquitto) -> String {
    let why = refusal(gateway).await;
    let expected = format!(
        "TLS handshake with broker 127.0.0.1:{} failed: ",
        broker.tls_port()
    );
    assert!(why.starts_with(&expected), "{why}");
    why
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_gateway_publishes_its_births_over_mqtts_trusting_the_given_ca_file() {
    let (dir, ca) = our_ca();
    let (broker, _files) = broker(dir.path(), &ca, &ca, false);
    let mut node = Subscriber::start(broker.port(), NODE).await;
    let gateway = start_over_tls(dir.path(), &broker, "").await;

    let birth = next_nbirth(&mut node, "an NBIRTH over TLS").await;
    assert!(birth.bd_seq().is_some());
    gateway
        .wait_for_link("connected", |l| matches!(l, Some(MqttLink::Connected)))
        .await;
    gateway.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_the_ca_file_does_not_vouch_for_is_refused_clearly_and_the_gateway_keeps_trying() {
    let (dir, ours) = our_ca();
    let strangers = Ca::new("someone else's CA");
    let (mut broker, _files) = broker(dir.path(), &strangers, &strangers, false);
    let mut node = Subscriber::start(broker.port(), NODE).await;
    let gateway = start_over_tls(dir.path(), &broker, "").await;

    let why = handshake_refusal(&gateway, &broker).await;
    assert!(why.contains("UnknownIssuer"), "{why}");
    assert!(why.contains("check ca_file"), "{why}");

    // The same broker with a certificate our CA signed: the gateway, still trying, gets in.
    ours.broker(dir.path());
    broker.restart();
    next_nbirth(&mut node, "an NBIRTH once the broker is vouched for").await;
    gateway.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_that_wants_a_client_certificate_takes_the_gateways_client_cert() {
    let (dir, ca) = our_ca();
    ca.sign(
        dir.path(),
        "gateway",
        &[],
        ExtendedKeyUsagePurpose::ClientAuth,
    );
    let (broker, _files) = broker(dir.path(), &ca, &ca, true);
    let mut node = Subscriber::start(broker.port(), NODE).await;
    let gateway = start_over_tls(
        dir.path(),
        &broker,
        "client_cert = \"gateway.pem\"\nclient_key = \"gateway.key\"\n",
    )
    .await;

    next_nbirth(&mut node, "an NBIRTH with a client certificate").await;
    gateway.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_that_wants_a_client_certificate_refuses_a_gateway_without_one_clearly() {
    let (dir, ca) = our_ca();
    let (broker, _files) = broker(dir.path(), &ca, &ca, true);
    let gateway = start_over_tls(dir.path(), &broker, "").await;

    let why = handshake_refusal(&gateway, &broker).await;
    assert!(why.contains("client_cert"), "{why}");
    gateway.stop().await;
}
