// How the `cellbus` binary and the gateway's benches are linked, shared by
// crates/cli/build.rs and crates/gateway/build.rs (`include!`), so the benches measure the
// memory the binary uses.
//
// On Linux with glibc:
// - Packed relative relocations (DT_RELR): a position-independent executable's table of
//   relocations to apply at start shrinks from 1.7 MB (read in full at every start, so
//   resident) to 19 kB. GNU ld 2.38+ and lld use it only when the C library supports it
//   (glibc 2.36+); older linkers ignore the option with a warning.
// - In optimised builds linked by lld (Rust 1.90 and later on x86_64 Linux, unless another
//   linker is configured), the functions listed in crates/cli/code-order.txt are laid out
//   first, in that order: the few thousand functions a gateway runs sit side by side
//   instead of spread over 20 MB of code, and the kernel maps only their pages (DESIGN.md,
//   "Code layout"; scripts/code-order writes the list). Names the binary does not define
//   are skipped, so a stale list costs memory, never a failed build.

/// Prints the link options for the targets of `kind` (`bins` or `benches`).
fn link_options(kind: &str, code_order: &std::path::Path) {
    let var = |name: &str| std::env::var(name).unwrap_or_default();
    println!("cargo:rerun-if-changed={}", code_order.display());
    println!("cargo:rerun-if-env-changed=RUSTC_LINKER");
    if var("CARGO_CFG_TARGET_OS") != "linux" || var("CARGO_CFG_TARGET_ENV") != "gnu" {
        return;
    }
    println!("cargo:rustc-link-arg-{kind}=-Wl,-z,pack-relative-relocs");
    if var("PROFILE") == "release" && code_order.is_file() && links_with_lld(&var) {
        println!(
            "cargo:rustc-link-arg-{kind}=-Wl,--symbol-ordering-file={}",
            code_order.display()
        );
        println!("cargo:rustc-link-arg-{kind}=-Wl,--no-warn-symbol-ordering");
    }
}

/// Whether rustc links with its own lld: its default on x86_64 Linux since Rust 1.90, when
/// neither a linker nor linker flags are configured.
fn links_with_lld(var: &dyn Fn(&str) -> String) -> bool {
    let flags = var("CARGO_ENCODED_RUSTFLAGS");
    if var("TARGET") != "x86_64-unknown-linux-gnu"
        || !var("RUSTC_LINKER").is_empty()
        || flags.contains("linker")
        || flags.contains("fuse-ld")
    {
        return false;
    }
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let Ok(output) = std::process::Command::new(rustc).arg("--version").output() else {
        return false;
    };
    // "rustc 1.95.0 (59807616e 2026-04-14)"
    let version = String::from_utf8_lossy(&output.stdout);
    let number: Vec<u32> = (version.split_whitespace().nth(1).unwrap_or_default().split('.'))
        .map_while(|part| part.parse().ok())
        .collect();
    matches!(number[..], [1, minor, ..] if minor >= 90) || matches!(number[..], [major, ..] if major > 1)
}
