//! Newline-framed bytes: the simplest framing, for the crate's unit tests of what runs on
//! top of a codec.

/// The frame at the start of `buf` (its bytes up to the first `\n`) and the bytes it
/// takes with the `\n`; `None` while no `\n` has come.
pub(crate) fn decode_line(buf: &[u8]) -> Option<(Vec<u8>, usize)> {
    buf.iter()
        .position(|&b| b == b'\n')
        .map(|i| (buf[..i].to_vec(), i + 1))
}

/// Appends `frame` and its `\n` to `out`.
pub(crate) fn encode_line(frame: &[u8], out: &mut Vec<u8>) {
    out.extend_from_slice(frame);
    out.push(b'\n');
}
