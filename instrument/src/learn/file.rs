//! The policy file: one trained [`PolicyNet`] plus free-form JSON metadata, versioned and
//! checksummed, so a policy trained on one machine is evaluated or flashed elsewhere only if
//! it is intact and was trained for the same inputs (rotation bins `K`, side length `S`).
//!
//! Byte layout, all integers and floats little-endian:
//!
//! | offset | size | field |
//! |-------:|-----:|-------|
//! | 0 | 8 | magic `b"ASPOLICY"` |
//! | 8 | 2 | format version, u16 = 1 |
//! | 10 | 2 | architecture id, u16 = 2 (`conv8-4-fc32`, see [`super::net`]; 1 was `conv8-16-fc64`, no longer read) |
//! | 12 | 1 | rotation bins `K`, u8, `1..=10` |
//! | 13 | 1 | reserved, 0 |
//! | 14 | 2 | side-feature length `S`, u16 |
//! | 16 | 4 | `param_count`, u32, must equal `NetShape { K, S }.param_count()` |
//! | 20 | 4 | `meta_len`, u32, at most 64 KiB |
//! | 24 | `meta_len` | UTF-8 JSON metadata (training command, seed, updates, wall time, …) |
//! | 24 + `meta_len` | 4 · `param_count` | f32 parameters in [`super::net`] order |
//! | end − 4 | 4 | CRC-32 (IEEE) of every preceding byte |
//!
//! The reader never panics on any input: every field is checked before it is used, lengths
//! before anything is allocated, and a bad file yields a [`PolicyFileError`] that says what is
//! wrong (wrapped with the path by [`load`]).

use super::net::{NetShape, PolicyNet, ARCH_ID, ARCH_NAME, MAX_ROT_BINS};
use activesense_core::protocol::crc32;
use std::fmt;
use std::path::{Path, PathBuf};

/// First 8 bytes of every policy file.
pub const MAGIC: [u8; 8] = *b"ASPOLICY";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u16 = 1;
/// Bytes before the metadata.
pub const HEADER_LEN: usize = 24;
/// Largest accepted metadata block.
pub const MAX_META_LEN: usize = 64 * 1024;
const CRC_LEN: usize = 4;

/// Why bytes are not a usable policy.
#[derive(Debug)]
pub enum PolicyFileError {
    Io(std::io::Error),
    /// Fewer bytes than the header (or, past the header, its lengths) require.
    Truncated {
        needed: u64,
        found: usize,
    },
    /// More bytes than the header's lengths account for.
    TrailingBytes {
        expected: u64,
        found: usize,
    },
    BadMagic,
    UnsupportedVersion(u16),
    UnknownArchitecture(u16),
    ReservedNotZero(u8),
    /// `K` outside `1..=MAX_ROT_BINS`.
    InvalidRotBins(u8),
    /// The stored parameter count is not the one the stored shape implies.
    ShapeMismatch {
        rot_bins: u8,
        side: u16,
        stored: u32,
        expected: usize,
    },
    WrongRotBins {
        expected: u8,
        found: u8,
    },
    WrongSideLength {
        expected: usize,
        found: usize,
    },
    ChecksumMismatch {
        stored: u32,
        computed: u32,
    },
    NonFiniteWeight {
        index: usize,
    },
    MetadataTooLong {
        len: usize,
    },
    BadMetadata(String),
}

