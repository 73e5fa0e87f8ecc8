//! Line timing of Modbus RTU: character time, inter-frame silence, inter-character gap.
//!
//! RTU delimits frames by silence: a master waits at least 3.5 character times between
//! frames, and a character gap above 1.5 character times ends a frame. Above 19200 baud
//! the standard fixes these at 1.75 ms and 0.75 ms, as a UART interrupt per character would
//! otherwise make them unworkably short. A character is a start bit, the data bits, the
//! parity bit if any and the stop bits: 10 bits for 8N1 (the CROSS's format), 11 for 8E1,
//! 8O1 and 8N2.

use std::time::Duration;

use super::value::InvalidValue;

/// Bits per character at 8 data bits, no parity, 1 stop bit (the CROSS's format).
pub const BITS_PER_CHAR_8N1: u32 = 10;
/// Bits per character at 8 data bits, even parity, 1 stop bit (Modbus's default).
pub const BITS_PER_CHAR_8E1: u32 = 11;
/// Bits per character at 8 data bits, no parity, 2 stop bits.
pub const BITS_PER_CHAR_8N2: u32 = 11;

/// Above this speed the silences are fixed rather than counted in characters.
pub const FIXED_TIMING_ABOVE_BAUD: u32 = 19_200;
/// The inter-frame silence above 19200 baud.
pub const FIXED_INTER_FRAME_SILENCE: Duration = Duration::from_micros(1_750);
/// The longest gap inside a frame above 19200 baud.
pub const FIXED_INTER_CHAR_TIMEOUT: Duration = Duration::from_micros(750);

/// A line's speed and character format, for timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct LineTiming {
    baud: u32,
    bits_per_char: u32,
}

const NANOS_PER_SECOND: u64 = 1_000_000_000;

impl LineTiming {
    /// A line at `baud` (1 and up) with `bits_per_char` bits per character (7–12: a start
    /// bit, 5–8 data bits, an optional parity bit, 1 or 2 stop bits).
    pub fn new(baud: u32, bits_per_char: u32) -> Result<Self, InvalidValue> {
        if baud == 0 {
            return Err(InvalidValue::out_of_range("baud rate", baud, 1, u32::MAX));
        }
        if !(7..=12).contains(&bits_per_char) {
            return Err(InvalidValue::out_of_range(
                "bits per character",
                bits_per_char,
                7,
                12,
            ));
        }
        Ok(Self {
            baud,
            bits_per_char,
        })
    }

    /// A line at `baud`, 8N1.
    pub fn for_8n1(baud: u32) -> Result<Self, InvalidValue> {
        Self::new(baud, BITS_PER_CHAR_8N1)
    }

    /// A line at `baud`, 8E1.
    pub fn for_8e1(baud: u32) -> Result<Self, InvalidValue> {
        Self::new(baud, BITS_PER_CHAR_8E1)
    }

    /// The speed in baud.
    pub const fn baud(&self) -> u32 {
        self.baud
    }

    /// Bits per character.
    pub const fn bits_per_char(&self) -> u32 {
        self.bits_per_char
    }

    /// The time one character takes on the line.
    pub fn char_time(&self) -> Duration {
        self.chars(1, 1)
    }

    /// The time `bytes` characters take on the line, back to back.
    pub fn transmit_time(&self, bytes: usize) -> Duration {
        self.chars(u64::try_from(bytes).unwrap_or(u64::MAX), 1)
    }

    /// The silence that separates frames: 3.5 character times, or 1.75 ms above 19200 baud.
    pub fn inter_frame_silence(&self) -> Duration {
        if self.baud > FIXED_TIMING_ABOVE_BAUD {
            FIXED_INTER_FRAME_SILENCE
        } else {
            self.chars(7, 2)
        }
    }

    /// The longest gap between characters of one frame: 1.5 character times, or 0.75 ms
    /// above 19200 baud.
    pub fn inter_char_timeout(&self) -> Duration {
        if self.baud > FIXED_TIMING_ABOVE_BAUD {
            FIXED_INTER_CHAR_TIMEOUT
        } else {
            self.chars(3, 2)
        }
    }

    /// `numerator / denominator` character times, rounded up to the nanosecond.
    fn chars(&self, numerator: u64, denominator: u64) -> Duration {
        let bits =
            u128::from(numerator) * u128::from(self.bits_per_char) * u128::from(NANOS_PER_SECOND);
        let nanos = bits.div_ceil(u128::from(denominator) * u128::from(self.baud));
        Duration::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
    }
}

/// The time one character takes at `baud` with `bits_per_char` bits per character
/// (see [`LineTiming::new`] for the ranges).
pub fn char_time(baud: u32, bits_per_char: u32) -> Result<Duration, InvalidValue> {
    Ok(LineTiming::new(baud, bits_per_char)?.char_time())
}

/// The silence before each frame at `baud` with `bits_per_char` bits per character:
/// 3.5 character times, 1.75 ms above 19200 baud.
pub fn inter_frame_silence(baud: u32, bits_per_char: u32) -> Result<Duration, InvalidValue> {
    Ok(LineTiming::new(baud, bits_per_char)?.inter_frame_silence())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_character_at_9600_8n1_takes_1042_microseconds() {
        let line = LineTiming::for_8n1(9600).expect("valid");
        assert_eq!(line.char_time(), Duration::from_nanos(1_041_667));
        assert_eq!(
            char_time(9600, BITS_PER_CHAR_8N1),
            Ok(Duration::from_nanos(1_041_667))
        );
    }

    #[test]
    fn inter_frame_silence_at_9600_8n1_is_3_5_characters() {
        let line = LineTiming::for_8n1(9600).expect("valid");
        assert_eq!(line.inter_frame_silence(), Duration::from_nanos(3_645_834));
        assert_eq!(line.inter_char_timeout(), Duration::from_nanos(1_562_500));
    }

    #[test]
    fn eight_e1_characters_take_eleven_bits() {
        let line = LineTiming::for_8e1(19200).expect("valid");
        assert_eq!(line.char_time(), Duration::from_nanos(572_917));
        assert_eq!(line.inter_frame_silence(), Duration::from_nanos(2_005_209));
        assert_eq!(
            inter_frame_silence(19200, BITS_PER_CHAR_8N2),
            Ok(Duration::from_nanos(2_005_209))
        );
    }

    #[test]
    fn above_19200_baud_the_silences_are_fixed() {
        let line = LineTiming::for_8e1(38400).expect("valid");
        assert_eq!(line.inter_frame_silence(), Duration::from_micros(1_750));
        assert_eq!(line.inter_char_timeout(), Duration::from_micros(750));
        assert_eq!(
            LineTiming::for_8n1(115_200)
                .expect("valid")
                .inter_frame_silence(),
            FIXED_INTER_FRAME_SILENCE
        );
    }

    #[test]
    fn an_eight_byte_request_at_1200_baud_takes_about_67_ms() {
        let line = LineTiming::for_8n1(1200).expect("valid");
        assert_eq!(line.transmit_time(8), Duration::from_nanos(66_666_667));
    }

    #[test]
    fn zero_baud_and_odd_character_sizes_are_refused() {
        assert_eq!(
            LineTiming::new(0, 10),
            Err(InvalidValue::OutOfRange {
                what: "baud rate",
                value: 0,
                min: 1,
                max: u32::MAX
            })
        );
        assert!(LineTiming::new(9600, 13).is_err());
        assert!(LineTiming::new(9600, 6).is_err());
    }
}
