//! GeoCOM ASCII framing (Leica GeoCOM Reference Manual, TPS1200/TS30/TM30 v1.50, §2.3
//! "ASCII protocol"): the request `%R1Q,<RPC>[,<TrId>[,<CRC>]]:<P0>,<P1>,…` and the reply
//! `%R1P,<RC_COM>[,<TrId>[,<CRC>]]:<RC>[,<P0>,…]`, each ended by CR/LF. Parameters are
//! decimal integers, decimal reals (angles in radians, distances in metres), strings in
//! double quotes and bytes in single quotes (`'07'`). The optional CRC field is the
//! CRC-16/ARC of the line with that field removed (as GeoComPy computes it,
//! `docs/GEOCOM.md`).
//!
//! Both directions are here because the client emits requests and parses replies while
//! the simulator ([`crate::geocom::sim`]) does the reverse. Nothing here panics on any
//! input: a line that is not GeoCOM is a [`WireError`].

use std::fmt::Write as _;

/// Longest line either side accepts (the manual's largest replies are far shorter).
pub const MAX_LINE: usize = 1024;

/// One request parameter.
#[derive(Clone, Debug, PartialEq)]
pub enum Param {
    /// An integer (enums, booleans 0/1, milliseconds).
    Int(i64),
    /// A real (radians, metres).
    Real(f64),
    /// A string, sent in double quotes.
    Str(String),
}

/// Why a line is not a GeoCOM request or reply.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WireError {
    /// Longer than [`MAX_LINE`].
    TooLong,
    /// Not ASCII text.
    NotAscii,
    /// Does not start with the expected `%R1Q,` / `%R1P,`.
    BadPrefix,
    /// No `:` between header and parameters.
    NoSeparator,
    /// A header field is not a decimal number in range.
    BadHeader,
    /// A string or byte value is not closed.
    Unterminated,
    /// A real parameter is not finite (emitting NaN or ∞ is refused).
    NonFinite,
}

impl std::fmt::Display for WireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            WireError::TooLong => "line too long",
            WireError::NotAscii => "line is not ASCII",
            WireError::BadPrefix => "line does not start with %R1Q/%R1P",
            WireError::NoSeparator => "no ':' after the header",
            WireError::BadHeader => "header field is not a number",
            WireError::Unterminated => "unterminated string",
            WireError::NonFinite => "non-finite real",
        })
    }
}

/// CRC-16/ARC (poly 0xA001 reflected, init 0), the GeoCOM checksum.
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in data {
        crc ^= b as u16;
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

fn push_param(out: &mut String, p: &Param) -> Result<(), WireError> {
    match p {
        Param::Int(i) => {
            let _ = write!(out, "{i}");
        }
        Param::Real(x) => {
            if !x.is_finite() {
                return Err(WireError::NonFinite);
            }
            // Rust's shortest round-trip form, never an exponent: the reader gets the
            // same f64 back (the bit-identity tests rely on it).
            let _ = write!(out, "{x}");
            if x.fract() == 0.0 {
                // Keep reals recognisable as reals ("2.0", not "2").
                out.push_str(".0");
            }
        }
        Param::Str(s) => {
            out.push('"');
            for c in s.chars().filter(|c| c.is_ascii() && *c != '"' && *c >= ' ') {
                out.push(c);
            }
            out.push('"');
        }
    }
    Ok(())
}

fn join(params: &[Param]) -> Result<String, WireError> {
    let mut s = String::new();
    for (i, p) in params.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        push_param(&mut s, p)?;
    }
    Ok(s)
}

/// A request line (without terminator): `%R1Q,<rpc>,<trid>[,<crc>]:<params>`.
pub fn emit_request(
    rpc: u16,
    trid: Option<u16>,
    crc: bool,
    params: &[Param],
) -> Result<String, WireError> {
    let p = join(params)?;
    let head = match trid {
        Some(t) => format!("%R1Q,{rpc},{t}"),
        None => format!("%R1Q,{rpc}"),
    };
    if crc {
        let t = trid.unwrap_or(0);
        let base = format!("%R1Q,{rpc},{t}:{p}");
        Ok(format!("%R1Q,{rpc},{t},{}:{p}", crc16(base.as_bytes())))
    } else {
        Ok(format!("{head}:{p}"))
    }
}

