//! Links the benches like the `cellbus` binary (see `crates/cli/build.rs`): packed relative
//! relocations on Linux with glibc, so the load bench's memory figures are the binary's.

fn main() {
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    let env = std::env::var("CARGO_CFG_TARGET_ENV").unwrap_or_default();
    if os == "linux" && env == "gnu" {
        println!("cargo:rustc-link-arg-benches=-Wl,-z,pack-relative-relocs");
    }
}
