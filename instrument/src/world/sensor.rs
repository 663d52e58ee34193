//! Simulated sensors of the instrument (paper §3.1, §4.1): the EDM range sensor along the
//! current bearing and the 20-pixel topological scan.
//!
//! EDM model, in order: with probability `outlier_prob` the reading is an outlier, a range
//! drawn uniformly from `(0, max_range)` (a stray return: multipath, a person walking by);
//! otherwise the true first wall hit is returned with additive Gaussian noise
//! `N(0, sigma²)`, unless it lies beyond `max_range` or the incidence angle exceeds
//! `max_incidence`, in which case there is no return (`None`). Every parameter is recorded
//! with every result (it is serialised into trajectories and result files).

use crate::world::site::{Site, SiteHit, SiteLevel};
use activesense_core::episode::{SCAN_FOV, SCAN_PIXELS};
use activesense_core::world::geometry::{unit, Vec2};
use activesense_core::FloorPlan;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// EDM and scan parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorModel {
    /// Standard deviation of the range noise (m). Default 0.01.
    pub sigma: f32,
    /// Probability that a measurement is an outlier. Default 0.05.
    pub outlier_prob: f32,
    /// No return beyond this range (m). Default 50.
    pub max_range: f32,
    /// No return when the ray meets the wall more obliquely than this (radians from the
    /// normal). Default 75°.
    pub max_incidence: f32,
    /// Probability that a scan pixel with a visible junction reads 0.
    pub scan_false_negative: f32,
    /// Probability that an empty scan pixel reads 1.
    pub scan_false_positive: f32,
    /// How far the room the EDM hits departs from its plan ([`SiteLevel`], `--site`).
    #[serde(default, skip_serializing_if = "SiteLevel::is_plan")]
    pub site: SiteLevel,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel {
            sigma: 0.01,
            outlier_prob: 0.05,
            max_range: 50.0,
            max_incidence: 75f32.to_radians(),
            scan_false_negative: 0.0,
            scan_false_positive: 0.0,
            site: SiteLevel::Plan,
        }
    }
}

/// Where a range reading came from (kept in trajectories for inspection; the device never
/// sees it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RangeKind {
    /// A true wall hit with Gaussian noise.
    Hit,
    /// A uniform random outlier.
    Outlier,
    /// Beyond maximum range or incidence, or the ray escaped (or met glass).
    NoReturn,
    /// Something the plan does not draw, in front of the wall: furniture, a column, an
    /// obstacle, a person ([`Site`]).
    Clutter,
    /// Through an open door, from the space behind the wall ([`Site`]).
    Behind,
}

impl SensorModel {
    /// Checks that every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), String> {
        let finite = [
            self.sigma,
            self.outlier_prob,
            self.max_range,
            self.max_incidence,
        ];
        if finite.iter().any(|x| !x.is_finite()) {
            return Err("sensor parameters must be finite".into());
        }
        if self.sigma < 0.0 {
            return Err(format!("sigma must be >= 0 (got {})", self.sigma));
        }
        for (name, p) in [
            ("outlier probability", self.outlier_prob),
            ("scan false-negative rate", self.scan_false_negative),
            ("scan false-positive rate", self.scan_false_positive),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(format!("{name} must be in [0, 1] (got {p})"));
            }
        }
        if self.max_range <= 0.0 {
            return Err("max range must be positive".into());
        }
        if !(0.0..=std::f32::consts::FRAC_PI_2).contains(&self.max_incidence) {
            return Err("max incidence must be in [0, 90°]".into());
        }
        Ok(())
    }

    /// The world stream's three draws of every reading: the outlier decision, its range and
    /// the Gaussian noise, always all three and first, so the random stream does not depend
    /// on the geometry (keeps episodes comparable across sensor settings and sites). `Err`
    /// is the outlier reading; `Ok` the noise to add to a hit.
    fn outlier_or_noise<R: Rng>(&self, rng: &mut R) -> Result<f32, (Option<f32>, RangeKind)> {
        let outlier = rng.gen_bool(self.outlier_prob as f64);
        let u: f32 = rng.gen_range(0.0..1.0);
        let noise = self.sigma * standard_normal(rng);
        if outlier {
            Err((Some(u * self.max_range), RangeKind::Outlier))
        } else {
            Ok(noise)
        }
    }

    /// One EDM reading from `origin` along the model-frame direction `angle`.
    pub fn measure<R: Rng>(
        &self,
        plan: &FloorPlan,
        origin: Vec2,
        angle: f32,
        rng: &mut R,
    ) -> (Option<f32>, RangeKind) {
        let noise = match self.outlier_or_noise(rng) {
            Ok(noise) => noise,
            Err(outlier) => return outlier,
        };
        let hit = plan.ray_cast(origin, unit(angle));
        // Through a door of the plan, the beam meets the wall behind it.
        let wall_range = hit.map_or(f32::INFINITY, |h| h.range);
        if let Some((range, incidence)) =
            crate::world::site::through_plan_door(plan, origin, unit(angle), wall_range)
        {
            return if range <= self.max_range && incidence <= self.max_incidence {
                (Some((range + noise).max(0.0)), RangeKind::Behind)
            } else {
                (None, RangeKind::NoReturn)
            };
        }
        match hit {
            Some(hit) if hit.range <= self.max_range && hit.incidence <= self.max_incidence => {
                (Some((hit.range + noise).max(0.0)), RangeKind::Hit)
            }
            _ => (None, RangeKind::NoReturn),
        }
    }

    /// One EDM reading on the site (what the beam meets as built, [`Site::cast`]). The
    /// world's stream `rng` makes the same three draws as [`SensorModel::measure`], so a
    /// plain site reads exactly what the plan reads; the site's own stream decides people.
    pub fn measure_in<R: Rng>(
        &self,
        site: &Site,
        origin: Vec2,
        angle: f32,
        rng: &mut R,
        site_rng: &mut R,
    ) -> (Option<f32>, RangeKind) {
        let noise = match self.outlier_or_noise(rng) {
            Ok(noise) => noise,
            Err(outlier) => return outlier,
        };
        let person = if site.people > 0.0 {
            (site_rng.gen_range(0.0..1.0), site_rng.gen_range(0.0..1.0))
        } else {
            (1.0, 0.0)
        };
        let (range, incidence, kind) = match site.cast(origin, unit(angle), person) {
            SiteHit::Wall { range, incidence } => (range, incidence, RangeKind::Hit),
            SiteHit::Clutter { range, incidence } => (range, incidence, RangeKind::Clutter),
            SiteHit::Behind { range, incidence } => (range, incidence, RangeKind::Behind),
            SiteHit::Nothing => return (None, RangeKind::NoReturn),
        };
        if range <= self.max_range && incidence <= self.max_incidence {
            (Some((range + noise).max(0.0)), kind)
        } else {
            (None, RangeKind::NoReturn)
        }
    }

    /// One topological scan centred on the model-frame direction `angle`.
    pub fn scan<R: Rng>(
        &self,
        plan: &FloorPlan,
        origin: Vec2,
        angle: f32,
        rng: &mut R,
    ) -> [bool; SCAN_PIXELS] {
        let mut px: [bool; SCAN_PIXELS] = plan.topological_scan(origin, angle, SCAN_FOV);
        if self.scan_false_negative > 0.0 || self.scan_false_positive > 0.0 {
            for p in px.iter_mut() {
                let flip = if *p {
                    rng.gen_bool(self.scan_false_negative as f64)
                } else {
                    rng.gen_bool(self.scan_false_positive as f64)
                };
                *p ^= flip;
            }
        }
        px
    }
}

