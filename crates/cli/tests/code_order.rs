//! The dist build's check that `crates/cli/code-order.txt` still fits the build
//! (`crates/cli/link.rs`, shared by the build scripts) and `scripts/code-order`, which
//! writes the list, agree on what a list was made for; and which builds the list lays out.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

// The build scripts' functions, as they include them (`link_options` is not called here).
include!("../link.rs");

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The made-for line of this checkout, as the build script computes it.
fn made_for_here() -> String {
    let lock = std::fs::read(root().join("Cargo.lock")).expect("the workspace has a Cargo.lock");
    format!("{}{}", MADE_FOR, made_for_line(&rustc_version(), &lock))
}

/// A code-order list whose made-for line is `made_for` (none if `None`).
fn list(made_for: Option<&str>) -> tempfile::NamedTempFile {
    let file = tempfile::NamedTempFile::new().expect("a temporary file");
    let mut text = String::from("# Functions the linker lays out first\n");
    if let Some(line) = made_for {
        text.push_str(line);
        text.push('\n');
    }
    text.push_str("_ZN4main17h0123456789abcdefE\n");
    std::fs::write(file.path(), text).expect("the list is written");
    file
}

#[test]
fn the_build_script_and_scripts_code_order_record_the_same_compiler_and_lock() {
    let output = Command::new("python3")
        .arg(root().join("scripts/code-order"))
        .arg("made-for")
        .output()
        .expect("python3 runs scripts/code-order");
    assert!(output.status.success(), "{output:?}");
    let line = String::from_utf8(output.stdout).expect("the line is text");
    assert_eq!(line.trim_end(), made_for_here());
    assert!(line.contains("rustc 1."), "{line}");
}

#[test]
fn a_list_made_for_this_compiler_and_lock_is_not_stale() {
    let file = list(Some(&made_for_here()));
    let rustc = rustc_version();
    assert_eq!(stale(file.path(), &root().join("Cargo.lock"), &rustc), None);
}

#[test]
fn a_list_made_for_another_lock_is_stale_and_names_both() {
    let other = "rustc 1.95.0 (59807616e 2026-04-14), Cargo.lock fnv1a64 0000000000000000";
    let file = list(Some(&format!("{}{other}", MADE_FOR)));
    let rustc = rustc_version();
    let why = stale(file.path(), &root().join("Cargo.lock"), &rustc)
        .expect("another lock's list is stale");
    assert!(
        why.starts_with(&format!("was made for {other}, this build is ")),
        "{why}"
    );
    assert!(
        why.ends_with(made_for_here().trim_start_matches(MADE_FOR)),
        "{why}"
    );
}

#[test]
fn a_list_that_does_not_say_what_it_was_made_for_is_stale() {
    let file = list(None);
    let why = stale(file.path(), &root().join("Cargo.lock"), "rustc 1.95.0")
        .expect("a list without the line is stale");
    assert_eq!(
        why,
        "does not say which compiler and Cargo.lock it was made for"
    );
}

#[test]
fn only_the_dist_builds_and_the_bench_profiles_benches_lay_code_out() {
    let out = |profile: &str| format!("/work/target/{profile}/build/cellbus-cli-0123abcd/out");
    assert!(lays_out_code("bins", &out("dist"), "3"));
    assert!(lays_out_code("benches", &out("dist"), "3"));
    // cargo puts the bench profile's builds (opt-level 3) into target/release, beside the
    // release profile's (opt-level s).
    assert!(lays_out_code("benches", &out("release"), "3"));
    assert!(!lays_out_code("benches", &out("release"), "s"));
    // The release profile's binary, and the debug builds, keep the compiler's order.
    assert!(!lays_out_code("bins", &out("release"), "s"));
    assert!(!lays_out_code("bins", &out("debug"), "0"));
    assert!(!lays_out_code("benches", &out("debug"), "0"));
    // With --target, the triple comes before the profile; a `build` in the target
    // directory's own path does not count.
    assert!(lays_out_code(
        "bins",
        "/home/build/t/x86_64-unknown-linux-gnu/dist/build/cellbus-cli-0123abcd/out",
        "3"
    ));
    assert!(!lays_out_code("bins", "", "3"));
}
