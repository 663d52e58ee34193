//! GeoCOM return codes as a typed value with the manual's names (GeoCOM Reference Manual
//! TPS1200/TS30/TM30 v1.50, appendix "Return codes"; the same numbers in GeoComPy's
//! `GeoComCode`), and what the session does with each class of them.

/// What a return code means for the session.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodeClass {
    /// GRC_OK.
    Ok,
    /// A warning whose values are still valid (e.g. accuracy not guaranteed): used, logged.
    Warning,
    /// The EDM found no distance (no target, no signal): the reading is a no-return.
    NoDistance,
    /// The instrument is busy: wait and repeat the same request.
    Busy,
    /// A communication error that a repeat can cure (checksum, undecodable request).
    Retry,
    /// Anything else: the session ends with the instrument left still.
    Fatal,
}

/// A GeoCOM return code (`RC` or `RC_COM`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ReturnCode(pub u16);

/// `(code, manual name, class, what it means / what to check)`.
const TABLE: &[(u16, &str, CodeClass, &str)] = &[
    (0, "GRC_OK", CodeClass::Ok, "success"),
    (1, "GRC_UNDEFINED", CodeClass::Fatal, "unknown error"),
    (2, "GRC_IVPARAM", CodeClass::Fatal, "invalid parameter"),
    (3, "GRC_IVRESULT", CodeClass::Fatal, "invalid result"),
    (
        4,
        "GRC_FATAL",
        CodeClass::Fatal,
        "fatal error on the instrument",
    ),
    (
        5,
        "GRC_NOT_IMPL",
        CodeClass::Fatal,
        "not implemented on this instrument",
    ),
    (
        6,
        "GRC_TIME_OUT",
        CodeClass::Fatal,
        "function timed out on the instrument",
    ),
    (
        8,
        "GRC_ABORT",
        CodeClass::Fatal,
        "function aborted on the instrument",
    ),
    (
        12,
        "GRC_SHUT_DOWN",
        CodeClass::Fatal,
        "instrument is shutting down",
    ),
    (13, "GRC_SYSBUSY", CodeClass::Busy, "system busy"),
    (
        27,
        "GRC_NA",
        CodeClass::Fatal,
        "function not available (licence?)",
    ),
    (
        770,
        "GRC_EDM_NOSIGNAL",
        CodeClass::NoDistance,
        "no EDM signal",
    ),
    (
        1283,
        "GRC_TMC_NO_FULL_CORRECTION",
        CodeClass::Warning,
        "measurement without full correction",
    ),
    (
        1284,
        "GRC_TMC_ACCURACY_GUARANTEE",
        CodeClass::Warning,
        "accuracy not guaranteed",
    ),
    (
        1285,
        "GRC_TMC_ANGLE_OK",
        CodeClass::NoDistance,
        "angles valid, no distance",
    ),
    (
        1288,
        "GRC_TMC_ANGLE_NO_FULL_CORRECTION",
        CodeClass::NoDistance,
        "angles only, without full correction",
    ),
    (
        1289,
        "GRC_TMC_ANGLE_ACCURACY_GUARANTEE",
        CodeClass::NoDistance,
        "angles only, accuracy not guaranteed",
    ),
    (
        1290,
        "GRC_TMC_ANGLE_ERROR",
        CodeClass::Fatal,
        "no valid angle (check the compensator / inclination mode)",
    ),
    (
        1291,
        "GRC_TMC_DIST_PPM",
        CodeClass::Fatal,
        "wrong EDM ppm settings",
    ),
    (
        1292,
        "GRC_TMC_DIST_ERROR",
        CodeClass::NoDistance,
        "no distance: target not found",
    ),
    (1293, "GRC_TMC_BUSY", CodeClass::Busy, "TMC busy"),
    (
        1294,
        "GRC_TMC_SIGNAL_ERROR",
        CodeClass::NoDistance,
        "no EDM signal",
    ),
    (
        1792,
        "GRC_MOT_UNREADY",
        CodeClass::Fatal,
        "motorisation not ready",
    ),
    (1793, "GRC_MOT_BUSY", CodeClass::Busy, "motorisation busy"),
    (
        1798,
        "GRC_MOT_NOT_BUSY",
        CodeClass::Warning,
        "motor controller was not running (nothing to stop)",
    ),
    (
        3072,
        "GRC_COM_ERO",
        CodeClass::Retry,
        "communication: initiation failed",
    ),
    (
        3073,
        "GRC_COM_CANT_ENCODE",
        CodeClass::Fatal,
        "communication: cannot encode",
    ),
    (
        3074,
        "GRC_COM_CANT_DECODE",
        CodeClass::Retry,
        "communication: cannot decode",
    ),
    (
        3075,
        "GRC_COM_CANT_SEND",
        CodeClass::Retry,
        "communication: cannot send",
    ),
    (
        3076,
        "GRC_COM_CANT_RECV",
        CodeClass::Retry,
        "communication: cannot receive",
    ),
    (
        3077,
        "GRC_COM_TIMEDOUT",
        CodeClass::Retry,
        "communication: time-out",
    ),
    (
        3078,
        "GRC_COM_WRONG_FORMAT",
        CodeClass::Retry,
        "communication: wrong packet format",
    ),
    (
        3079,
        "GRC_COM_VER_MISMATCH",
        CodeClass::Fatal,
        "communication: RPC version mismatch",
    ),
    (
        3080,
        "GRC_COM_CANT_DECODE_REQ",
        CodeClass::Retry,
        "instrument could not decode the request",
    ),
    (
        3081,
        "GRC_COM_PROC_UNAVAIL",
        CodeClass::Fatal,
        "RPC not available on this instrument",
    ),
    (
        3082,
        "GRC_COM_CANT_ENCODE_REP",
        CodeClass::Retry,
        "instrument could not encode the reply",
    ),
    (
        3083,
        "GRC_COM_SYSTEM_ERR",
        CodeClass::Fatal,
        "communication: system error",
    ),
    (
        3085,
        "GRC_COM_FAILED",
        CodeClass::Fatal,
        "communication: failed",
    ),
    (
        3093,
        "GRC_COM_TR_ID_MISMATCH",
        CodeClass::Retry,
        "transaction id mismatch",
    ),
    (
        3094,
        "GRC_COM_NOT_GEOCOM",
        CodeClass::Retry,
        "reply is not GeoCOM",
    ),
    (
        3101,
        "GRC_COM_SRVR_RX_CHECKSUM_ERROR",
        CodeClass::Retry,
        "instrument received a bad checksum",
    ),
    (
        3102,
        "GRC_COM_CLNT_RX_CHECKSUM_ERROR",
        CodeClass::Retry,
        "client received a bad checksum",
    ),
    (
        3110,
        "GRC_COM_NO_CHECKSUM",
        CodeClass::Retry,
        "checksum missing",
    ),
    (
        8704,
        "GRC_AUT_TIMEOUT",
        CodeClass::Fatal,
        "positioning not completed in time",
    ),
    (
        8705,
        "GRC_AUT_DETENT_ERROR",
        CodeClass::Fatal,
        "positioning not possible (detent / working area)",
    ),
    (
        8706,
        "GRC_AUT_ANGLE_ERROR",
        CodeClass::Fatal,
        "angle measurement error while positioning",
    ),
    (
        8707,
        "GRC_AUT_MOTOR_ERROR",
        CodeClass::Fatal,
        "motorisation error: no motor, or it failed",
    ),
    (
        8708,
        "GRC_AUT_INCACC",
        CodeClass::Retry,
        "position not exactly reached",
    ),
    (
        8709,
        "GRC_AUT_DEV_ERROR",
        CodeClass::Retry,
        "deviation measurement error",
    ),
    (
        8710,
        "GRC_AUT_NO_TARGET",
        CodeClass::Fatal,
        "no ATR target found",
    ),
    (
        8711,
        "GRC_AUT_MULTIPLE_TARGETS",
        CodeClass::Fatal,
        "several ATR targets",
    ),
    (
        8712,
        "GRC_AUT_BAD_ENVIRONMENT",
        CodeClass::Fatal,
        "bad environment for ATR",
    ),
    (
        8714,
        "GRC_AUT_NOT_ENABLED",
        CodeClass::Fatal,
        "ATR not enabled",
    ),
    (
        8716,
        "GRC_AUT_ACCURACY",
        CodeClass::Retry,
        "position not within tolerance: repeat",
    ),
    (
        9217,
        "GRC_BAP_CHANGE_ALL_TO_DIST",
        CodeClass::Warning,
        "prism not detected, changed to distance",
    ),
];

