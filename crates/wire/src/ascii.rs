//! Fixed-width ASCII numbers, as the serial protocols put them on the wire.

/// A number that does not fit its fixed-width field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{value} does not fit in {width} ASCII characters")]
pub struct TooWide {
    /// The value that was to be written.
    pub value: i64,
    /// The width of the field.
    pub width: usize,
}

/// Parses an unsigned decimal field: one or more ASCII digits and nothing else.
pub fn parse_unsigned(field: &[u8]) -> Option<u32> {
    if field.is_empty() || field.len() > 9 || !field.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(field.iter().fold(0, |n, d| n * 10 + u32::from(d - b'0')))
}

/// Parses a signed decimal field: an optional leading `-`, then ASCII digits.
pub fn parse_signed(field: &[u8]) -> Option<i32> {
    match field.split_first() {
        Some((b'-', digits)) => parse_unsigned(digits).map(|n| -(n as i32)),
        _ => parse_unsigned(field).map(|n| n as i32),
    }
}

/// Appends `value` zero-padded to exactly `width` digits.
pub fn write_unsigned(value: u32, width: usize, out: &mut Vec<u8>) -> Result<(), TooWide> {
    let text = value.to_string();
    if text.len() > width {
        return Err(TooWide {
            value: value.into(),
            width,
        });
    }
    out.extend(std::iter::repeat_n(b'0', width - text.len()));
    out.extend_from_slice(text.as_bytes());
    Ok(())
}

/// Appends `value` in exactly `width` characters: zero-padded digits, with a negative
/// number's `-` in the first position (`-50` in 5 characters is `-0050`).
pub fn write_signed(value: i32, width: usize, out: &mut Vec<u8>) -> Result<(), TooWide> {
    if value >= 0 {
        return write_unsigned(value.unsigned_abs(), width, out).map_err(|_| TooWide {
            value: value.into(),
            width,
        });
    }
    if width < 2 {
        return Err(TooWide {
            value: value.into(),
            width,
        });
    }
    out.push(b'-');
    write_unsigned(value.unsigned_abs(), width - 1, out).map_err(|_| {
        out.pop();
        TooWide {
            value: value.into(),
            width,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn signed(value: i32, width: usize) -> Result<String, TooWide> {
        let mut out = Vec::new();
        write_signed(value, width, &mut out).map(|()| String::from_utf8(out).expect("ASCII"))
    }

    #[test]
    fn numbers_are_zero_padded_with_the_sign_in_front() {
        // jbc-jtse-control-unit-programmers-guide.txt: "375" is sent as "00375", -50 as "-0050".
        assert_eq!(signed(375, 5), Ok("00375".into()));
        assert_eq!(signed(-50, 5), Ok("-0050".into()));
        assert_eq!(signed(99999, 5), Ok("99999".into()));
        assert_eq!(signed(-9999, 5), Ok("-9999".into()));
    }

    #[test]
    fn numbers_that_do_not_fit_are_refused_and_write_nothing() {
        let mut out = Vec::new();
        assert_eq!(
            write_signed(100_000, 5, &mut out),
            Err(TooWide {
                value: 100_000,
                width: 5
            })
        );
        assert_eq!(
            write_signed(-10_000, 5, &mut out),
            Err(TooWide {
                value: -10_000,
                width: 5
            })
        );
        assert!(out.is_empty());
    }

    #[test]
    fn parsing_refuses_anything_but_digits() {
        assert_eq!(parse_unsigned(b"00375"), Some(375));
        assert_eq!(parse_signed(b"-0050"), Some(-50));
        assert_eq!(parse_unsigned(b""), None);
        assert_eq!(parse_unsigned(b" 375"), None);
        assert_eq!(parse_signed(b"-"), None);
        assert_eq!(parse_signed(b"--005"), None);
        assert_eq!(parse_unsigned(b"1234567890"), None);
    }

    proptest! {
        #[test]
        fn signed_numbers_round_trip(value in -9999i32..=99999) {
            let mut out = Vec::new();
            write_signed(value, 5, &mut out).expect("in range");
            prop_assert_eq!(out.len(), 5);
            prop_assert_eq!(parse_signed(&out), Some(value));
        }
    }
}
