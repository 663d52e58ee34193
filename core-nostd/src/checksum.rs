//! CRC-32 (IEEE / ISO-HDLC: reflected polynomial `0xEDB88320`, init and xorout
//! `0xFFFFFFFF`; check value of `"123456789"` is `0xCBF43926`), the one checksum of the
//! core. A leaf (it imports nothing) because two layers need it: the int8 policy blob
//! carries its own CRC ([`crate::policy::int8`]) and the protocol protects every frame and
//! fingerprints every episode trace with it ([`crate::protocol`]); neither may import the
//! other.

// Nibble-table implementation: 64 bytes of table, fine for ~1 KiB frames.
const fn crc_table() -> [u32; 16] {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 4 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
}

const CRC_TABLE: [u32; 16] = crc_table();

/// Incremental CRC-32 (IEEE).
#[derive(Clone, Copy, Debug)]
pub struct Crc32(u32);

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    /// A fresh CRC.
    pub const fn new() -> Self {
        Crc32(0xFFFF_FFFF)
    }
    /// Feeds bytes.
    pub fn update(&mut self, data: &[u8]) {
        let mut c = self.0;
        for &b in data {
            c ^= b as u32;
            c = (c >> 4) ^ CRC_TABLE[(c & 15) as usize];
            c = (c >> 4) ^ CRC_TABLE[(c & 15) as usize];
        }
        self.0 = c;
    }
    /// The CRC of everything fed so far.
    pub fn finish(&self) -> u32 {
        !self.0
    }
}

/// CRC-32 (IEEE) of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut c = Crc32::new();
    c.update(data);
    c.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        let mut c = Crc32::new();
        c.update(b"1234");
        c.update(b"56789");
        assert_eq!(c.finish(), 0xCBF4_3926);
    }
}
