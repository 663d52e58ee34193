//! Why an int8 policy blob was refused ([`BlobError`]). A leaf (it imports nothing) so that
//! the protocol can carry the parser's exact reason in `PolicyError::Invalid` without
//! importing the policy layer ([`crate::protocol`]'s module doc says why this is the one
//! exception to its imports).

/// Why a blob was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BlobError {
    /// Shorter than its header or than the length it declares.
    Truncated,
    /// Longer than the length it declares.
    TrailingBytes,
    /// Not a policy blob.
    BadMagic,
    /// A format version this code does not read.
    UnsupportedVersion(u16),
    /// An architecture this code does not run.
    UnknownArchitecture(u16),
    /// `K`, the belief side, the side-feature count or a layer's dimensions do not fit the
    /// architecture.
    ShapeMismatch,
    /// The CRC-32 over the blob does not match the stored one.
    BadChecksum,
    /// A tensor lies outside the data area, or a kind/activation code is unknown.
    BadTensorTable,
    /// A scale, zero point, multiplier, shift or weight is out of its range, or two tensors
    /// that must share quantisation parameters do not.
    BadQuantization,
    /// The instrument-profile byte names no profile this code knows.
    UnknownInstrument(u8),
}

impl core::fmt::Display for BlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BlobError::Truncated => f.write_str("truncated (shorter than its declared length)"),
            BlobError::TrailingBytes => f.write_str("longer than its declared length"),
            BlobError::BadMagic => f.write_str("not an int8 policy blob (bad magic)"),
            BlobError::UnsupportedVersion(v) => write!(f, "unsupported blob format version {v}"),
            BlobError::UnknownArchitecture(a) => write!(f, "unknown architecture id {a}"),
            BlobError::ShapeMismatch => f.write_str("shapes do not fit the architecture"),
            BlobError::BadChecksum => f.write_str("checksum mismatch (corrupt blob)"),
            BlobError::BadTensorTable => f.write_str("bad tensor table"),
            BlobError::BadQuantization => f.write_str("bad quantisation parameters"),
            BlobError::UnknownInstrument(c) => write!(f, "unknown instrument profile {c}"),
        }
    }
}
