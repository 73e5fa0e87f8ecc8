//! Links the `cellbus` binary for memory: packed relative relocations and the functions it
//! runs laid out first (see `link.rs`).

include!("link.rs");

fn main() {
    println!("cargo:rerun-if-changed=link.rs");
    let manifest =
        std::path::PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    link_options(
        "bins",
        &manifest.join("code-order.txt"),
        &manifest.join("../../Cargo.lock"),
    );
}
