//! The one error type of the host side of the link: what can go wrong talking to the
//! device, whatever the transport ([`crate::link::serial`]) or the emulator
//! ([`crate::link::device::Qemu`]) it runs over. A leaf: it imports only the core's wire types.

use activesense_core::protocol::{FrameError, WireError};
use std::io;

/// Everything that can go wrong talking to the device.
#[derive(Debug)]
pub enum LinkError {
    /// No reply within the transport's timeout.
    Timeout,
    /// The link closed (EOF / broken pipe / device gone).
    Disconnected,
    /// Other I/O failure.
    Io(io::Error),
    /// The device rejected the request.
    Device(WireError),
    /// The device answered something the protocol does not allow here.
    Unexpected(String),
    /// The device is not compatible with this host (protocol or limits).
    Incompatible(String),
    /// A frame from the device failed to decode.
    BadFrame(FrameError),
    /// A local error (plan too large, transport setup...).
    Local(String),
    /// A request could not be got through: sent `sends` times (re-sent after corrupt
    /// frames or time-outs), `last` is what went wrong the last time.
    GaveUp {
        /// Times the request was sent.
        sends: u32,
        /// The last failure.
        last: Box<LinkError>,
    },
}

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkError::Timeout => write!(
                f,
                "timed out waiting for the device (is it running, on this port and baud rate?)"
            ),
            LinkError::Disconnected => write!(f, "the device link closed"),
            LinkError::Io(e) => write!(f, "link I/O error: {e}"),
            LinkError::Device(e) => write!(f, "device error: {e}"),
            LinkError::Unexpected(s) => write!(f, "unexpected reply from the device: {s}"),
            LinkError::Incompatible(s) => write!(f, "incompatible device: {s}"),
            LinkError::BadFrame(e) => write!(f, "corrupt frame from the device: {e}"),
            LinkError::Local(s) => write!(f, "{s}"),
            LinkError::GaveUp { sends, last } => write!(
                f,
                "no clean reply after sending the request {sends} times (last: {last}); check \
                 the cable, the baud rate and the line's noise"
            ),
        }
    }
}

impl std::error::Error for LinkError {}

impl From<io::Error> for LinkError {
    fn from(e: io::Error) -> Self {
        match e.kind() {
            io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => LinkError::Timeout,
            io::ErrorKind::UnexpectedEof
            | io::ErrorKind::BrokenPipe
            | io::ErrorKind::ConnectionReset
            | io::ErrorKind::ConnectionAborted => LinkError::Disconnected,
            _ => LinkError::Io(e),
        }
    }
}

/// Result alias.
pub type LinkResult<T> = Result<T, LinkError>;
