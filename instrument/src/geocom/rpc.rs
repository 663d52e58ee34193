//! The GeoCOM RPCs the station job uses, typed. Numbers and parameter lists follow the
//! GeoCOM Reference Manual (TPS1200/TS30/TM30 v1.50) and agree with two independent open
//! clients, GeoComPy 1.0.0 (`geocompy/geo/*.py`) and DMPACK's `dm_geocom_api`
//! (`docs/GEOCOM.md` lists each with its source).

use crate::geocom::client::{Client, Fault, GeoComError};
use crate::geocom::codes::{CodeClass, ReturnCode};
use crate::geocom::wire::{self, Param, Reply};

pub use crate::geocom::codes::rpc_numbers::*;

/// TMC_MEASURE_PRG values of TMC_DoMeasure.
pub mod tmc_prog {
    /// TMC_STOP: stop the measurement program.
    pub const STOP: i64 = 0;
    /// TMC_DEF_DIST: one distance in the set EDM mode.
    pub const DEF_DIST: i64 = 1;
    /// TMC_CLEAR: stop and clear the distance.
    pub const CLEAR: i64 = 3;
}
/// TMC_INCLINE_PRG TMC_AUTO_INC: the instrument chooses the inclination correction.
pub const TMC_AUTO_INC: i64 = 1;
/// BAP_TARGET_TYPE BAP_REFL_LESS.
pub const BAP_REFL_LESS: i64 = 1;
/// EDM_MODE EDM_SINGLE_STANDARD (TPS1200 numbering).
pub const EDM_SINGLE_STANDARD: i64 = 2;
/// AUT_POSMODE AUT_NORMAL, AUT_ATRMODE AUT_POSITION.
pub const AUT_NORMAL: i64 = 0;
/// AUT_ATRMODE AUT_POSITION (plain angle positioning, no target search).
pub const AUT_POSITION: i64 = 0;
/// BAP_MEASURE_PRG BAP_DEF_DIST.
pub const BAP_DEF_DIST: i64 = 2;

/// Fails unless the RPC returned GRC_OK (or a warning whose values are valid).
fn ok(rpc: u16, r: Reply) -> Result<Reply, GeoComError> {
    match ReturnCode(r.rc).class() {
        CodeClass::Ok | CodeClass::Warning => Ok(r),
        _ => Err(GeoComError {
            rpc,
            fault: Fault::Code(ReturnCode(r.rc)),
        }),
    }
}

fn bad(rpc: u16, what: &str, r: &Reply) -> GeoComError {
    GeoComError {
        rpc,
        fault: Fault::BadReply(format!("{what} (values {:?})", r.values)),
    }
}

fn reals<const N: usize>(rpc: u16, r: &Reply) -> Result<[f64; N], GeoComError> {
    let mut out = [0.0; N];
    for (i, o) in out.iter_mut().enumerate() {
        *o = r
            .values
            .get(i)
            .and_then(|v| wire::real(v))
            .ok_or_else(|| bad(rpc, "expected reals", r))?;
    }
    Ok(out)
}

fn plain(c: &mut Client, rpc: u16, params: &[Param]) -> Result<Reply, GeoComError> {
    let r = c.call(rpc, params)?;
    ok(rpc, r)
}

/// COM_NullProc.
pub fn null_proc(c: &mut Client) -> Result<(), GeoComError> {
    plain(c, COM_NULLPROC, &[]).map(drop)
}

/// CSV_GetInstrumentName.
pub fn instrument_name(c: &mut Client) -> Result<String, GeoComError> {
    let r = plain(c, CSV_GET_INSTRUMENT_NAME, &[])?;
    r.values
        .first()
        .and_then(|v| wire::string(v))
        .ok_or_else(|| bad(CSV_GET_INSTRUMENT_NAME, "expected a string", &r))
}

/// CSV_GetInstrumentNo.
pub fn serial_no(c: &mut Client) -> Result<i64, GeoComError> {
    let r = plain(c, CSV_GET_INSTRUMENT_NO, &[])?;
    r.values
        .first()
        .and_then(|v| wire::int(v))
        .ok_or_else(|| bad(CSV_GET_INSTRUMENT_NO, "expected an integer", &r))
}

/// COM_GetSWVersion: (release, version, subversion).
pub fn sw_version(c: &mut Client) -> Result<(i64, i64, i64), GeoComError> {
    let r = plain(c, COM_GET_SW_VERSION, &[])?;
    let v: Vec<i64> = r.values.iter().filter_map(|v| wire::int(v)).collect();
    match v.as_slice() {
        [a, b, c, ..] => Ok((*a, *b, *c)),
        _ => Err(bad(COM_GET_SW_VERSION, "expected three integers", &r)),
    }
}

/// BAP_SetTargetType(BAP_REFL_LESS).
pub fn set_reflectorless(c: &mut Client) -> Result<(), GeoComError> {
    plain(c, BAP_SET_TARGET_TYPE, &[Param::Int(BAP_REFL_LESS)]).map(drop)
}

/// TMC_SetEdmMode(mode).
pub fn set_edm_mode(c: &mut Client, mode: i64) -> Result<(), GeoComError> {
    plain(c, TMC_SET_EDM_MODE, &[Param::Int(mode)]).map(drop)
}

