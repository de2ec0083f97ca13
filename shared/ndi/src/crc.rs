//! CRC-16/ARC (polynomial 0x8005 reflected = 0xA001, initial value 0, no final XOR): the checksum
//! the NDI Combined API puts on every command and reply.

/// Lookup table for one byte at a time, built at compile time.
const TABLE: [u16; 256] = build_table();

const fn build_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut crc = byte as u16;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
            bit += 1;
        }
        table[byte] = crc;
        byte += 1;
    }
    table
}

/// CRC-16/ARC of `data`.
///
/// ASCII replies carry it as 4 upper-case hex digits before the CR; BX replies carry it little
/// endian, once over the 4-byte header and once over the body.
pub fn crc16(data: &[u8]) -> u16 {
    data.iter().fold(0u16, |crc, &byte| {
        (crc >> 8) ^ TABLE[usize::from((crc ^ u16::from(byte)) & 0xFF)]
    })
}

/// The CRC of `data` as the 4 upper-case hex digits ASCII replies and commands end with.
pub fn crc16_hex(data: &[u8]) -> String {
    format!("{:04X}", crc16(data))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-by-bit reference implementation, to check the table.
    fn crc16_bitwise(data: &[u8]) -> u16 {
        let mut crc = 0u16;
        for &byte in data {
            crc ^= u16::from(byte);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xA001
                } else {
                    crc >> 1
                };
            }
        }
        crc
    }

    #[test]
    fn standard_check_value() {
        // The catalogued check value of CRC-16/ARC over "123456789".
        assert_eq!(crc16(b"123456789"), 0xBB3D);
    }

    #[test]
    fn values_from_the_polaris_log() {
        // Commands and replies exactly as the real device exchanged them.
        assert_eq!(crc16_hex(b"INIT:"), "E3A5");
        assert_eq!(crc16_hex(b"OKAY"), "A896");
        assert_eq!(crc16_hex(b"RESET"), "BE6F");
        assert_eq!(crc16_hex(b"BX:0001"), "C26D");
        assert_eq!(crc16_hex(b"TX:1000"), "3FDA");
        assert_eq!(crc16_hex(b"PENA:01D"), "6D3B");
        assert_eq!(crc16_hex(b"020100102001"), "C741");
        // BX header of log exchange 41: C4 A5 17 00 carries 22 E3 (little endian).
        assert_eq!(crc16(&[0xC4, 0xA5, 0x17, 0x00]), 0xE322);
    }

    #[test]
    fn table_matches_bitwise_definition() {
        let data: Vec<u8> = (0..=255u8).chain((0..=255u8).rev()).collect();
        for len in [0, 1, 2, 7, 100, data.len()] {
            assert_eq!(
                crc16(&data[..len]),
                crc16_bitwise(&data[..len]),
                "len {len}"
            );
        }
    }
}
