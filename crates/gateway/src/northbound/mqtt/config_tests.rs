//! The `[mqtt]` table: what it reads, its defaults, and each mistake where it is.

use std::path::Path;

use super::*;
use crate::config::CellConfig;
use crate::config::table::hide_userinfo;
use crate::plugins::parse_config;
use crate::testing::config::{ONE, parse, refused};

/// The `[mqtt]` table, if the file has one.
fn mqtt_table(config: &CellConfig) -> Option<MqttConfig> {
    config.interface::<MqttConfig>("mqtt").cloned()
}

#[test]
fn no_mqtt_table_means_no_mqtt() {
    assert_eq!(mqtt_table(&parse(ONE).unwrap()), None);
}

#[test]
fn an_mqtt_table_is_read_with_its_defaults() {
    let text =
        format!("{ONE}\n[mqtt]\nbroker = \"mqtt://broker.local\"\nedge_node_id = \"cell-7\"\n");
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!((mqtt.host.as_str(), mqtt.port), ("broker.local", 1883));
    assert_eq!(mqtt.group_id, "cellbus");
    assert_eq!(mqtt.client_id, "cellbus-cell-7");
    assert_eq!(mqtt.keep_alive, DEFAULT_MQTT_KEEP_ALIVE);
    assert_eq!((mqtt.username, mqtt.password_env), (None, None));
}

#[test]
fn mqtt_mistakes_are_refused_where_they_are() {
    let at = |table: &str| format!("{ONE}\n[mqtt]\n{table}");
    refused(
        &at("broker = \"http://b\"\n"),
        11,
        10,
        "write mqtt://host:1883",
    );
    refused(
        &at("broker = \"mqtt://b\"\npassword = \"x\"\n"),
        12,
        1,
        "unknown field `password`",
    );
    refused(
        &at("broker = \"mqtt://b\"\ngroup_id = \"a/b\"\n"),
        12,
        12,
        "group_id",
    );
    refused(
        &at("broker = \"mqtt://b\"\nkeep_alive = \"1ms\"\n"),
        12,
        14,
        "keep_alive",
    );
    refused(
        &at("broker = \"mqtt://b:0\"\n"),
        11,
        10,
        "port 0 is not a port a broker listens on",
    );
    refused(
        &at(&format!(
            "broker = \"mqtt://b\"\nclient_id = \"{}\"\n",
            "c".repeat(70_000)
        )),
        12,
        13,
        "client_id is 70000 bytes; MQTT carries at most 65535",
    );
}

#[test]
fn the_mqtt_modes_commands_primary_host_and_backlog_are_read_with_their_defaults() {
    let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\nedge_node_id = \"cell-7\"\n");
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!(mqtt.mode, MqttMode::Sparkplug);
    assert_eq!(mqtt.prefix, "cellbus/cell-7");
    assert!(!mqtt.commands);
    assert_eq!(mqtt.primary_host, None);
    assert_eq!(mqtt.max_backlog, DEFAULT_MQTT_BACKLOG);
    assert_eq!(mqtt.max_command_metrics, DEFAULT_MQTT_COMMAND_METRICS);
    assert_eq!(mqtt.check_retained, DEFAULT_MQTT_CHECK_RETAINED);
    let text = format!(
        "{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\nmode = \"JSON\"\nprefix = \"plant/cell7/\"\n\
         commands = true\nprimary_host = \"scada\"\nmax_backlog = 5000\n\
         max_command_metrics = 8\ncheck_retained = \"1h\"\n"
    );
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!(mqtt.mode, MqttMode::Json);
    assert_eq!(mqtt.prefix, "plant/cell7", "a trailing / is dropped");
    assert!(mqtt.commands);
    assert_eq!(mqtt.primary_host.as_deref(), Some("scada"));
    assert_eq!(mqtt.max_backlog, 5000);
    assert_eq!(mqtt.max_command_metrics, 8);
    assert_eq!(mqtt.check_retained, Duration::from_secs(3600));
}

#[test]
fn mqtt_mode_prefix_primary_host_and_backlog_mistakes_are_refused_where_they_are() {
    let at = |line: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\n{line}\n");
    refused(
        &at("mode = \"xml\""),
        12,
        8,
        "write \"sparkplug\" or \"json\"",
    );
    refused(&at("prefix = \"a/#\""), 12, 10, "not a usable topic prefix");
    refused(&at("primary_host = \"a+b\""), 12, 16, "primary_host");
    refused(&at("max_backlog = 0"), 12, 15, "outside 1–100000000");
    refused(&at("max_command_metrics = 0"), 12, 23, "outside 1–10000");
    refused(&at("check_retained = \"1s\""), 12, 18, "out of range");
    refused(&at("commands = \"yes\""), 12, 12, "bool");
}