impl fmt::Display for PolicyFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use PolicyFileError::*;
        match self {
            Io(e) => write!(f, "{e}"),
            Truncated { needed, found } => write!(
                f,
                "truncated: {found} bytes, but the header needs {needed}"
            ),
            TrailingBytes { expected, found } => write!(
                f,
                "{found} bytes, but the header accounts for {expected}: unexpected trailing data"
            ),
            BadMagic => write!(f, "not a policy file (it does not start with \"ASPOLICY\")"),
            UnsupportedVersion(v) => write!(
                f,
                "format version {v} is not supported (this build reads version {FORMAT_VERSION})"
            ),
            UnknownArchitecture(a) => write!(
                f,
                "unknown network architecture id {a} (this build knows {ARCH_ID}, {ARCH_NAME})"
            ),
            ReservedNotZero(r) => write!(f, "reserved header byte is {r}, not 0"),
            InvalidRotBins(k) => write!(f, "rot_bins K={k} is outside 1..={MAX_ROT_BINS}"),
            ShapeMismatch {
                rot_bins,
                side,
                stored,
                expected,
            } => write!(
                f,
                "stores {stored} parameters, but K={rot_bins}, S={side} needs {expected}"
            ),
            WrongRotBins { expected, found } => write!(
                f,
                "trained for rot_bins K={found}, but K={expected} is in use"
            ),
            WrongSideLength { expected, found } => write!(
                f,
                "trained for {found} side features, but {expected} are in use"
            ),
            ChecksumMismatch { stored, computed } => write!(
                f,
                "checksum mismatch (stored 0x{stored:08x}, computed 0x{computed:08x}): the file is corrupt"
            ),
            NonFiniteWeight { index } => {
                write!(f, "parameter {index} is not finite (diverged training?)")
            }
            MetadataTooLong { len } => {
                write!(f, "metadata is {len} bytes, more than {MAX_META_LEN}")
            }
            BadMetadata(why) => write!(f, "metadata is not valid UTF-8 JSON: {why}"),
        }
    }
}

// No `source()`: the messages already include their cause, and a chained report
// (`anyhow`'s `{:#}`) would print it again.
impl std::error::Error for PolicyFileError {}

/// A [`PolicyFileError`] with the file it came from:
/// `policy file 'x.policy': checksum mismatch (…): the file is corrupt`.
#[derive(Debug)]
pub struct LoadError {
    pub path: PathBuf,
    pub error: PolicyFileError,
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "policy file '{}': {}", self.path.display(), self.error)
    }
}

impl std::error::Error for LoadError {}

