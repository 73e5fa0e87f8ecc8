use super::*;
use crate::testing::config::parse;

/// A line `name` with the JBC station `id` (its `extra` keys) at port `port`.
fn station(name: &str, port: u16, id: &str, extra: &str) -> String {
    format!(
        "[[line]]\nname = \"{name}\"\nendpoint = \"tcp://127.0.0.1:{port}\"\n\
         [[line.device]]\nid = \"{id}\"\nprotocol = \"jbc\"\n{extra}\n"
    )
}

/// A cell of three JBC stations, each on a line of its own.
fn three() -> String {
    [
        station("a", 7001, "jbc_a", ""),
        station("b", 7002, "jbc_b", ""),
        station("c", 7003, "jbc_c", ""),
    ]
    .concat()
}

fn ids(ids: &[DeviceId]) -> Vec<&str> {
    ids.iter().map(DeviceId::as_str).collect()
}

#[test]
fn the_same_file_again_keeps_every_line_and_changes_nothing() {
    let config = parse(&three()).unwrap();
    let plan = plan(&config, &config);
    assert!(plan.is_empty(), "{plan:?}");
    assert_eq!(plan.kept, ["a", "b", "c"]);
    assert!(plan.added.is_empty() && plan.removed.is_empty() && plan.changed.is_empty());
    assert!(plan.restart_needed.is_empty());
}

#[test]
fn a_line_removed_stops_a_line_added_starts_and_a_changed_device_restarts_only_its_line() {
    let old = parse(&three()).unwrap();
    let new = parse(
        &[
            station("a", 7001, "jbc_a", ""),
            station("c", 7003, "jbc_c", "name = \"Rework station C\""),
            station("d", 7004, "jbc_d", ""),
        ]
        .concat(),
    )
    .unwrap();
    let plan = plan(&old, &new);
    assert_eq!(plan.kept, ["a"]);
    assert_eq!(plan.stop, ["c", "b"]);
    assert_eq!(plan.start, ["c", "d"]);
    assert_eq!(ids(&plan.added), ["jbc_d"]);
    assert_eq!(ids(&plan.removed), ["jbc_b"]);
    assert_eq!(ids(&plan.changed), ["jbc_c"]);
}

#[test]
fn a_line_whose_endpoint_moved_restarts_but_its_unchanged_device_is_not_changed() {
    let old = parse(&three()).unwrap();
    let new = parse(&three().replace("7002", "7012")).unwrap();
    let plan = plan(&old, &new);
    assert_eq!(plan.stop, ["b"]);
    assert_eq!(plan.start, ["b"]);
    assert!(plan.changed.is_empty(), "{plan:?}");
}

#[test]
fn a_changed_token_or_interface_table_is_named_as_needing_a_restart() {
    let old = parse(&three()).unwrap();
    let new = parse(&format!(
        "token = \"a-new-token-for-writes\"\n\n[mqtt]\nbroker = \"mqtt://127.0.0.1:1883\"\n{}",
        three()
    ))
    .unwrap();
    let plan = plan(&old, &new);
    assert!(plan.is_empty(), "{plan:?}");
    assert_eq!(plan.restart_needed, ["token", "[mqtt]"]);
}

#[test]
fn the_event_of_a_reload_lists_the_devices_for_the_interfaces() {
    let old = parse(&three()).unwrap();
    let new = parse(&three().replace("jbc_b", "jbc_e")).unwrap();
    let plan = plan(&old, &new);
    let event = reloaded_event(&plan, std::path::Path::new("/etc/cellbus/cell.toml"));
    assert_eq!(event.kind, EventKind::ConfigReloaded);
    assert_eq!(ids(&devices_in(&event, "added")), ["jbc_e"]);
    assert_eq!(ids(&devices_in(&event, "removed")), ["jbc_b"]);
    assert!(devices_in(&event, "changed").is_empty());
    assert_eq!(
        event.message,
        "configuration reloaded from /etc/cellbus/cell.toml: devices added: jbc_e; \
         devices removed: jbc_b; 2 lines keep polling"
    );
}
