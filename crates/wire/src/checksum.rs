//! Checksums used on the cell's lines.

use crc::{CRC_16_MODBUS, Crc, Table};

/// CRC-16/MODBUS (init 0xFFFF, reflected polynomial 0xA001), as JBUS and Modbus RTU use it.
/// The frame carries the result low byte first.
///
/// A `static` with the crate's 16-byte-per-step tables (8 KiB): a `const` was copied at
/// every use, and the byte-wise table made the CRC of a 125-register answer most of a
/// Modbus client's time per request (the `versus` bench).
pub static CRC16_MODBUS: Crc<u16, Table<16>> = Crc::<u16, Table<16>>::new(&CRC_16_MODBUS);

/// CRC-16/MODBUS of `bytes`.
pub fn crc16_modbus(bytes: &[u8]) -> u16 {
    CRC16_MODBUS.checksum(bytes)
}

/// The XOR of all bytes: the JBC block check character (BCC).
pub fn xor_bcc(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0, |acc, b| acc ^ b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc16_modbus_matches_the_cross_manual_example() {
        // chloride-cross-jbus.txt: frame `02 07` gives 0x1241, sent as `41 12`.
        assert_eq!(crc16_modbus(&[0x02, 0x07]), 0x1241);
        assert_eq!(crc16_modbus(&[0x02, 0x07]).to_le_bytes(), [0x41, 0x12]);
    }

    #[test]
    fn crc16_modbus_matches_the_standard_check_value() {
        assert_eq!(crc16_modbus(b"123456789"), 0x4B37);
    }

    #[test]
    fn xor_bcc_of_nothing_is_zero_and_of_a_byte_is_that_byte() {
        assert_eq!(xor_bcc(&[]), 0);
        assert_eq!(xor_bcc(&[0x5A]), 0x5A);
        assert_eq!(xor_bcc(&[0x02, 0x03]), 0x01);
    }
}
