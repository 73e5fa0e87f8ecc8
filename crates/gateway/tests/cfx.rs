//! The IPC-CFX link in the gateway's process:
//!
//! - the endpoints follow a reload of the configuration: a placement machine added by
//!   `SIGHUP` greets the line (`EndpointConnected`), one removed says goodbye
//!   (`EndpointShuttingDown`), while the link stays up;
//! - `amqps://` to a real RabbitMQ (Debian's, with its AMQP 1.0 plugin) with a TLS listener
//!   and certificates made here: trusted with `ca_file`, refused clearly without it.
//!
//! Received by cellbus's own AMQP 1.0 receiver (`cellbus cfx sub`'s); the messages'
//! fidelity is checked against an independent peer in the CLI's tests.

use gateway::ServeOptions;
use gateway::northbound::cfx::listen;
use panasonic::server::{RunningTwin, TwinServer};
use panasonic::{Machine, MachineConfig};
use tokio::sync::mpsc;

mod certs;
mod running;
use certs::Ca;
use running::{LIMIT, Running};

/// A Panasonic BM twin on two free loopback ports.
async fn placer() -> RunningTwin {
    let any = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
    let machine = Machine::new(MachineConfig::default()).unwrap();
    TwinServer::bind(any, any, machine)
        .await
        .unwrap()
        .spawn()
        .unwrap()
}

/// A cell file publishing to `receiver`'s address `cfx`, with one placement machine per
/// `(line, id, twin)`.
fn cell_file(receiver: u16, machines: &[(&str, &str, &RunningTwin)]) -> String {
    let mut text = format!("[cfx]\nbroker = \"amqp://127.0.0.1:{receiver}\"\naddress = \"cfx\"\n");
    for (line, id, twin) in machines {
        text.push_str(&format!(
            "\n[[line]]\nname = \"{line}\"\nendpoint = \"tcp://{}\"\n\
             [[line.device]]\nid = \"{id}\"\nprotocol = \"panasonic\"\nevent_port = {}\n",
            twin.command_addr(),
            twin.event_addr().port()
        ));
    }
    text
}

/// The next message named `name` (its source handle), skipping others.
async fn next_named(messages: &mut mpsc::Receiver<listen::Taken>, name: &str) -> String {
    loop {
        let taken = tokio::time::timeout(LIMIT, messages.recv())
            .await
            .unwrap_or_else(|_| panic!("no {name} within {LIMIT:?}"))
            .expect("the receiver runs");
        let (_, body) = taken.expect("a message");
        for envelope in cfx::Received::decode(&body).unwrap() {
            if envelope.message_name == name {
                return envelope.source.unwrap_or_default();
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reload_greets_the_placement_machine_added_and_says_goodbye_for_the_one_removed() {
    let socket = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = socket.local_addr().unwrap().port();
    let (tx, mut messages) = mpsc::channel(1000);
    tokio::spawn(listen::receive(socket, tx));
    let (a, b) = (placer().await, placer().await);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cell.toml");
    std::fs::write(&path, cell_file(port, &[("lan-a", "pa", &a)])).unwrap();
    let gateway = Running::start(ServeOptions {
        config: Some(path.clone()),
        data_dir: dir.path().join("data"),
        ..ServeOptions::default()
    })
    .await;
    let first = next_named(&mut messages, "CFX.EndpointConnected").await;
    assert!(first.ends_with(".pa"), "{first}");

    std::fs::write(&path, cell_file(port, &[("lan-b", "pb", &b)])).unwrap();
    let plan = gateway.reloader.reload().await.unwrap();
    assert!(plan.restart_needed.is_empty(), "{:?}", plan.restart_needed);
    let gone = next_named(&mut messages, "CFX.EndpointShuttingDown").await;
    assert_eq!(gone, first);
    let added = next_named(&mut messages, "CFX.EndpointConnected").await;
    assert!(added.ends_with(".pb"), "{added}");
    // The new machine beats under its handle; the removed one beats no more.
    let beat = tokio::time::timeout(LIMIT, async {
        loop {
            let (_, body) = messages.recv().await.unwrap().unwrap();
            let envelope = cfx::Received::decode(&body).unwrap().remove(0);
            if envelope.message_name == "CFX.Heartbeat" {
                return envelope.source.unwrap_or_default();
            }
        }
    })
    .await
    .expect("a heartbeat of the new endpoint");
    assert_eq!(beat, added);
    gateway.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn over_amqps_the_broker_its_ca_vouches_for_takes_the_messages_and_another_is_refused_clearly()
 {
    let dir = tempfile::tempdir().unwrap();
    let ca = Ca::new("plant CA");
    let (cert, key) = ca.broker(dir.path());
    ca.write(dir.path(), "plant-ca");
    Ca::new("someone else").write(dir.path(), "other-ca");
    let broker = testkit::RabbitMq::start_tls("cfx", "mes", &cert, &key);
    let tls_port = broker.tls_port().unwrap();
    // The test reads the queue on the broker's plain port.
    let (tx, mut messages) = mpsc::channel(1000);
    tokio::spawn(listen::subscribe(
        format!("amqp://127.0.0.1:{}", broker.port()),
        "/amq/queue/mes".to_owned(),
        None,
        tx,
    ));

    let start = |ca_file: &str, data: &str| {
        let path = dir.path().join(format!("{data}.toml"));
        std::fs::write(
            &path,
            format!(
                "[cfx]\nbroker = \"amqps://127.0.0.1:{tls_port}\"\naddress = \"/exchange/cfx\"\n\
                 ca_file = \"{ca_file}\"\n\n[[line]]\nname = \"lan\"\n\
                 endpoint = \"tcp://127.0.0.1:{}\"\n[[line.device]]\nid = \"placer1\"\n\
                 protocol = \"panasonic\"\n",
                testkit::free_port()
            ),
        )
        .unwrap();
        Running::start(ServeOptions {
            config: Some(path),
            data_dir: dir.path().join(data),
            ..ServeOptions::default()
        })
    };
    // A CA that does not vouch for the broker: the link stays down and says why.
    let refused = start("other-ca.pem", "refused").await;
    let started = std::time::Instant::now();
    let why = loop {
        let health = refused
            .cell
            .interface("cfx")
            .map(|i| i.health().to_string())
            .unwrap_or_default();
        if health.contains("TLS") {
            break health;
        }
        assert!(started.elapsed() < LIMIT, "no TLS failure shown: {health}");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    assert!(
        why.contains("disconnected") && why.contains("certificate"),
        "{why}"
    );
    refused.stop().await;

    let trusted = start("plant-ca.pem", "trusted").await;
    let connected = next_named(&mut messages, "CFX.EndpointConnected").await;
    assert!(connected.ends_with(".placer1"), "{connected}");
    trusted.stop().await;
}
