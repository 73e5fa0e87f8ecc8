//! Scanning streams framed by a start byte and an end byte, optionally followed by a fixed
//! number of check bytes (`STX … ETX BCC` for JBC, `% … LF` for Thermosald).

/// The framing of a delimited protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Delimited {
    /// The byte that starts every frame.
    pub start: u8,
    /// The byte that ends the frame body.
    pub end: u8,
    /// Bytes that follow the end byte (a check character), taken whatever their value.
    pub trailer: usize,
    /// The longest frame, trailer included; longer runs are not frames.
    pub max_len: usize,
}

/// What lies at the front of a buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scan {
    /// A frame may start here but is not complete yet.
    NeedMore,
    /// `len` bytes before the next start byte (or all bytes) cannot begin a frame.
    Garbage {
        /// Bytes to drop.
        len: usize,
    },
    /// A frame starts here but breaks off: another start byte comes before its end, or no
    /// end byte comes within the longest frame. `len` bytes (up to the next start byte) are
    /// to be dropped.
    Unterminated {
        /// Bytes to drop.
        len: usize,
    },
    /// A complete frame of `len` bytes, start to trailer, is at the front.
    Frame {
        /// Length of the frame.
        len: usize,
    },
}

impl Delimited {
    /// Looks at the front of `buf`.
    pub fn scan(&self, buf: &[u8]) -> Scan {
        let Some(&first) = buf.first() else {
            return Scan::NeedMore;
        };
        if first != self.start {
            let len = self.next_start(buf, 0).unwrap_or(buf.len());
            return Scan::Garbage { len };
        }
        let body_end = buf[1..]
            .iter()
            .position(|&b| b == self.end || b == self.start);
        match body_end.map(|i| i + 1) {
            Some(i) if buf[i] == self.start => Scan::Unterminated { len: i },
            Some(i) => {
                let len = i + 1 + self.trailer;
                if len > self.max_len {
                    Scan::Unterminated {
                        len: (i + 1).min(buf.len()),
                    }
                } else if buf.len() < len {
                    Scan::NeedMore
                } else {
                    Scan::Frame { len }
                }
            }
            None if buf.len() >= self.max_len => Scan::Unterminated { len: buf.len() },
            None => Scan::NeedMore,
        }
    }

    fn next_start(&self, buf: &[u8], after: usize) -> Option<usize> {
        buf.iter()
            .skip(after + 1)
            .position(|&b| b == self.start)
            .map(|i| i + after + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STX_ETX_BCC: Delimited = Delimited {
        start: 0x02,
        end: 0x03,
        trailer: 1,
        max_len: 16,
    };
    const PERCENT_LF: Delimited = Delimited {
        start: b'%',
        end: b'\n',
        trailer: 0,
        max_len: 12,
    };

    #[test]
    fn scan_finds_a_frame_with_its_check_byte() {
        assert_eq!(
            STX_ETX_BCC.scan(b"\x02RST1\x03\x41rest"),
            Scan::Frame { len: 7 }
        );
    }

    #[test]
    fn scan_takes_the_check_byte_even_when_it_looks_like_a_start() {
        assert_eq!(STX_ETX_BCC.scan(b"\x02ab\x03\x02"), Scan::Frame { len: 5 });
    }

    #[test]
    fn scan_waits_for_the_check_byte() {
        assert_eq!(STX_ETX_BCC.scan(b"\x02RST1\x03"), Scan::NeedMore);
        assert_eq!(STX_ETX_BCC.scan(b"\x02RS"), Scan::NeedMore);
        assert_eq!(STX_ETX_BCC.scan(b""), Scan::NeedMore);
    }

    #[test]
    fn scan_marks_garbage_up_to_the_next_start() {
        assert_eq!(PERCENT_LF.scan(b"xx%0"), Scan::Garbage { len: 2 });
        assert_eq!(PERCENT_LF.scan(b"xyz"), Scan::Garbage { len: 3 });
    }

    #[test]
    fn scan_drops_a_half_frame_interrupted_by_a_new_start() {
        assert_eq!(
            PERCENT_LF.scan(b"%05%051Q99\n"),
            Scan::Unterminated { len: 3 }
        );
    }

    #[test]
    fn scan_gives_up_on_a_frame_longer_than_the_longest() {
        assert_eq!(
            PERCENT_LF.scan(b"%0123456789ab"),
            Scan::Unterminated { len: 13 }
        );
        assert_eq!(
            PERCENT_LF.scan(b"%0123456789abc\n"),
            Scan::Unterminated { len: 15 }
        );
    }
}