/// A reply line (without terminator): `%R1P,<rc_com>,<trid>[,<crc>]:<rc>[,<values>]`.
/// `values` are already formatted ([`format_values`]).
pub fn emit_reply(rc_com: u16, trid: u16, crc: bool, rc: u16, values: &str) -> String {
    let tail = if values.is_empty() {
        format!("{rc}")
    } else {
        format!("{rc},{values}")
    };
    if crc {
        let base = format!("%R1P,{rc_com},{trid}:{tail}");
        format!("%R1P,{rc_com},{trid},{}:{tail}", crc16(base.as_bytes()))
    } else {
        format!("%R1P,{rc_com},{trid}:{tail}")
    }
}

/// Formats reply values like request parameters.
pub fn format_values(values: &[Param]) -> Result<String, WireError> {
    join(values)
}

/// The header of a parsed line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Header {
    /// The request's RPC number, or the reply's `RC_COM`.
    pub first: u16,
    /// Transaction id (`None`: absent; the manual's replies then carry 0).
    pub trid: Option<u16>,
    /// The CRC field, if present.
    pub crc: Option<u16>,
    /// True when the CRC field is present and matches the line.
    pub crc_ok: bool,
}

/// A parsed request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RequestLine {
    /// Header (`first` = RPC number).
    pub header: Header,
    /// Raw parameter fields (strings still quoted).
    pub params: Vec<String>,
}

/// A parsed reply.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reply {
    /// Header (`first` = RC_COM).
    pub header: Header,
    /// The RPC's return code.
    pub rc: u16,
    /// Raw value fields (strings still quoted).
    pub values: Vec<String>,
}

fn check_line(line: &str) -> Result<&str, WireError> {
    if line.len() > MAX_LINE {
        return Err(WireError::TooLong);
    }
    if !line.is_ascii() {
        return Err(WireError::NotAscii);
    }
    Ok(line.trim_end_matches(['\r', '\n']).trim_start_matches('\n'))
}

fn num<T: std::str::FromStr>(s: &str) -> Result<T, WireError> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(WireError::BadHeader);
    }
    s.parse().map_err(|_| WireError::BadHeader)
}

/// Splits `a,b,"c,d",'e'` on commas outside quotes.
pub fn split_fields(s: &str) -> Result<Vec<String>, WireError> {
    let mut out = Vec::new();
    if s.is_empty() {
        return Ok(out);
    }
    let mut cur = String::new();
    let mut quote: Option<char> = None;
    for c in s.chars() {
        match (quote, c) {
            (None, ',') => out.push(std::mem::take(&mut cur)),
            (None, '"' | '\'') => {
                quote = Some(c);
                cur.push(c);
            }
            (Some(q), c) if c == q => {
                quote = None;
                cur.push(c);
            }
            _ => cur.push(c),
        }
    }
    if quote.is_some() {
        return Err(WireError::Unterminated);
    }
    out.push(cur);
    Ok(out)
}

/// Parses `<prefix><first>[,<trid>[,<crc>]]:<rest>`; the CRC is checked over the line
/// with its field removed.
fn parse_header<'a>(line: &'a str, prefix: &str) -> Result<(Header, &'a str), WireError> {
    let body = line.strip_prefix(prefix).ok_or(WireError::BadPrefix)?;
    let (head, rest) = body.split_once(':').ok_or(WireError::NoSeparator)?;
    let fields: Vec<&str> = head.split(',').collect();
    let (first, trid, crc) = match fields.as_slice() {
        [a] => (num(a)?, None, None),
        [a, t] => (num(a)?, Some(num(t)?), None),
        [a, t, c] => (num(a)?, Some(num(t)?), Some(num(c)?)),
        _ => return Err(WireError::BadHeader),
    };
    let crc_ok = match (crc, trid) {
        (Some(c), Some(t)) => {
            let base = format!("{prefix}{first},{t}:{rest}");
            crc16(base.as_bytes()) == c
        }
        _ => false,
    };
    Ok((
        Header {
            first,
            trid,
            crc,
            crc_ok,
        },
        rest,
    ))
}

/// Parses a request line (the simulator's side).
pub fn parse_request(line: &str) -> Result<RequestLine, WireError> {
    let line = check_line(line)?;
    let (header, rest) = parse_header(line, "%R1Q,")?;
    Ok(RequestLine {
        header,
        params: split_fields(rest)?,
    })
}

/// Parses a reply line (the client's side).
pub fn parse_reply(line: &str) -> Result<Reply, WireError> {
    let line = check_line(line)?;
    let (header, rest) = parse_header(line, "%R1P,")?;
    let mut fields = split_fields(rest)?;
    if fields.is_empty() {
        return Err(WireError::BadHeader);
    }
    let rc = num(&fields.remove(0))?;
    Ok(Reply {
        header,
        rc,
        values: fields,
    })
}

