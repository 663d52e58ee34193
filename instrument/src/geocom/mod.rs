//! Drive a commercial motorised total station (Leica TPS1200 / TS / TM / MS) over GeoCOM,
//! the ASCII RPC protocol of its serial, Bluetooth-serial and TCP ports, with the same
//! core decision chain the firmware runs (`docs/GEOCOM.md`). Lowest first:
//! [`wire`] the request/reply framing, [`codes`] the return codes, [`client`] the
//! transports and the checked, retrying call, [`rpc`] the typed RPCs, [`instrument`] the
//! instrument behind the core's `Instrument` trait and the station session, [`sim`] the
//! instrument simulator the tests and `activesense geocom-sim` run.

pub mod client;
pub mod codes;
pub mod instrument;
pub mod rpc;
pub mod sim;
pub mod wire;
