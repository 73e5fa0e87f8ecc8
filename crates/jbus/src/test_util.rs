//! Helpers the crate's unit tests share.

use wire::{Codec, Deframer};

/// Bytes written as hex pairs separated by spaces: `"01 03 00 0A"`.
pub(crate) fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("test hex"))
        .collect()
}

/// The frames a deframer with `codec` finds in `stream`, what it drops as damage left out.
pub(crate) fn good_frames<C: Codec>(codec: C, stream: &[u8]) -> Vec<C::Frame> {
    let mut deframer = Deframer::new(codec);
    deframer.push(stream);
    std::iter::from_fn(|| deframer.next_frame())
        .filter_map(Result::ok)
        .collect()
}
