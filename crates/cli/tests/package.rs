//! The Debian package as plant IT installs it: made by cargo-deb from this build's binary
//! (the debug one here; `scripts/package` makes the release one the same way), it holds the
//! binary, the two systemd units (which `systemd-analyze verify` accepts against the
//! package's own files), the configuration as conffiles, and maintainer scripts that make
//! the `cellbus` user in `dialout`. The packaged binary checks the packaged configuration,
//! as the unit's `ExecStartPre` does.

mod common;

use std::path::Path;
use std::process::Command;

/// Runs `program ARGS…`; its standard output, or a panic with what it said.
fn run(program: &str, args: &[&str], dir: Option<&Path>) -> String {
    let mut command = Command::new(program);
    command.args(args);
    if let Some(dir) = dir {
        command.current_dir(dir);
    }
    let output = command
        .output()
        .unwrap_or_else(|e| panic!("{program} does not run ({e}); scripts/test installs it"));
    assert!(
        output.status.success(),
        "{program} {args:?}: {}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[test]
fn the_debian_package_holds_the_binary_units_conffiles_and_a_user_and_its_units_verify() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = tempfile::tempdir().unwrap();
    let binary = Path::new(env!("CARGO_BIN_EXE_cellbus"));
    // cargo-deb takes the binary from the profile's directory: the one this test runs.
    let profile = binary.parent().and_then(Path::file_name).unwrap();
    assert_eq!(profile, "debug", "the tests run the debug build");
    run(
        "cargo",
        &[
            "deb",
            "-p",
            "cellbus-cli",
            "--no-build",
            "--profile",
            "dev",
            "--output",
            out.path().to_str().unwrap(),
        ],
        Some(&workspace),
    );
    let deb = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "deb"))
        .expect("a .deb");
    let name = deb.file_name().unwrap().to_str().unwrap().to_owned();
    let version = format!("cellbus_{}-1_", env!("CARGO_PKG_VERSION"));
    assert!(
        name.starts_with(&version) && name.ends_with(".deb"),
        "{name}"
    );

    let contents = run("dpkg-deb", &["-c", deb.to_str().unwrap()], None);
    for path in [
        "./usr/bin/cellbus",
        "./usr/lib/systemd/system/cellbus.service",
        "./usr/lib/systemd/system/cellbus-historian.service",
        "./etc/cellbus/cell.toml",
        "./usr/share/doc/cellbus/examples/60-cellbus-serial.rules",
    ] {
        assert!(
            contents.lines().any(|l| l.ends_with(path)),
            "{path} is not in the package:\n{contents}"
        );
    }
    let secrets: Vec<&str> = contents
        .lines()
        .filter(|l| l.ends_with("/etc/cellbus/env") || l.ends_with("/etc/cellbus/historian.env"))
        .collect();
    assert_eq!(secrets.len(), 2, "{contents}");
    assert!(
        secrets.iter().all(|l| l.starts_with("-rw-------")),
        "the environment files hold secrets: {secrets:?}"
    );

    let control = out.path().join("control");
    run(
        "dpkg-deb",
        &["-e", deb.to_str().unwrap(), control.to_str().unwrap()],
        None,
    );
    let conffiles = std::fs::read_to_string(control.join("conffiles")).unwrap();
    for file in [
        "/etc/cellbus/cell.toml",
        "/etc/cellbus/env",
        "/etc/cellbus/historian.env",
    ] {
        assert!(conffiles.lines().any(|l| l == file), "{file}: {conffiles}");
    }
    let postinst = std::fs::read_to_string(control.join("postinst")).unwrap();
    assert!(
        postinst.contains("adduser --system --ingroup cellbus"),
        "{postinst}"
    );
    assert!(postinst.contains("adduser cellbus dialout"), "{postinst}");
    assert!(
        postinst.contains("systemctl --system daemon-reload"),
        "{postinst}"
    );
    let fields = std::fs::read_to_string(control.join("control")).unwrap();
    assert!(fields.contains("Depends: adduser"), "{fields}");

    // The package's files in a root of their own: the units verify against them (the
    // binary they start must be there), and the packaged binary accepts the packaged
    // configuration, as ExecStartPre asks it to.
    let root = out.path().join("root");
    run(
        "dpkg-deb",
        &["-x", deb.to_str().unwrap(), root.to_str().unwrap()],
        None,
    );
    for unit in ["cellbus.service", "cellbus-historian.service"] {
        let path = root.join("usr/lib/systemd/system").join(unit);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("User=cellbus"), "{unit}");
        assert!(text.contains("NoNewPrivileges=yes"), "{unit}");
        run(
            "systemd-analyze",
            &[
                "verify",
                "--man=no",
                "--recursive-errors=no",
                &format!("--root={}", root.display()),
                path.to_str().unwrap(),
            ],
            None,
        );
    }
    let gateway =
        std::fs::read_to_string(root.join("usr/lib/systemd/system/cellbus.service")).unwrap();
    for line in [
        "Type=notify",
        "WatchdogSec=60s",
        "SupplementaryGroups=dialout",
        "StateDirectory=cellbus",
        "DevicePolicy=closed",
        "DeviceAllow=char-ttyUSB rw",
        "ExecStartPre=/usr/bin/cellbus config check /etc/cellbus/cell.toml",
    ] {
        assert!(
            gateway.lines().any(|l| l == line),
            "{line} is not in the unit"
        );
    }
    let packaged = root.join("usr/bin/cellbus");
    let checked = run(
        packaged.to_str().unwrap(),
        &[
            "config",
            "check",
            root.join("etc/cellbus/cell.toml").to_str().unwrap(),
        ],
        None,
    );
    assert!(!checked.is_empty(), "config check says what it read");
}