impl ReturnCode {
    /// GRC_OK.
    pub const OK: ReturnCode = ReturnCode(0);
    /// GRC_SYSBUSY.
    pub const SYSBUSY: ReturnCode = ReturnCode(13);
    /// GRC_EDM_NOSIGNAL.
    pub const EDM_NOSIGNAL: ReturnCode = ReturnCode(770);
    /// GRC_TMC_ACCURACY_GUARANTEE.
    pub const TMC_ACCURACY_GUARANTEE: ReturnCode = ReturnCode(1284);
    /// GRC_TMC_ANGLE_OK.
    pub const TMC_ANGLE_OK: ReturnCode = ReturnCode(1285);
    /// GRC_TMC_DIST_ERROR.
    pub const TMC_DIST_ERROR: ReturnCode = ReturnCode(1292);
    /// GRC_TMC_BUSY.
    pub const TMC_BUSY: ReturnCode = ReturnCode(1293);
    /// GRC_TMC_SIGNAL_ERROR.
    pub const TMC_SIGNAL_ERROR: ReturnCode = ReturnCode(1294);
    /// GRC_COM_TIMEDOUT.
    pub const COM_TIMEDOUT: ReturnCode = ReturnCode(3077);
    /// GRC_COM_CANT_DECODE_REQ.
    pub const COM_CANT_DECODE_REQ: ReturnCode = ReturnCode(3080);
    /// GRC_COM_PROC_UNAVAIL.
    pub const COM_PROC_UNAVAIL: ReturnCode = ReturnCode(3081);
    /// GRC_COM_SRVR_RX_CHECKSUM_ERROR.
    pub const COM_SRVR_RX_CHECKSUM_ERROR: ReturnCode = ReturnCode(3101);
    /// GRC_COM_CLNT_RX_CHECKSUM_ERROR.
    pub const COM_CLNT_RX_CHECKSUM_ERROR: ReturnCode = ReturnCode(3102);
    /// GRC_AUT_MOTOR_ERROR.
    pub const AUT_MOTOR_ERROR: ReturnCode = ReturnCode(8707);
    /// GRC_AUT_NO_TARGET.
    pub const AUT_NO_TARGET: ReturnCode = ReturnCode(8710);
    /// GRC_IVPARAM.
    pub const IVPARAM: ReturnCode = ReturnCode(2);

