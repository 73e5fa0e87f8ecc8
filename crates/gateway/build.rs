//! Links the benches like the `cellbus` binary (see `crates/cli/link.rs`), so the load
//! bench's memory figures are the binary's.

include!("../cli/link.rs");

fn main() {
    link_crate("benches", "../cli");
}
