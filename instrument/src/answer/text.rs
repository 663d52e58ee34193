//! [`Answer::to_text`]: the answer as printed by `episode`, `sim` and `serial run`.

use super::{Answer, Determination, ReadingFit};
use std::fmt::Write;

/// Decimals that show a millimetre in `unit`.
fn decimals(unit: &str) -> usize {
    match unit {
        "mm" => 1,
        "cm" => 2,
        "dm" => 3,
        "in" => 2,
        _ => 3,
    }
}

impl Answer {
    /// The answer in a few lines (the first starts with `answer`), for a terminal.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let u = &self.unit;
        let d = decimals(u);
        let _ = writeln!(
            s,
            "answer ({}; unit {u}; heading = {}):",
            self.coordinates, self.heading_convention
        );
        let (Some(e), Some(n), Some(h), Some(g)) = (
            self.easting,
            self.northing,
            self.heading_deg,
            self.heading_gon,
        ) else {
            let _ = writeln!(s, "  no station: {}", self.precision);
            return s;
        };
        let _ = writeln!(
            s,
            "  station: E {e:.d$} {u}  N {n:.d$} {u}  heading {h:.3}° = {g:.4} gon{} (azimuth {:.4} gon, clockwise from +y){}",
            if self.heading_given { " (given)" } else { "" },
            self.azimuth_gon.unwrap_or(0.0),
            if self.estimate == "coarse" {
                "  [coarse estimate]"
            } else {
                ""
            }
        );
        match (self.sigma_e, self.sigma_n, self.sigma_heading_deg) {
            (Some(se), Some(sn), Some(sh)) => {
                let heading = if self.heading_given {
                    "heading given".to_string()
                } else {
                    format!("heading ±{sh:.3}°")
                };
                let _ = writeln!(
                    s,
                    "  precision (1σ): E ±{se:.p$} {u}  N ±{sn:.p$} {u}  {heading}; {}",
                    self.precision,
                    p = d + 1
                );
            }
            _ => {
                let what = if self.determination == Determination::Underdetermined {
                    "UNDERDETERMINED"
                } else {
                    "none"
                };
                let _ = writeln!(s, "  precision: {what}: {}", self.precision);
            }
        }
        let _ = writeln!(
            s,
            "  readings: {} ({} explained by the answer){}",
            self.readings.len(),
            self.readings_explained,
            if self.readings.is_empty() {
                String::new()
            } else {
                format!(
                    ": {}",
                    self.readings
                        .iter()
                        .map(|r| format!("{:.1}° {:.d$}", r.bearing_deg, r.range))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        );
        let off: Vec<_> = self
            .readings
            .iter()
            .filter(|r| !matches!(r.fit, ReadingFit::Explained | ReadingFit::ThroughDoor))
            .collect();
        if !off.is_empty() {
            let _ = writeln!(s, "  readings the plan does not explain at the answer:");
            for r in off {
                let what = match r.fit {
                    ReadingFit::Short => "short: something in front of the wall",
                    ReadingFit::Long => "long: beyond the wall",
                    _ => "no wall of the plan along it",
                };
                let expected = match (r.expected, r.wall) {
                    (Some(x), Some(w)) => format!("{x:.d$} {u} expected (wall {w})"),
                    _ => "no range expected".to_string(),
                };
                let _ = writeln!(
                    s,
                    "    {:.1}°: {:.d$} {u} measured, {expected}; {what}",
                    r.bearing_deg, r.range
                );
            }
        }
        if let Some(m) = &self.mismatch {
            let _ = writeln!(s, "  ROOM DOES NOT MATCH THE PLAN: {m}");
        }
        if let Some(w) = &self.wall_reliance {
            let _ = writeln!(s, "  RESTS ON ONE WALL: {w}");
        }
        let _ = writeln!(
            s,
            "  risk that this answer is wrong: {}",
            match self.risk {
                Some(r) => format!(
                    "{} (the smallest --stop-risk at which the calibrated stop answers with it)",
                    percent(r)
                ),
                None if self.wall_reliance.is_some() => {
                    "not available (the stop does not answer while the answer rests on one wall: see above)".into()
                }
                None => "not available (belief below the stop's gate, or no registration)".into(),
            }
        );
        if self.ambiguous {
            let _ = writeln!(
                s,
                "  AMBIGUOUS: {} poses are consistent{}; no single pose is certain{}",
                self.candidates.len(),
                self.ambiguity
                    .as_deref()
                    .map(|a| format!(" ({a})"))
                    .unwrap_or_default(),
                if self.heading_hint.is_none() {
                    "; give --heading-hint DEG±TOL to choose"
                } else {
                    ""
                }
            );
        } else if let Some(a) = &self.ambiguity {
            let _ = writeln!(s, "  unambiguous: {a}");
        }
        if self.candidates.len() > 1 {
            for (k, c) in self.candidates.iter().enumerate() {
                let _ = writeln!(
                    s,
                    "    candidate {}: p = {:.2}  E {:.d$}  N {:.d$}  heading {:.3}° = {:.4} gon  ({})",
                    k + 1,
                    c.probability,
                    c.easting,
                    c.northing,
                    c.heading_deg,
                    c.heading_gon,
                    c.source
                );
            }
        }
        if let Some(t) = &self.truth {
            let _ = write!(
                s,
                "  truth (simulation): E {:.d$}  N {:.d$}  heading {:.3}°; error of the answer: position {:.p$} {u}, heading {:+.3}°",
                t.easting,
                t.northing,
                t.heading_deg,
                t.position_error,
                t.heading_error_deg,
                p = d + 1
            );
            if t.nearest != 0 {
                let e = t.nearest_errors;
                let _ = write!(
                    s,
                    "; candidate {} is the true one (position {:.p$} {u}, heading {:+.3}°)",
                    t.nearest + 1,
                    (e[0] * e[0] + e[1] * e[1]).sqrt(),
                    e[2],
                    p = d + 1
                );
            }
            s.push('\n');
        }
        s
    }
}

/// A risk as a percentage with the digits it needs (0.10 %, 1.0 %, 12 %).
fn percent(r: f64) -> String {
    let p = 100.0 * r;
    if p < 1.0 {
        format!("{p:.2} %")
    } else if p < 10.0 {
        format!("{p:.1} %")
    } else {
        format!("{p:.0} %")
    }
}