    fn entry(self) -> Option<&'static (u16, &'static str, CodeClass, &'static str)> {
        TABLE.iter().find(|e| e.0 == self.0)
    }

    /// The manual's name (`GRC_UNKNOWN` for a number the table does not know).
    pub fn name(self) -> &'static str {
        self.entry().map_or("GRC_UNKNOWN", |e| e.1)
    }

    /// What the session does with it (unknown codes are fatal).
    pub fn class(self) -> CodeClass {
        self.entry().map_or(CodeClass::Fatal, |e| e.2)
    }

    /// One-phrase meaning.
    pub fn meaning(self) -> &'static str {
        self.entry()
            .map_or("return code not in the manual's table", |e| e.3)
    }
}

impl std::fmt::Display for ReturnCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({}: {})", self.name(), self.0, self.meaning())
    }
}

/// The RPC numbers of the job and their manual names (here, below the client, so that its
/// errors can name the RPC; [`crate::geocom::rpc`] re-exports them).
pub mod rpc_numbers {
    /// COM_NullProc: ping.
    pub const COM_NULLPROC: u16 = 0;
    /// COM_GetDoublePrecision: digits of reals in replies.
    pub const COM_GET_DOUBLE_PRECISION: u16 = 108;
    /// COM_GetSWVersion: GeoCOM release, version, subversion.
    pub const COM_GET_SW_VERSION: u16 = 110;
    /// CSV_GetInstrumentNo: serial number.
    pub const CSV_GET_INSTRUMENT_NO: u16 = 5003;
    /// CSV_GetInstrumentName: instrument name.
    pub const CSV_GET_INSTRUMENT_NAME: u16 = 5004;
    /// CSV_GetSWVersion: instrument firmware release, version, subversion.
    pub const CSV_GET_SW_VERSION: u16 = 5034;
    /// EDM_Laserpointer: the visible laser on/off.
    pub const EDM_LASERPOINTER: u16 = 1004;
    /// TMC_GetAngle5: Hz, V (simple angle measurement).
    pub const TMC_GET_ANGLE5: u16 = 2107;
    /// TMC_DoMeasure: start / stop / clear a distance measurement.
    pub const TMC_DO_MEASURE: u16 = 2008;
    /// TMC_GetSimpleMea: Hz, V and the slope distance of the last measurement.
    pub const TMC_GET_SIMPLE_MEA: u16 = 2108;
    /// TMC_GetStation: E0, N0, H0, Hi.
    pub const TMC_GET_STATION: u16 = 2009;
    /// TMC_SetStation: E0, N0, H0, Hi.
    pub const TMC_SET_STATION: u16 = 2010;
    /// TMC_SetEdmMode: EDM measurement mode.
    pub const TMC_SET_EDM_MODE: u16 = 2020;
    /// TMC_SetOrientation: make the current direction read a given Hz.
    pub const TMC_SET_ORIENTATION: u16 = 2113;
    /// MOT_StopController: stop the motor controller.
    pub const MOT_STOP_CONTROLLER: u16 = 6002;
    /// AUT_MakePositioning: turn the telescope to Hz, V.
    pub const AUT_MAKE_POSITIONING: u16 = 9027;
    /// BAP_SetTargetType: reflector or reflectorless.
    pub const BAP_SET_TARGET_TYPE: u16 = 17021;
    /// BAP_GetTargetType.
    pub const BAP_GET_TARGET_TYPE: u16 = 17022;
    /// BAP_MeasDistanceAngle: measure and return Hz, V, distance.
    pub const BAP_MEAS_DISTANCE_ANGLE: u16 = 17017;

