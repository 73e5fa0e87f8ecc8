//! Links the `cellbus` binary for memory: packed relative relocations and the functions it
//! runs laid out first (see `link.rs`).

include!("link.rs");

fn main() {
    link_crate("bins", ".");
}
