//! The Debian package as plant IT installs it: made by cargo-deb from this build's binary
//! (the debug one here; `scripts/package` makes the `dist` one the same way), it holds the
//! binary, the two systemd units (which `systemd-analyze verify` accepts against the
//! package's own files), the configuration as conffiles, and maintainer scripts that make
//! the `cellbus` user in `dialout`. The packaged binary checks the packaged configuration,
//! as the unit's `ExecStartPre` does. Where the test runs as root with dpkg, the package is
//! also installed with `dpkg -i`, its binary run as its user, and purged.

mod common;

use std::fs::File;
use std::io::Write;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
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

/// Whether `program ARGS…` runs and succeeds (its output dropped).
fn succeeds(program: &str, args: &[&str]) -> bool {
    Command::new(program)
        .args(args)
        .output()
        .is_ok_and(|output| output.status.success())
}

/// Makes the package of the debug binary in `out` with `extra` cargo-deb options; its path.
fn package(out: &Path, extra: &[&str]) -> PathBuf {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let binary = Path::new(env!("CARGO_BIN_EXE_cellbus"));
    // cargo-deb takes the binary from the profile's directory: the one this test runs.
    let profile = binary.parent().and_then(Path::file_name).unwrap();
    assert_eq!(profile, "debug", "the tests run the debug build");
    let mut args = vec![
        "deb",
        "-p",
        "cellbus-cli",
        "--no-build",
        "--profile",
        "dev",
        "--output",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    // One cargo-deb at a time: both tests' runs stage the package's files under the same
    // target/debian directory, and one could archive a binary the other is copying there
    // (seen once: "Exec format error" from the extracted binary).
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    run("cargo", &args, Some(&workspace));
    std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "deb"))
        .expect("a .deb")
}

#[test]
fn the_debian_package_holds_the_binary_units_conffiles_and_a_user_and_its_units_verify() {
    let out = tempfile::tempdir().unwrap();
    let deb = package(out.path(), &[]);
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
    let depends = fields
        .lines()
        .find_map(|l| l.strip_prefix("Depends: "))
        .unwrap_or_default();
    for wanted in ["adduser", "procps"] {
        assert!(depends.split(", ").any(|d| d == wanted), "{fields}");
    }

    // The package's files in a root of their own: the units verify against them (the
    // binary they start must be there), and the packaged binary accepts the packaged
    // configuration, as ExecStartPre asks it to.
    let root = out.path().join("root");
    run(
        "dpkg-deb",
        &["-x", deb.to_str().unwrap(), root.to_str().unwrap()],
        None,
    );
    // ExecReload runs /bin/kill, which the package depends on (procps) rather than ships:
    // verify checks that it is there and executable, so the root gets a stand-in.
    std::fs::create_dir_all(root.join("bin")).unwrap();
    std::fs::write(root.join("bin/kill"), "#!/bin/sh\n").unwrap();
    std::fs::set_permissions(
        root.join("bin/kill"),
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    for unit in ["cellbus.service", "cellbus-historian.service"] {
        let path = root.join("usr/lib/systemd/system").join(unit);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("User=cellbus"), "{unit}");
        if unit == "cellbus.service" {
            assert!(
                text.contains("ExecReload=/bin/kill -HUP $MAINPID"),
                "{text}"
            );
        }
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

/// The version the installing test gives its package: an installed `cellbus` of this
/// version is a test's (one interrupted before its purge), which the next run may purge;
/// any other is someone's, which the test leaves alone.
const TEST_VERSION: &str = concat!(env!("CARGO_PKG_VERSION"), "-0~packagetest");

/// Who may install: the test runs the package's maintainer scripts, as root, with dpkg.
/// `None` when it can, or why it cannot here.
fn cannot_install() -> Option<String> {
    let uid = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let line = status.lines().find(|l| l.starts_with("Uid:"))?.to_owned();
            line.split_whitespace().nth(1)?.parse::<u32>().ok()
        });
    if uid != Some(0) {
        return Some("it is not running as root (dpkg -i needs root)".to_owned());
    }
    for tool in ["dpkg", "dpkg-query", "runuser", "getent"] {
        if !succeeds("sh", &["-c", &format!("command -v {tool}")]) {
            return Some(format!("{tool} is not installed"));
        }
    }
    None
}

/// Says why the installing part was skipped, on the test's standard error itself: the
/// test harness captures `eprintln!` of a passing test, not a write to the handle.
fn skipped(why: &str) {
    let _ = writeln!(
        std::io::stderr(),
        "package test: SKIPPED installing the package: {why}"
    );
}

/// The installed version of the `cellbus` package, if one is installed.
fn installed_version() -> Option<String> {
    let output = Command::new("dpkg-query")
        .args(["-W", "-f", "${db:Status-Status} ${Version}", "cellbus"])
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&output.stdout).into_owned();
    let (status, version) = text.split_once(' ')?;
    (output.status.success() && status != "not-installed").then(|| version.to_owned())
}