/// Serialises `net` and `meta`. Refuses non-finite parameters (a diverged network should
/// fail where it is saved, not where it is flashed) and shapes the header cannot hold.
pub fn to_bytes(net: &PolicyNet, meta: &serde_json::Value) -> Result<Vec<u8>, PolicyFileError> {
    let shape = net.shape;
    let rot_bins = u8::try_from(shape.rot_bins)
        .ok()
        .filter(|k| (1..=MAX_ROT_BINS).contains(&usize::from(*k)))
        .ok_or(PolicyFileError::InvalidRotBins(
            shape.rot_bins.min(255) as u8
        ))?;
    let side = u16::try_from(shape.side).map_err(|_| PolicyFileError::WrongSideLength {
        expected: usize::from(u16::MAX),
        found: shape.side,
    })?;
    if net.params.len() != shape.param_count() {
        return Err(PolicyFileError::ShapeMismatch {
            rot_bins,
            side,
            stored: net.params.len() as u32,
            expected: shape.param_count(),
        });
    }
    if let Some(index) = net.params.iter().position(|p| !p.is_finite()) {
        return Err(PolicyFileError::NonFiniteWeight { index });
    }
    let meta = serde_json::to_vec(meta).map_err(|e| PolicyFileError::BadMetadata(e.to_string()))?;
    if meta.len() > MAX_META_LEN {
        return Err(PolicyFileError::MetadataTooLong { len: meta.len() });
    }
    let mut out = Vec::with_capacity(HEADER_LEN + meta.len() + 4 * net.params.len() + CRC_LEN);
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&ARCH_ID.to_le_bytes());
    out.push(rot_bins);
    out.push(0);
    out.extend_from_slice(&side.to_le_bytes());
    out.extend_from_slice(&(net.params.len() as u32).to_le_bytes());
    out.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    out.extend_from_slice(&meta);
    for p in &net.params {
        out.extend_from_slice(&p.to_le_bytes());
    }
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(out)
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Parses and validates a policy file image. Checks run from the most to the least
/// specific diagnosis: magic, version, architecture, shape, lengths, checksum, metadata,
/// finiteness.
pub fn from_bytes(bytes: &[u8]) -> Result<(PolicyNet, serde_json::Value), PolicyFileError> {
    use PolicyFileError::*;
    let minimum = (HEADER_LEN + CRC_LEN) as u64;
    if bytes.len() < MAGIC.len() {
        return Err(Truncated {
            needed: minimum,
            found: bytes.len(),
        });
    }
    if bytes[..MAGIC.len()] != MAGIC {
        return Err(BadMagic);
    }
    if (bytes.len() as u64) < minimum {
        return Err(Truncated {
            needed: minimum,
            found: bytes.len(),
        });
    }
    let version = u16_at(bytes, 8);
    if version != FORMAT_VERSION {
        return Err(UnsupportedVersion(version));
    }
    let arch = u16_at(bytes, 10);
    if arch != ARCH_ID {
        return Err(UnknownArchitecture(arch));
    }
    let rot_bins = bytes[12];
    if bytes[13] != 0 {
        return Err(ReservedNotZero(bytes[13]));
    }
    if !(1..=MAX_ROT_BINS).contains(&usize::from(rot_bins)) {
        return Err(InvalidRotBins(rot_bins));
    }
    let side = u16_at(bytes, 14);
    let stored = u32_at(bytes, 16);
    let meta_len = u32_at(bytes, 20) as usize;
    let shape = NetShape {
        rot_bins: usize::from(rot_bins),
        side: usize::from(side),
    };
    let expected = shape.param_count();
    if stored as usize != expected {
        return Err(ShapeMismatch {
            rot_bins,
            side,
            stored,
            expected,
        });
    }
    if meta_len > MAX_META_LEN {
        return Err(MetadataTooLong { len: meta_len });
    }
    let total = (HEADER_LEN + meta_len + 4 * expected + CRC_LEN) as u64;
    match (bytes.len() as u64).cmp(&total) {
        std::cmp::Ordering::Less => {
            return Err(Truncated {
                needed: total,
                found: bytes.len(),
            })
        }
        std::cmp::Ordering::Greater => {
            return Err(TrailingBytes {
                expected: total,
                found: bytes.len(),
            })
        }
        std::cmp::Ordering::Equal => {}
    }
    let body = &bytes[..bytes.len() - CRC_LEN];
    let stored_crc = u32_at(bytes, body.len());
    let computed = crc32(body);
    if stored_crc != computed {
        return Err(ChecksumMismatch {
            stored: stored_crc,
            computed,
        });
    }
    let meta_bytes = &body[HEADER_LEN..HEADER_LEN + meta_len];
    let meta: serde_json::Value =
        serde_json::from_slice(meta_bytes).map_err(|e| BadMetadata(e.to_string()))?;
    let params: Vec<f32> = body[HEADER_LEN + meta_len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if let Some(index) = params.iter().position(|p| !p.is_finite()) {
        return Err(NonFiniteWeight { index });
    }
    let net = PolicyNet::from_params(shape, params).expect("count checked above");
    Ok((net, meta))
}

/// Writes the policy to `path` (via a temporary file and a rename, so a crash never leaves
/// a half-written policy under the final name).
pub fn save(
    path: impl AsRef<Path>,
    net: &PolicyNet,
    meta: &serde_json::Value,
) -> Result<(), LoadError> {
    let path = path.as_ref();
    let wrap = |error| LoadError {
        path: path.to_path_buf(),
        error,
    };
    let bytes = to_bytes(net, meta).map_err(wrap)?;
    let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    std::fs::write(&tmp, &bytes)
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| wrap(PolicyFileError::Io(e)))
}

/// Reads and validates the policy at `path`.
pub fn load(path: impl AsRef<Path>) -> Result<(PolicyNet, serde_json::Value), LoadError> {
    let path = path.as_ref();
    let wrap = |error| LoadError {
        path: path.to_path_buf(),
        error,
    };
    let bytes = std::fs::read(path).map_err(|e| wrap(PolicyFileError::Io(e)))?;
    from_bytes(&bytes).map_err(wrap)
}