    /// The manual's name of an RPC number.
    pub fn rpc_name(rpc: u16) -> &'static str {
        match rpc {
            COM_NULLPROC => "COM_NullProc",
            COM_GET_DOUBLE_PRECISION => "COM_GetDoublePrecision",
            COM_GET_SW_VERSION => "COM_GetSWVersion",
            CSV_GET_INSTRUMENT_NO => "CSV_GetInstrumentNo",
            CSV_GET_INSTRUMENT_NAME => "CSV_GetInstrumentName",
            CSV_GET_SW_VERSION => "CSV_GetSWVersion",
            EDM_LASERPOINTER => "EDM_Laserpointer",
            TMC_GET_ANGLE5 => "TMC_GetAngle5",
            TMC_DO_MEASURE => "TMC_DoMeasure",
            TMC_GET_SIMPLE_MEA => "TMC_GetSimpleMea",
            TMC_GET_STATION => "TMC_GetStation",
            TMC_SET_STATION => "TMC_SetStation",
            TMC_SET_EDM_MODE => "TMC_SetEdmMode",
            TMC_SET_ORIENTATION => "TMC_SetOrientation",
            MOT_STOP_CONTROLLER => "MOT_StopController",
            AUT_MAKE_POSITIONING => "AUT_MakePositioning",
            BAP_SET_TARGET_TYPE => "BAP_SetTargetType",
            BAP_GET_TARGET_TYPE => "BAP_GetTargetType",
            BAP_MEAS_DISTANCE_ANGLE => "BAP_MeasDistanceAngle",
            _ => "RPC",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_sorted_and_unique() {
        assert!(TABLE.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(TABLE.iter().all(|e| e.1.starts_with("GRC_")));
    }

    #[test]
    fn classes() {
        assert_eq!(ReturnCode(0).class(), CodeClass::Ok);
        assert_eq!(ReturnCode::TMC_DIST_ERROR.class(), CodeClass::NoDistance);
        assert_eq!(ReturnCode::TMC_BUSY.class(), CodeClass::Busy);
        assert_eq!(ReturnCode::AUT_MOTOR_ERROR.class(), CodeClass::Fatal);
        assert_eq!(ReturnCode(60000).class(), CodeClass::Fatal);
        assert_eq!(ReturnCode(60000).name(), "GRC_UNKNOWN");
        assert!(ReturnCode::TMC_ACCURACY_GUARANTEE
            .to_string()
            .contains("accuracy not guaranteed"));
    }
}
