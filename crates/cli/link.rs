// How the `cellbus` binary and the gateway's benches are linked, shared by
// crates/cli/build.rs and crates/gateway/build.rs (`include!`), so the benches measure the
// memory the binary uses.
//
// On Linux with glibc:
// - Packed relative relocations (DT_RELR): a position-independent executable's table of
//   relocations to apply at start shrinks from 1.7 MB (read in full at every start, so
//   resident) to 19 kB. GNU ld 2.38+ and lld use it only when the C library supports it
//   (glibc 2.36+); older linkers ignore the option with a warning.
// - In the builds that lay code out (the `dist` profile, the package's; and for the
//   benches the `bench` profile too, which shares target/release: `lays_out_code`) when
//   linked by lld (Rust 1.90 and later on x86_64 Linux, unless another linker is
//   configured), the functions listed in crates/cli/code-order.txt are laid out first, in
//   that order: the few thousand functions a gateway runs sit side by side
//   instead of spread over 20 MB of code, and the kernel maps only their pages (DESIGN.md,
//   "Code layout"; scripts/code-order writes the list). Names the binary does not define
//   are skipped, so a stale list costs memory, never a failed build; a release build warns
//   when the list was made for another compiler or Cargo.lock.

/// Prints the link options for the targets of `kind` (`bins` or `benches`) of the crate
/// being built, from which `cli_dir` is crates/cli (where this file and code-order.txt
/// are): `.` for the binary's crate, `../cli` for the gateway's benches.
fn link_crate(kind: &str, cli_dir: &str) {
    println!("cargo:rerun-if-changed={cli_dir}/link.rs");
    let manifest =
        std::path::PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    link_options(
        kind,
        &manifest.join(cli_dir).join("code-order.txt"),
        &manifest.join("../../Cargo.lock"),
    );
}

/// Prints the link options for the targets of `kind` (`bins` or `benches`); `lock` is the
/// workspace's Cargo.lock.
fn link_options(kind: &str, code_order: &std::path::Path, lock: &std::path::Path) {
    let var = |name: &str| std::env::var(name).unwrap_or_default();
    println!("cargo:rerun-if-changed={}", code_order.display());
    println!("cargo:rerun-if-env-changed=RUSTC_LINKER");
    if var("CARGO_CFG_TARGET_OS") != "linux" || var("CARGO_CFG_TARGET_ENV") != "gnu" {
        return;
    }
    println!("cargo:rustc-link-arg-{kind}=-Wl,-z,pack-relative-relocs");
    if !lays_out_code(kind, &var("OUT_DIR"), &var("OPT_LEVEL")) || !code_order.is_file() {
        return;
    }
    // Only here: `rustc --version` is a process of its own, which other builds skip.
    let rustc = rustc_version();
    if !links_with_lld(&var, &rustc) {
        return;
    }
    println!(
        "cargo:rustc-link-arg-{kind}=-Wl,--symbol-ordering-file={}",
        code_order.display()
    );
    println!("cargo:rustc-link-arg-{kind}=-Wl,--no-warn-symbol-ordering");
    println!("cargo:rerun-if-changed={}", lock.display());
    if let Some(why) = stale(code_order, lock, &rustc) {
        println!(
            "cargo:warning=crates/cli/code-order.txt {why}: the functions it lists may have \
             other names in this build, so the binary works the same but its code may not \
             be laid out by use and take more memory (scripts/code-order writes a new list)"
        );
    }
}

/// Whether the targets of `kind` built into `out_dir` (the build script's `OUT_DIR`) at
/// `opt_level` (its `OPT_LEVEL`) are laid out by crates/cli/code-order.txt: those of the
/// `dist` profile (one optimisation unit, whose function names the list can match), and
/// the benches of the `bench` profile (one unit too, in the workspace's Cargo.toml). The
/// quick `release` profile (16 units a crate, optimised for size) has other names, some
/// with per-unit `.llvm.` suffixes, so its builds are left in the compiler's order. Cargo
/// tells a build script its profile only as `PROFILE=release` or `debug` (`release` for
/// every optimised profile), so the profile's name is read from `OUT_DIR`:
/// `TARGET_DIR/[TRIPLE/]PROFILE/build/PACKAGE-HASH/out`, the directory before the last
/// `build`. `bench` and `release` share `target/release`: there `bench` is the one at
/// `opt-level = 3` (`release` is at `s`).
fn lays_out_code(kind: &str, out_dir: &str, opt_level: &str) -> bool {
    let parts: Vec<&std::ffi::OsStr> = std::path::Path::new(out_dir).iter().collect();
    let profile = parts
        .iter()
        .rposition(|part| *part == "build")
        .and_then(|at| at.checked_sub(1))
        .and_then(|at| parts[at].to_str())
        .unwrap_or_default();
    profile == "dist" || (profile == "release" && kind == "benches" && opt_level == "3")
}

/// What a code-order list records of the build it was made from (written by
/// scripts/code-order): the compiler's version and a digest of Cargo.lock, since the
/// symbol names it lists carry hashes that change with either.
const MADE_FOR: &str = "# made for: ";

/// Why the list in `code_order` no longer matches this build, if it does not.
fn stale(code_order: &std::path::Path, lock: &std::path::Path, rustc: &str) -> Option<String> {
    let list = std::fs::read_to_string(code_order).unwrap_or_default();
    let Some(made_for) = list.lines().find_map(|line| line.strip_prefix(MADE_FOR)) else {
        return Some("does not say which compiler and Cargo.lock it was made for".to_owned());
    };
    let lock = std::fs::read(lock).unwrap_or_default();
    let now = made_for_line(rustc, &lock);
    (made_for != now).then(|| format!("was made for {made_for}, this build is {now}"))
}

/// `rustc 1.95.0 (59807616e 2026-04-14), Cargo.lock fnv1a64 0123456789abcdef`.
fn made_for_line(rustc: &str, lock: &[u8]) -> String {
    // FNV-1a, 64 bits: scripts/code-order computes the same.
    let digest = lock.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    format!("{rustc}, Cargo.lock fnv1a64 {digest:016x}")
}

/// `rustc --version`, e.g. "rustc 1.95.0 (59807616e 2026-04-14)"; empty if it cannot run.
fn rustc_version() -> String {
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    std::process::Command::new(rustc)
        .arg("--version")
        .output()
        .map(|output| String::from_utf8_lossy(&output.stdout).trim().to_owned())
        .unwrap_or_default()
}

/// Whether rustc links with its own lld: its default on x86_64 Linux since Rust 1.90, when
/// neither a linker nor linker flags are configured.
fn links_with_lld(var: &dyn Fn(&str) -> String, rustc: &str) -> bool {
    let flags = var("CARGO_ENCODED_RUSTFLAGS");
    if var("TARGET") != "x86_64-unknown-linux-gnu"
        || !var("RUSTC_LINKER").is_empty()
        || flags.contains("linker")
        || flags.contains("fuse-ld")
    {
        return false;
    }
    // "rustc 1.95.0 (59807616e 2026-04-14)"
    let number: Vec<u32> = (rustc.split_whitespace().nth(1).unwrap_or_default().split('.'))
        .map_while(|part| part.parse().ok())
        .collect();
    matches!(number[..], [1, minor, ..] if minor >= 90) || matches!(number[..], [major, ..] if major > 1)
}
