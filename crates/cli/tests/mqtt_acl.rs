//! The broker access control of the user guide's recipe, `docs/mosquitto/cellbus.acl`, on a
//! real mosquitto: the gateway (`cellbus serve` with the gateway's login) is born and
//! publishes through it; a client with a valid login that the file does not name cannot
//! publish a gateway's data or death, the host's STATE, or a command, and a client without
//! a login cannot connect.

mod common;

use std::path::Path;
use std::process::{Child, Stdio};
use std::time::Duration;

use rumqttc::{AsyncClient, ConnectReturnCode, Event, MqttOptions, Packet, QoS};
use testkit::{Mosquitto, password_file};
use tokio::sync::mpsc;

/// Generous: a loaded 2-core machine, a gateway starting.
const LIMIT: Duration = Duration::from_secs(60);

/// What a test client hears: messages (topic, payload), publish acknowledgements, and
/// whether the broker took the connection.
enum Heard {
    Message(String, Vec<u8>),
    Acked,
    Connected(ConnectReturnCode),
}

struct Client {
    client: AsyncClient,
    heard: mpsc::UnboundedReceiver<Heard>,
}

impl Client {
    /// Connects as `user` (no login when `None`) and subscribes to `filter`.
    async fn connect(broker: &Mosquitto, user: Option<(&str, &str)>, filter: &str) -> Client {
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let id = format!("acl-test-{}-{n}", std::process::id());
        let mut options = MqttOptions::new(id, "127.0.0.1", broker.port());
        if let Some((name, password)) = user {
            options.set_credentials(name, password);
        }
        let (client, mut eventloop) = AsyncClient::new(options, 100);
        let (tx, heard) = mpsc::unbounded_channel();
        client
            .subscribe(filter, QoS::AtLeastOnce)
            .await
            .expect("queued");
        tokio::spawn(async move {
            loop {
                let heard = match eventloop.poll().await {
                    Ok(Event::Incoming(Packet::ConnAck(ack))) => Heard::Connected(ack.code),
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        Heard::Message(p.topic, p.payload.to_vec())
                    }
                    Ok(Event::Incoming(Packet::PubAck(_))) => Heard::Acked,
                    Ok(_) => continue,
                    Err(rumqttc::ConnectionError::ConnectionRefused(code)) => {
                        let _ = tx.send(Heard::Connected(code));
                        return;
                    }
                    Err(_) => return,
                };
                if tx.send(heard).is_err() {
                    return;
                }
            }
        });
        Client { client, heard }
    }

    /// How the broker answered the connection.
    async fn connected(&mut self) -> ConnectReturnCode {
        tokio::time::timeout(LIMIT, async {
            loop {
                match self.heard.recv().await {
                    Some(Heard::Connected(code)) => return code,
                    Some(_) => {}
                    None => panic!("the client ended before the broker answered"),
                }
            }
        })
        .await
        .expect("the broker answers the connection")
    }

    /// Publishes (QoS 1) and waits for the broker's acknowledgement: the broker has then
    /// handled the message, delivered or dropped.
    async fn publish_acked(&mut self, topic: &str, retain: bool, payload: &[u8]) {
        self.client
            .publish(topic, QoS::AtLeastOnce, retain, payload.to_vec())
            .await
            .expect("queued");
        tokio::time::timeout(LIMIT, async {
            loop {
                match self.heard.recv().await {
                    Some(Heard::Acked) => return,
                    Some(_) => {}
                    None => panic!("the client ended before the acknowledgement"),
                }
            }
        })
        .await
        .unwrap_or_else(|_| panic!("no acknowledgement of {topic}"));
    }

    /// Every message heard until one on `topic` with `payload`, that one included.
    async fn until(&mut self, topic: &str, payload: &[u8]) -> Vec<(String, Vec<u8>)> {
        let mut heard = Vec::new();
        tokio::time::timeout(LIMIT, async {
            loop {
                match self.heard.recv().await {
                    Some(Heard::Message(t, p)) => {
                        let done = t == topic && p == payload;
                        heard.push((t, p));
                        if done {
                            return;
                        }
                    }
                    Some(_) => {}
                    None => panic!("the client ended"),
                }
            }
        })
        .await
        .unwrap_or_else(|_| panic!("nothing on {topic} within {LIMIT:?}: heard {heard:?}"));
        heard
    }
}