/// A real value field (finite only).
pub fn real(field: &str) -> Option<f64> {
    let t = field.trim();
    // `f64::from_str` also takes "inf"/"NaN"; an instrument never sends those.
    if t.is_empty()
        || !t
            .bytes()
            .all(|b| b.is_ascii_digit() || b"+-.eE".contains(&b))
    {
        return None;
    }
    t.parse::<f64>().ok().filter(|x| x.is_finite())
}

/// An integer value field.
pub fn int(field: &str) -> Option<i64> {
    field.trim().parse().ok()
}

/// A string value field without its quotes.
pub fn string(field: &str) -> Option<String> {
    let t = field.trim();
    t.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .map(str::to_owned)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn crc_matches_crc16_arc_check_value() {
        // The catalogue check value of CRC-16/ARC.
        assert_eq!(crc16(b"123456789"), 0xBB3D);
    }

    #[test]
    fn request_and_reply_round_trip() {
        let l = emit_request(
            9027,
            Some(7),
            false,
            &[
                Param::Real(1.25),
                Param::Real(std::f64::consts::FRAC_PI_2),
                Param::Int(0),
            ],
        )
        .unwrap();
        assert_eq!(l, "%R1Q,9027,7:1.25,1.5707963267948966,0");
        let r = parse_request(&l).unwrap();
        assert_eq!(r.header.first, 9027);
        assert_eq!(r.header.trid, Some(7));
        assert_eq!(real(&r.params[1]), Some(std::f64::consts::FRAC_PI_2));
        let c = emit_request(0, Some(3), true, &[]).unwrap();
        let r = parse_request(&c).unwrap();
        assert!(r.header.crc_ok, "{c}");
        let rep = emit_reply(0, 3, true, 0, "\"TS30\",2.0");
        let p = parse_reply(&rep).unwrap();
        assert!(p.header.crc_ok);
        assert_eq!(string(&p.values[0]).as_deref(), Some("TS30"));
        assert_eq!(real(&p.values[1]), Some(2.0));
        // The manual's example reply (CSV_GetDateTime): bytes in single quotes.
        let p = parse_reply("%R1P,0,0:0,1996,'07','19','10','13','2f'\r\n").unwrap();
        assert_eq!(p.values.len(), 6);
        assert!(parse_reply("%R1P,0,0:0,\"open").is_err());
        assert!(emit_request(1, None, false, &[Param::Real(f64::NAN)]).is_err());
        assert_eq!(real("nan"), None);
        assert_eq!(real("inf"), None);
    }

    #[test]
    fn tampered_crc_is_detected() {
        let rep = emit_reply(0, 9, true, 0, "1.5");
        let bad = rep.replace("1.5", "1.6");
        assert!(!parse_reply(&bad).unwrap().header.crc_ok);
    }

    proptest! {
        #[test]
        fn parsers_never_panic(s in "\\PC{0,200}") {
            let _ = parse_reply(&s);
            let _ = parse_request(&s);
            let _ = split_fields(&s);
            let _ = real(&s);
        }

        #[test]
        fn parsers_never_panic_on_near_misses(
            head in prop::sample::select(vec!["%R1P,", "%R1Q,", "%R1P,0,", "%R1P,0,1,"]),
            s in "[0-9,:\"'.%RPQ\\-]{0,60}",
        ) {
            let line = format!("{head}{s}");
            let _ = parse_reply(&line);
            let _ = parse_request(&line);
        }

        #[test]
        fn reals_round_trip_bit_exactly(x in prop_oneof![any::<f64>(), (-1e3f64..1e3)].prop_filter("finite", |x| x.is_finite()),
                                        trid in any::<u16>(), crc in any::<bool>()) {
            let l = emit_request(2108, Some(trid), crc, &[Param::Real(x), Param::Str("a\"b".into())]).unwrap();
            let r = parse_request(&l).unwrap();
            prop_assert_eq!(r.header.trid, Some(trid));
            prop_assert_eq!(r.header.crc_ok, crc);
            prop_assert_eq!(real(&r.params[0]).map(f64::to_bits), Some(x.to_bits()));
            let text = string(&r.params[1]);
            prop_assert_eq!(text.as_deref(), Some("ab"));
            // A simulator range: f32, sent as its f64, read back as f32 (finite ones only).
            let f = x as f32;
            if f.is_finite() {
                let v = format_values(&[Param::Real(f as f64)]).unwrap();
                let rep = parse_reply(&emit_reply(0, trid, crc, 0, &v)).unwrap();
                prop_assert_eq!(real(&rep.values[0]).map(|y| (y as f32).to_bits()), Some(f.to_bits()));
            }
        }
    }
}
