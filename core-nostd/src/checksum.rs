//! CRC-32 (IEEE / ISO-HDLC: reflected polynomial `0xEDB88320`, init and xorout
//! `0xFFFFFFFF`; check value of `"123456789"` is `0xCBF43926`), the one checksum of the
//! core. A leaf (it imports nothing) because two layers need it: the int8 policy blob
//! carries its own CRC ([`crate::policy::int8`]) and the protocol protects every frame and
//! fingerprints every episode trace with it ([`crate::protocol`]); neither may import the
//! other.

use crc::{Crc, Table, CRC_32_ISO_HDLC};

/// The algorithm, from the `crc` crate (byte-wise table: 1 KiB of flash; `docs/protocol.md`
/// has the measured choice).
const CRC: Crc<u32, Table<1>> = Crc::<u32, Table<1>>::new(&CRC_32_ISO_HDLC);

/// Incremental CRC-32 (IEEE). Holds the CRC of everything fed so far, so it is `Copy` and
/// `const`-constructible (the episode trace hash lives in a `static` on the device).
#[derive(Clone, Copy, Debug)]
pub struct Crc32(u32);

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc32 {
    /// A fresh CRC (of nothing: 0).
    pub const fn new() -> Self {
        Crc32(0)
    }
    /// Feeds bytes: resumes the `crc` crate's digest from the CRC so far. For ISO-HDLC
    /// (reflected, xorout `0xFFFFFFFF`) the register after `c` is `!c`, which
    /// `digest_with_initial` takes bit-reversed.
    pub fn update(&mut self, data: &[u8]) {
        let mut d = CRC.digest_with_initial((!self.0).reverse_bits());
        d.update(data);
        self.0 = d.finalize();
    }
    /// The CRC of everything fed so far.
    pub fn finish(&self) -> u32 {
        self.0
    }
}

/// CRC-32 (IEEE) of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    CRC.checksum(data)
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

    /// The bitwise definition (the nibble-table code this module had before the `crc`
    /// crate): every length and split gives the same CRC.
    #[test]
    fn matches_the_bitwise_definition() {
        fn reference(data: &[u8]) -> u32 {
            let mut c = 0xFFFF_FFFFu32;
            for &b in data {
                c ^= b as u32;
                for _ in 0..8 {
                    c = if c & 1 != 0 {
                        (c >> 1) ^ 0xEDB8_8320
                    } else {
                        c >> 1
                    };
                }
            }
            !c
        }
        let data: [u8; 300] =
            core::array::from_fn(|i| (i as u32).wrapping_mul(2_654_435_761) as u8);
        for n in [0, 1, 3, 4, 9, 64, 255, 300] {
            assert_eq!(crc32(&data[..n]), reference(&data[..n]), "{n}");
            for split in [0, n / 3, n / 2, n] {
                let mut c = Crc32::new();
                c.update(&data[..split]);
                c.update(&data[split..n]);
                assert_eq!(c.finish(), reference(&data[..n]), "{n} {split}");
            }
        }
    }
}