/// A standard normal draw by Box–Muller through libm (platform-independent bits; rand_distr
/// would use the platform's `exp`/`ln`).
pub fn standard_normal<R: Rng>(rng: &mut R) -> f32 {
    use activesense_core::world::math::{cos, ln, sqrt, TAU};
    // u1 in (0, 1]: never ln(0).
    let u1 = 1.0 - rng.gen_range(0.0f32..1.0);
    let u2: f32 = rng.gen_range(0.0f32..1.0);
    sqrt(-2.0 * ln(u1)) * cos(TAU * u2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use activesense_core::world::geometry::v2;
    use rand::SeedableRng;
    use rand_pcg::Pcg32;

    fn square() -> FloorPlan {
        crate::fixtures::rect(10.0, 10.0)
    }

    #[test]
    fn noise_statistics() {
        let s = SensorModel {
            outlier_prob: 0.0,
            ..Default::default()
        };
        let mut rng = Pcg32::seed_from_u64(1);
        let n = 20_000;
        let errs: Vec<f32> = (0..n)
            .map(|_| s.measure(&square(), v2(0.0, 0.0), 0.0, &mut rng).0.unwrap() - 5.0)
            .collect();
        let mean = errs.iter().sum::<f32>() / n as f32;
        let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f32>() / n as f32).sqrt();
        assert!(mean.abs() < 0.0005, "{mean}");
        assert!((sd - 0.01).abs() < 0.0005, "{sd}");
    }

    #[test]
    fn outlier_rate_and_no_return() {
        let s = SensorModel {
            outlier_prob: 0.3,
            ..Default::default()
        };
        let mut rng = Pcg32::seed_from_u64(2);
        let n = 20_000;
        let outliers = (0..n)
            .filter(|_| s.measure(&square(), v2(0.0, 0.0), 0.0, &mut rng).1 == RangeKind::Outlier)
            .count();
        assert!((outliers as f32 / n as f32 - 0.3).abs() < 0.015);
        // 80° from the normal of the right wall: beyond the 75° limit -> no return.
        let s = SensorModel {
            outlier_prob: 0.0,
            ..Default::default()
        };
        let (r, k) = s.measure(&square(), v2(4.9, 0.0), 80f32.to_radians(), &mut rng);
        assert_eq!((r, k), (None, RangeKind::NoReturn));
        let s = SensorModel {
            outlier_prob: 0.0,
            max_range: 4.0,
            ..Default::default()
        };
        assert_eq!(
            s.measure(&square(), v2(0.0, 0.0), 0.0, &mut rng).1,
            RangeKind::NoReturn
        );
    }

    #[test]
    fn validation() {
        assert!(SensorModel::default().validate().is_ok());
        assert!(SensorModel {
            sigma: f32::NAN,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(SensorModel {
            outlier_prob: 1.5,
            ..Default::default()
        }
        .validate()
        .is_err());
    }
}