/// `cellbus serve` with a config file; killed when dropped.
struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn state(online: bool) -> Vec<u8> {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("after 1970")
        .as_millis();
    format!("{{\"online\":{online},\"timestamp\":{now}}}").into_bytes()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_documented_acl_lets_the_gateway_publish_and_drops_a_rogues_data_death_state_and_commands()
 {
    let dir = tempfile::tempdir().unwrap();
    let passwords = dir.path().join("passwords");
    password_file(
        &passwords,
        &[
            ("gw-cell1", "gw-secret"),
            ("historian", "historian-secret"),
            ("operator", "operator-secret"),
            ("rogue", "rogue-secret"),
        ],
    );
    let acl = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/mosquitto/cellbus.acl");
    let broker = Mosquitto::start_with_access(&passwords, &acl);

    // Without a login, no connection at all.
    let mut anonymous = Client::connect(&broker, None, "spBv1.0/#").await;
    assert_ne!(anonymous.connected().await, ConnectReturnCode::Success);

    // The historian's login reads everything and announces the host.
    let mut historian = Client::connect(
        &broker,
        Some(("historian", "historian-secret")),
        "spBv1.0/#",
    )
    .await;
    assert_eq!(historian.connected().await, ConnectReturnCode::Success);
    historian
        .publish_acked("spBv1.0/STATE/plant", true, &state(true))
        .await;

    // The gateway, with the gateway's login, a station that does not answer (port 9).
    let config = dir.path().join("cell.toml");
    std::fs::write(
        &config,
        format!(
            "[[line]]\nname = \"rework\"\nendpoint = \"tcp://127.0.0.1:9\"\n\n\
             [[line.device]]\nid = \"jbc1\"\nprotocol = \"jbc\"\naddress = 1\n\n\
             [mqtt]\nbroker = \"{}\"\ngroup_id = \"cell\"\nedge_node_id = \"cell1\"\n\
             username = \"gw-cell1\"\npassword_env = \"CELLBUS_TEST_MQTT_PASSWORD\"\n\
             primary_host = \"plant\"\n",
            broker.url()
        ),
    )
    .unwrap();
    let _gateway = Served(
        common::cellbus()
            .args(["serve", "--listen", "127.0.0.1:0", "--data"])
            .arg(dir.path().join("data"))
            .arg("--config")
            .arg(&config)
            .env("CELLBUS_TEST_MQTT_PASSWORD", "gw-secret")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("cellbus runs"),
    );
    let born = tokio::time::timeout(LIMIT, async {
        loop {
            if let Some(Heard::Message(topic, _)) = historian.heard.recv().await
                && topic == "spBv1.0/cell/DBIRTH/cell1/jbc1"
            {
                return;
            }
        }
    })
    .await;
    assert!(born.is_ok(), "the gateway is born through the ACL");

    // A valid login the file does not name: everything it publishes is dropped.
    let mut rogue = Client::connect(&broker, Some(("rogue", "rogue-secret")), "rogue/#").await;
    assert_eq!(rogue.connected().await, ConnectReturnCode::Success);
    let forged = [
        (
            "spBv1.0/cell/DDATA/cell1/jbc1",
            false,
            b"forged data".to_vec(),
        ),
        ("spBv1.0/cell/NDEATH/cell1", false, b"forged death".to_vec()),
        ("spBv1.0/STATE/plant", true, state(false)),
        (
            "spBv1.0/cell/DCMD/cell1/jbc1",
            false,
            b"forged command".to_vec(),
        ),
    ];
    for (topic, retain, payload) in &forged {
        rogue.publish_acked(topic, *retain, payload).await;
    }
    // The gateway's own login cannot speak as the host or send commands either.
    let mut gateway_login =
        Client::connect(&broker, Some(("gw-cell1", "gw-secret")), "rogue/#").await;
    assert_eq!(gateway_login.connected().await, ConnectReturnCode::Success);
    gateway_login
        .publish_acked("spBv1.0/STATE/plant", true, &state(false))
        .await;
    gateway_login
        .publish_acked("spBv1.0/cell/DCMD/cell1/jbc1", false, b"gateway's command")
        .await;

    // The operator's command is delivered: everything handled before it was too, if at all.
    let mut operator =
        Client::connect(&broker, Some(("operator", "operator-secret")), "operator/#").await;
    assert_eq!(operator.connected().await, ConnectReturnCode::Success);
    operator
        .publish_acked("spBv1.0/cell/DCMD/cell1/jbc1", false, b"operator's mark")
        .await;
    let heard = historian
        .until("spBv1.0/cell/DCMD/cell1/jbc1", b"operator's mark")
        .await;
    for (topic, payload) in &heard {
        assert!(
            !forged.iter().any(|(_, _, p)| p == payload)
                && payload.as_slice() != b"gateway's command"
                && !String::from_utf8_lossy(payload).contains("\"online\":false"),
            "the broker delivered {topic}: {:?}",
            String::from_utf8_lossy(payload)
        );
    }
    // The host's retained STATE is still its own.
    let mut fresh = Client::connect(
        &broker,
        Some(("historian", "historian-secret")),
        "spBv1.0/STATE/plant",
    )
    .await;
    let retained = tokio::time::timeout(LIMIT, async {
        loop {
            if let Some(Heard::Message(_, payload)) = fresh.heard.recv().await {
                return payload;
            }
        }
    })
    .await
    .expect("the retained STATE");
    assert!(
        String::from_utf8_lossy(&retained).contains("\"online\":true"),
        "{}",
        String::from_utf8_lossy(&retained)
    );
}