/// Purges the test's package when dropped, so a failed check leaves nothing installed.
struct Installed;

impl Drop for Installed {
    fn drop(&mut self) {
        if installed_version().as_deref() == Some(TEST_VERSION) {
            let _ = Command::new("dpkg").args(["--purge", "cellbus"]).output();
        }
    }
}

/// `getent DATABASE KEY`'s line, if it has one.
fn getent(database: &str, key: &str) -> Option<String> {
    let output = Command::new("getent").args([database, key]).output().ok()?;
    output
        .status
        .success()
        .then(|| String::from_utf8_lossy(&output.stdout).trim().to_owned())
}

#[test]
fn the_package_installs_with_its_user_runs_as_it_and_purges_without_a_trace() {
    if let Some(why) = cannot_install() {
        skipped(&format!("the package is not installed here, since {why}"));
        return;
    }
    // One installing test at a time on this machine (another checkout's run included):
    // dpkg would refuse a second one, and the two would purge each other's user.
    let lock = File::create("/run/lock/cellbus-package-test.lock")
        .or_else(|_| File::create(std::env::temp_dir().join("cellbus-package-test.lock")))
        .unwrap();
    lock.lock().unwrap();

    match installed_version() {
        Some(version) if version == TEST_VERSION => drop(Installed),
        Some(version) => {
            skipped(&format!(
                "cellbus {version} is installed on this machine; the test installs and \
                 purges its own package only where none is"
            ));
            return;
        }
        None => {}
    }
    if getent("passwd", "cellbus").is_some() || getent("group", "cellbus").is_some() {
        skipped(
            "a `cellbus` user or group exists with no cellbus package installed; the test's \
             purge would delete it",
        );
        return;
    }

    let out = tempfile::tempdir().unwrap();
    let deb = package(out.path(), &["--fast", "--deb-version", TEST_VERSION]);
    let installed = Installed;
    run("dpkg", &["-i", deb.to_str().unwrap()], None);
    assert_eq!(installed_version().as_deref(), Some(TEST_VERSION));

    // cellbus:x:UID:GID:cellbus gateway,,,:/var/lib/cellbus:/usr/sbin/nologin
    let user = getent("passwd", "cellbus").expect("the package makes the cellbus user");
    let fields: Vec<&str> = user.split(':').collect();
    assert_eq!(fields.len(), 7, "{user}");
    let uid: u32 = fields[2].parse().unwrap();
    assert!(uid < 1000, "a system user: {user}");
    assert_eq!(fields[5], "/var/lib/cellbus", "{user}");
    assert_eq!(fields[6], "/usr/sbin/nologin", "{user}");
    let group = getent("group", "cellbus").expect("the package makes the cellbus group");
    let gid: u32 = group.split(':').nth(2).unwrap().parse().unwrap();
    assert_eq!(
        fields[3],
        gid.to_string(),
        "its primary group: {user} {group}"
    );
    let groups = run("id", &["-nG", "cellbus"], None);
    assert!(
        groups.split_whitespace().any(|g| g == "dialout"),
        "cellbus is in dialout for the serial ports: {groups}"
    );

    // The secrets stay root's; the cell's configuration is readable by the gateway only.
    for (file, mode, owner) in [
        ("/etc/cellbus/env", 0o600, (0, 0)),
        ("/etc/cellbus/historian.env", 0o600, (0, 0)),
        ("/etc/cellbus/cell.toml", 0o640, (0, gid)),
        ("/usr/bin/cellbus", 0o755, (0, 0)),
    ] {
        let meta = std::fs::metadata(file).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(meta.mode() & 0o7777, mode, "{file}'s mode");
        assert_eq!((meta.uid(), meta.gid()), owner, "{file}'s owner and group");
    }

    let version = run(
        "runuser",
        &["-u", "cellbus", "--", "/usr/bin/cellbus", "--version"],
        None,
    );
    assert_eq!(
        version.trim(),
        concat!("cellbus ", env!("CARGO_PKG_VERSION")),
        "the packaged binary runs as its user"
    );
    let checked = run(
        "runuser",
        &[
            "-u",
            "cellbus",
            "--",
            "/usr/bin/cellbus",
            "config",
            "check",
            "/etc/cellbus/cell.toml",
        ],
        None,
    );
    assert!(
        !checked.is_empty(),
        "its user reads the configuration, as ExecStartPre does"
    );

    run("dpkg", &["--purge", "cellbus"], None);
    drop(installed);
    assert_eq!(installed_version(), None, "the package is purged");
    assert_eq!(
        getent("passwd", "cellbus"),
        None,
        "the purge removes the user"
    );
    assert_eq!(
        getent("group", "cellbus"),
        None,
        "the purge removes the group"
    );
    for gone in ["/etc/cellbus", "/usr/bin/cellbus", "/var/lib/cellbus"] {
        assert!(!Path::new(gone).exists(), "the purge leaves {gone}");
    }
}