#[test]
fn an_mqtts_broker_takes_port_8883_and_trusts_the_systems_roots_by_default() {
    let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtts://broker.local\"\n");
    let mqtt = mqtt_table(&parse(&text).unwrap()).unwrap();
    assert_eq!((mqtt.host.as_str(), mqtt.port), ("broker.local", 8883));
    assert_eq!(mqtt.tls, Some(MqttTls::default()));
    let cli = MqttConfig::for_broker("mqtts://b:18883", "cell").unwrap();
    assert_eq!((cli.port, cli.tls), (18883, Some(MqttTls::default())));
    let plain = MqttConfig::for_broker("mqtt://b", "cell").unwrap();
    assert_eq!((plain.port, plain.tls), (1883, None));
}

#[test]
fn tls_keys_with_an_mqtt_broker_are_refused_naming_the_key() {
    let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtt://b\"\n{table}");
    refused(&at("ca_file = \"ca.pem\"\n"), 12, 11, "ca_file is for TLS");
    refused(
        &at("client_key = \"k.pem\"\n"),
        12,
        14,
        "client_key is for TLS",
    );
}

#[test]
fn a_client_cert_without_its_key_is_refused_and_the_other_way_round() {
    let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\n{table}");
    refused(
        &at("client_cert = \"c.pem\"\n"),
        12,
        15,
        "client_cert needs client_key",
    );
    refused(
        &at("client_key = \"k.pem\"\n"),
        12,
        14,
        "client_key needs client_cert",
    );
}

#[test]
fn tls_files_are_read_relative_to_the_config_file_and_named_when_missing() {
    let text = format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\nca_file = \"certs/ca.pem\"\n");
    let err = parse_config(&text, Path::new("/nonexistent/cellbus/cell.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(":12:11: ca_file /nonexistent/cellbus/certs/ca.pem: cannot be read"),
        "{err}"
    );
}

#[test]
fn tls_files_that_are_not_pem_are_refused_without_showing_a_key() {
    let dir = tempfile::tempdir().unwrap();
    let key = rcgen::KeyPair::generate().unwrap();
    let cert = rcgen::CertificateParams::new(vec!["gateway".to_owned()])
        .unwrap()
        .self_signed(&key)
        .unwrap();
    std::fs::write(dir.path().join("ca.pem"), cert.pem()).unwrap();
    std::fs::write(dir.path().join("gateway.pem"), cert.pem()).unwrap();
    std::fs::write(dir.path().join("gateway.key"), key.serialize_pem()).unwrap();
    std::fs::write(dir.path().join("notes.txt"), "no PEM here").unwrap();
    let secret = key.serialize_pem().replace("PRIVATE KEY", "PRIVAT KEY");
    std::fs::write(dir.path().join("mangled.key"), &secret).unwrap();
    let path = dir.path().join("cell.toml");
    let at = |table: &str| format!("{ONE}\n[mqtt]\nbroker = \"mqtts://b\"\n{table}");

    let good = parse_config(
        &at("ca_file = \"ca.pem\"\nclient_cert = \"gateway.pem\"\nclient_key = \"gateway.key\"\n"),
        &path,
    )
    .unwrap();
    let tls = mqtt_table(&good).unwrap().tls.unwrap();
    assert_eq!(tls.ca_file, Some(dir.path().join("ca.pem")));
    assert_eq!(
        tls.client,
        Some(MqttClientCert {
            cert: dir.path().join("gateway.pem"),
            key: dir.path().join("gateway.key"),
        })
    );

    let err = parse_config(&at("ca_file = \"notes.txt\"\n"), &path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("notes.txt holds no certificate"), "{err}");
    let err = parse_config(
        &at("client_cert = \"gateway.pem\"\nclient_key = \"mangled.key\"\n"),
        &path,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains(":13:14: client_key "), "{err}");
    assert!(err.contains("mangled.key: "), "{err}");
    let body: String = secret.lines().filter(|l| !l.starts_with("-----")).collect();
    assert!(!err.contains(&body[..16]), "{err}");
}

#[test]
fn a_broker_url_with_a_user_and_password_is_refused_without_showing_them() {
    let err = parse_broker("mqtt://user:pw@127.0.0.1:1883").unwrap_err();
    assert!(!err.contains("pw") && !err.contains("user:"), "{err}");
    assert!(err.contains("mqtt://(hidden)@127.0.0.1:1883"), "{err}");
    let text = format!("[mqtt]\nbroker = \"mqtt://user:pw@127.0.0.1:1883\"\n{ONE}");
    let shown = parse(&text).unwrap_err().to_string();
    assert!(!shown.contains("pw"), "{shown}");
    assert_eq!(
        hide_userinfo("mqtt://host:1883/a@b"),
        "mqtt://host:1883/a@b"
    );
}