/// AUT_MakePositioning(Hz, V, AUT_NORMAL, AUT_POSITION, 0): blocks until the telescope
/// stands at (Hz, V).
pub fn make_positioning(c: &mut Client, hz: f64, v: f64) -> Result<(), GeoComError> {
    plain(
        c,
        AUT_MAKE_POSITIONING,
        &[
            Param::Real(hz),
            Param::Real(v),
            Param::Int(AUT_NORMAL),
            Param::Int(AUT_POSITION),
            Param::Int(0),
        ],
    )
    .map(drop)
}

/// TMC_GetAngle5(TMC_AUTO_INC): (Hz, V).
pub fn get_angle(c: &mut Client) -> Result<(f64, f64), GeoComError> {
    let r = plain(c, TMC_GET_ANGLE5, &[Param::Int(TMC_AUTO_INC)])?;
    let [hz, v] = reals::<2>(TMC_GET_ANGLE5, &r)?;
    Ok((hz, v))
}

/// TMC_DoMeasure(prog, TMC_AUTO_INC).
pub fn do_measure(c: &mut Client, prog: i64) -> Result<(), GeoComError> {
    plain(
        c,
        TMC_DO_MEASURE,
        &[Param::Int(prog), Param::Int(TMC_AUTO_INC)],
    )
    .map(drop)
}

/// One distance reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Horizontal angle (rad).
    pub hz: f64,
    /// Zenith angle (rad).
    pub v: f64,
    /// Slope distance (m); `None` when the EDM found no distance.
    pub slope: Option<f64>,
    /// The return code (GRC_OK, a warning, or the no-distance code).
    pub rc: ReturnCode,
}

fn measurement(rpc: u16, r: Reply) -> Result<Measurement, GeoComError> {
    let rc = ReturnCode(r.rc);
    match rc.class() {
        CodeClass::Ok | CodeClass::Warning => {
            let [hz, v, d] = reals::<3>(rpc, &r)?;
            if d < 0.0 {
                return Err(bad(rpc, "negative distance", &r));
            }
            Ok(Measurement {
                hz,
                v,
                slope: Some(d),
                rc,
            })
        }
        CodeClass::NoDistance => {
            let a = reals::<2>(rpc, &r).unwrap_or([f64::NAN; 2]);
            Ok(Measurement {
                hz: a[0],
                v: a[1],
                slope: None,
                rc,
            })
        }
        _ => Err(GeoComError {
            rpc,
            fault: Fault::Code(rc),
        }),
    }
}

/// TMC_GetSimpleMea(wait_ms, TMC_AUTO_INC): the last measurement.
pub fn get_simple_mea(c: &mut Client, wait_ms: i64) -> Result<Measurement, GeoComError> {
    let r = c.call(
        TMC_GET_SIMPLE_MEA,
        &[Param::Int(wait_ms), Param::Int(TMC_AUTO_INC)],
    )?;
    measurement(TMC_GET_SIMPLE_MEA, r)
}

/// BAP_MeasDistanceAngle(BAP_DEF_DIST): measure and return in one call.
pub fn meas_distance_angle(c: &mut Client) -> Result<Measurement, GeoComError> {
    let r = c.call(BAP_MEAS_DISTANCE_ANGLE, &[Param::Int(BAP_DEF_DIST)])?;
    measurement(BAP_MEAS_DISTANCE_ANGLE, r)
}

/// TMC_GetStation: (E0, N0, H0, Hi).
pub fn get_station(c: &mut Client) -> Result<[f64; 4], GeoComError> {
    let r = plain(c, TMC_GET_STATION, &[])?;
    reals::<4>(TMC_GET_STATION, &r)
}

/// TMC_SetStation(E0, N0, H0, Hi).
pub fn set_station(c: &mut Client, station: [f64; 4]) -> Result<(), GeoComError> {
    let p: Vec<Param> = station.iter().map(|&x| Param::Real(x)).collect();
    plain(c, TMC_SET_STATION, &p).map(drop)
}

/// TMC_SetOrientation(Hz): the current direction reads `hz` from now on.
pub fn set_orientation(c: &mut Client, hz: f64) -> Result<(), GeoComError> {
    plain(c, TMC_SET_ORIENTATION, &[Param::Real(hz)]).map(drop)
}

/// Leaves the instrument still with the EDM off: TMC_DoMeasure(TMC_CLEAR),
/// EDM_Laserpointer(off), MOT_StopController(MOT_NORMAL). Best effort: every call is made
/// even if an earlier one fails; the failures are returned.
pub fn safe_state(c: &mut Client) -> Vec<GeoComError> {
    let mut errs = Vec::new();
    for (rpc, p) in [
        (
            TMC_DO_MEASURE,
            vec![Param::Int(tmc_prog::CLEAR), Param::Int(TMC_AUTO_INC)],
        ),
        (EDM_LASERPOINTER, vec![Param::Int(0)]),
        (MOT_STOP_CONTROLLER, vec![Param::Int(0)]),
    ] {
        match c.call(rpc, &p) {
            Ok(r) if matches!(ReturnCode(r.rc).class(), CodeClass::Ok | CodeClass::Warning) => {}
            // Nothing was running: still.
            Ok(r) if r.rc == 1798 => {}
            Ok(r) => errs.push(GeoComError {
                rpc,
                fault: Fault::Code(ReturnCode(r.rc)),
            }),
            Err(e) => errs.push(e),
        }
    }
    errs
}
