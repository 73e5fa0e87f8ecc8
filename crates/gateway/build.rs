//! Links the benches like the `cellbus` binary (see `crates/cli/link.rs`), so the load
//! bench's memory figures are the binary's.

include!("../cli/link.rs");

fn main() {
    println!("cargo:rerun-if-changed=../cli/link.rs");
    let manifest =
        std::path::PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    link_options(
        "benches",
        &manifest.join("../cli/code-order.txt"),
        &manifest.join("../../Cargo.lock"),
    );
}