/// [`load`], and also rejects a policy trained for another `K` or another side length.
pub fn load_expecting(
    path: impl AsRef<Path>,
    rot_bins: u8,
    side: usize,
) -> Result<(PolicyNet, serde_json::Value), LoadError> {
    let path = path.as_ref();
    let (net, meta) = load(path)?;
    check_shape(&net.shape, rot_bins, side).map_err(|error| LoadError {
        path: path.to_path_buf(),
        error,
    })?;
    Ok((net, meta))
}

/// `Ok` if `shape` is for `rot_bins` bins and `side` side features.
pub fn check_shape(shape: &NetShape, rot_bins: u8, side: usize) -> Result<(), PolicyFileError> {
    if shape.rot_bins != usize::from(rot_bins) {
        return Err(PolicyFileError::WrongRotBins {
            expected: rot_bins,
            found: shape.rot_bins as u8,
        });
    }
    if shape.side != side {
        return Err(PolicyFileError::WrongSideLength {
            expected: side,
            found: shape.side,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;
    use serde_json::json;

    fn small() -> (PolicyNet, serde_json::Value) {
        let net = PolicyNet::new(
            NetShape {
                rot_bins: 1,
                side: 3,
            },
            9,
        );
        let meta = json!({"command": "activesense train --seed 9", "seed": 9, "updates": 12, "wall_s": 1.5});
        (net, meta)
    }

    fn tmp_path(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("activesense-{}-{name}", std::process::id()))
    }

    #[test]
    fn round_trip_is_bit_identical() {
        let net = PolicyNet::new(
            NetShape {
                rot_bins: 10,
                side: 108,
            },
            3,
        );
        let meta = json!({"seed": 3, "note": "ünïcode ok"});
        let path = tmp_path("roundtrip.policy");
        save(&path, &net, &meta).unwrap();
        let (back, back_meta) = load(&path).unwrap();
        let (again, _) = load_expecting(&path, 10, 108).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(back.shape, net.shape);
        let bits = |n: &PolicyNet| n.params.iter().map(|p| p.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&net));
        assert_eq!(bits(&again), bits(&net));
        assert_eq!(back_meta, meta);
        let bytes = to_bytes(&net, &meta).unwrap();
        assert_eq!(&bytes[..8], b"ASPOLICY");
        assert_eq!(u32_at(&bytes, 16) as usize, net.shape.param_count());
    }

    #[test]
    fn every_truncation_is_rejected() {
        let (net, meta) = small();
        let bytes = to_bytes(&net, &meta).unwrap();
        for n in 0..bytes.len() {
            match from_bytes(&bytes[..n]) {
                Err(PolicyFileError::Truncated { .. }) => {}
                other => panic!("length {n}: {:?}", other.map(|_| ())),
            }
        }
        let mut long = bytes.clone();
        long.push(0);
        assert!(matches!(
            from_bytes(&long),
            Err(PolicyFileError::TrailingBytes { .. })
        ));
        assert!(from_bytes(&bytes).is_ok());
    }

    /// A CRC-32 detects every single-bit error, so every flip of the header (and of the
    /// metadata, and a sample of the parameters) must be rejected, with some error.
    #[test]
    fn every_single_bit_flip_is_rejected() {
        let (net, meta) = small();
        let bytes = to_bytes(&net, &meta).unwrap();
        let meta_end = HEADER_LEN + u32_at(&bytes, 20) as usize;
        let mut rng = Pcg64::seed_from_u64(1);
        let positions = (0..meta_end)
            .chain((0..200).map(|_| rng.gen_range(meta_end..bytes.len())))
            .chain(bytes.len() - 4..bytes.len());
        for pos in positions {
            for bit in 0..8 {
                let mut bad = bytes.clone();
                bad[pos] ^= 1 << bit;
                assert!(
                    from_bytes(&bad).is_err(),
                    "flip at byte {pos} bit {bit} accepted"
                );
            }
        }
        let mut body_flip = bytes.clone();
        body_flip[meta_end + 5] ^= 0x10;
        assert!(matches!(
            from_bytes(&body_flip),
            Err(PolicyFileError::ChecksumMismatch { .. })
        ));
    }

    #[test]
    fn header_errors_are_specific() {
        let (net, meta) = small();
        let bytes = to_bytes(&net, &meta).unwrap();
        let with = |at: usize, v: &[u8]| {
            let mut b = bytes.clone();
            b[at..at + v.len()].copy_from_slice(v);
            from_bytes(&b).map(|_| ()).unwrap_err()
        };
        assert!(matches!(with(0, b"NOTAPOLI"), PolicyFileError::BadMagic));
        assert!(matches!(
            with(8, &2u16.to_le_bytes()),
            PolicyFileError::UnsupportedVersion(2)
        ));
        assert!(matches!(
            with(10, &7u16.to_le_bytes()),
            PolicyFileError::UnknownArchitecture(7)
        ));
        assert!(matches!(
            with(12, &[11]),
            PolicyFileError::InvalidRotBins(11)
        ));
        assert!(matches!(
            with(12, &[2]),
            PolicyFileError::ShapeMismatch { .. }
        ));
        assert!(matches!(
            with(20, &u32::MAX.to_le_bytes()),
            PolicyFileError::MetadataTooLong { .. }
        ));
        // Non-finite weight with a valid checksum: only the finiteness check can catch it.
        let mut nan = bytes.clone();
        let at = HEADER_LEN + u32_at(&bytes, 20) as usize + 4 * 7;
        nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let n = nan.len() - 4;
        let crc = crc32(&nan[..n]).to_le_bytes();
        nan[n..].copy_from_slice(&crc);
        assert!(matches!(
            from_bytes(&nan),
            Err(PolicyFileError::NonFiniteWeight { index: 7 })
        ));
        // And the writer refuses to produce such a file.
        let mut bad_net = net.clone();
        bad_net.params[3] = f32::INFINITY;
        assert!(matches!(
            to_bytes(&bad_net, &meta),
            Err(PolicyFileError::NonFiniteWeight { index: 3 })
        ));
    }

    #[test]
    fn messages_name_the_file_and_the_problem() {
        let (net, meta) = small();
        let path = tmp_path("corrupt.policy");
        let mut bytes = to_bytes(&net, &meta).unwrap();
        let last = bytes.len() - 10;
        bytes[last] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        let msg = load(&path).unwrap_err().to_string();
        assert!(
            msg.starts_with(&format!(
                "policy file '{}': checksum mismatch (stored 0x",
                path.display()
            )),
            "{msg}"
        );
        assert!(msg.ends_with("): the file is corrupt"), "{msg}");

        save(&path, &net, &meta).unwrap();
        let err = load_expecting(&path, 10, 3).unwrap_err();
        assert!(matches!(
            err.error,
            PolicyFileError::WrongRotBins {
                expected: 10,
                found: 1
            }
        ));
        assert!(
            err.to_string()
                .contains("trained for rot_bins K=1, but K=10"),
            "{err}"
        );
        let err = load_expecting(&path, 1, 108).unwrap_err();
        assert!(matches!(
            err.error,
            PolicyFileError::WrongSideLength {
                expected: 108,
                found: 3
            }
        ));
        std::fs::remove_file(&path).unwrap();
        let err = load(&path).unwrap_err();
        assert!(matches!(err.error, PolicyFileError::Io(_)));
    }

    /// Random garbage, with and without a valid-looking header, never panics.
    #[test]
    fn garbage_never_panics() {
        let (net, meta) = small();
        let valid = to_bytes(&net, &meta).unwrap();
        let mut rng = Pcg64::seed_from_u64(2);
        for i in 0..2000 {
            let len = rng.gen_range(0..200);
            let mut g: Vec<u8> = (0..len).map(|_| rng.gen()).collect();
            if i % 2 == 0 {
                let keep = rng.gen_range(0..=HEADER_LEN.min(g.len()));
                g[..keep].copy_from_slice(&valid[..keep]);
            }
            assert!(from_bytes(&g).is_err());
        }
        // Valid header, garbage after it, at the full length.
        let mut g = valid.clone();
        for b in &mut g[HEADER_LEN..] {
            *b = rng.gen();
        }
        assert!(from_bytes(&g).is_err());
    }
}
