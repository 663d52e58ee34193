//! The simulated world (paper §3, §4.2): a generated floor-plan, the agent placed about the
//! room's visual centre, and a simulated instrument that executes actions and answers with
//! observations.
//!
//! Placement: the visual centre is the pole of inaccessibility (quad-tree algorithm, the
//! `polylabel` crate); the agent is drawn uniformly from the disc around it whose radius is
//! the distance from the centre to the nearest wall, and its initial heading uniformly from
//! [0, 2π). The ground truth is the [`AgentPose`](activesense_core::Pose2) `(a, h)` in the
//! model frame (see `docs/ARCHITECTURE.md`, "Frames").
//!
//! The submodules make the rooms and the sensors: [`plans`] is the seeded floor-plan
//! generator (training and test seed ranges), [`planfile`] reads the user's own plans (JSON,
//! GeoJSON, DXF), and [`sensor`] simulates the EDM and the topological scan.

pub mod planfile;
pub mod plans;
pub mod sensor;
pub mod site;

use crate::world::sensor::{RangeKind, SensorModel};
use crate::world::site::Site;
use activesense_core::episode::Action;
use activesense_core::episode::{EpisodeConfig, EpisodeState, Observation};
use activesense_core::world::geometry::{v2, Vec2};
use activesense_core::world::math::{cos, sin, sqrt, TAU};
use activesense_core::{FloorPlan, Pose2};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg32;
use serde::{Deserialize, Serialize};

/// Visual centre and the radius of the placement disc.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Pole of inaccessibility (model frame).
    pub visual_centre: [f32; 2],
    /// Distance from the visual centre to the nearest wall (m).
    pub radius: f32,
}

/// Computes the visual centre of `plan` (polylabel, 1 cm tolerance) and the placement radius.
pub fn placement(plan: &FloorPlan) -> Placement {
    // The outline with the columns as holes: the visual centre is never inside a column.
    let ring = |r: usize| -> geo_types::LineString<f64> {
        plan.ring(r)
            .map(|i| {
                let p = plan.vertex(i);
                geo_types::coord! { x: p.x as f64, y: p.y as f64 }
            })
            .collect::<Vec<_>>()
            .into()
    };
    let holes = (1..plan.ring_count()).map(ring).collect();
    let poly = geo_types::Polygon::new(ring(0), holes);
    let c = polylabel::polylabel(&poly, &0.01)
        .map(|p| v2(p.x() as f32, p.y() as f32))
        .unwrap_or_else(|_| plan.perimeter_centroid());
    let radius = plan.nearest_point(c).distance;
    Placement {
        visual_centre: [c.x, c.y],
        radius,
    }
}

/// The simulated instrument in its room.
#[derive(Clone, Debug)]
pub struct SimWorld {
    plan: FloorPlan,
    truth: Pose2,
    placement: Placement,
    sensor: SensorModel,
    state: EpisodeState,
    rng: Pcg32,
    /// What the EDM hits ([`site`]); the plan itself unless `sensor.site` says otherwise.
    site: Site,
    /// The site's own stream (people in the beam), apart from the world's.
    site_rng: Pcg32,
}

/// What the world knows about one step that the instrument does not report (for the
/// trajectory log).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepTruth {
    /// How the range reading arose (measurements only).
    pub range_kind: Option<RangeKind>,
    /// Model-frame direction of the beam after the action (rad).
    pub world_bearing: f32,
}

impl SimWorld {
    /// Places the agent in `plan` (model frame) using `seed` and prepares an episode.
    pub fn new(plan: FloorPlan, sensor: SensorModel, config: EpisodeConfig, seed: u64) -> Self {
        let mut rng = Pcg32::seed_from_u64(seed);
        let placement = placement(&plan);
        let c = v2(placement.visual_centre[0], placement.visual_centre[1]);
        // Uniform in the disc: radius ∝ sqrt(u). Points exactly on a wall are redrawn.
        let mut a = c;
        for _ in 0..100 {
            let r = placement.radius * sqrt(rng.gen_range(0.0f32..1.0));
            let phi = rng.gen_range(0.0..TAU);
            let p = c + v2(r * cos(phi), r * sin(phi));
            if plan.contains(p) && plan.nearest_point(p).distance > 0.05 {
                a = p;
                break;
            }
        }
        let h = rng.gen_range(0.0..TAU);
        let site = if sensor.site.is_plan() {
            Site::plain(&plan)
        } else {
            Site::generate(&plan, a, sensor.site, seed)
        };
        SimWorld {
            site,
            site_rng: Pcg32::seed_from_u64(seed ^ 0x0070_656f_706c_6521),
            plan,
            truth: Pose2::new(a.x, a.y, h),
            placement,
            sensor,
            state: EpisodeState::new(config),
            rng,
        }
    }

    /// The ground-truth AgentPose (scene→model).
    pub fn truth(&self) -> Pose2 {
        self.truth
    }

    /// The model (the room).
    pub fn plan(&self) -> &FloorPlan {
        &self.plan
    }

    /// The room as it stands (what the EDM hits).
    pub fn site(&self) -> &Site {
        &self.site
    }

    /// Visual centre and placement radius.
    pub fn placement(&self) -> Placement {
        self.placement
    }

    /// The sensor model.
    pub fn sensor(&self) -> &SensorModel {
        &self.sensor
    }

    /// Model-frame direction of the beam at the current encoder bearing.
    pub fn world_bearing(&self) -> f32 {
        self.truth.theta + self.state.bearing()
    }

    /// Agent position in the model frame.
    pub fn position(&self) -> Vec2 {
        self.truth.translation()
    }

    /// The scan at the current bearing (also sent at episode start).
    pub fn scan(&mut self) -> u32 {
        // An instrument without a camera sees no scan, and draws nothing for one.
        if !self.state.config.instrument.has_scan() {
            return 0;
        }
        let px = self.sensor.scan(
            &self.plan,
            self.position(),
            self.world_bearing(),
            &mut self.rng,
        );
        Observation::pack_scan(&px)
    }

    /// One EDM reading along the model-frame direction `angle`, from the world's random
    /// stream, without moving the encoder (the GeoCOM simulator's telescope can stand
    /// between encoder steps when a client positions it there).
    pub fn measure_along(&mut self, angle: f32) -> (Option<f32>, RangeKind) {
        let origin = self.position();
        self.sensor
            .measure_in(&self.site, origin, angle, &mut self.rng, &mut self.site_rng)
    }

    /// Executes one action on the instrument and returns its observation.
    pub fn act(&mut self, action: Action) -> (Observation, StepTruth) {
        self.state.apply(action);
        let (range, kind) = if action == Action::Measure {
            let (r, k) = self.measure_along(self.world_bearing());
            (r, Some(k))
        } else {
            (None, None)
        };
        let scan = self.scan();
        (
            Observation { range, scan },
            StepTruth {
                range_kind: kind,
                world_bearing: activesense_core::world::math::wrap_angle(self.world_bearing()),
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::plans;

    #[test]
    fn agent_inside_disc_and_room() {
        for seed in plans::TEST_SEEDS.take(200) {
            let plan = plans::generate(seed);
            let w = SimWorld::new(
                plan.clone(),
                SensorModel::default(),
                EpisodeConfig::default(),
                seed as u64,
            );
            let p = w.placement();
            let c = v2(p.visual_centre[0], p.visual_centre[1]);
            assert!(plan.contains(c), "seed {seed}: visual centre outside");
            assert!(p.radius > 0.5, "seed {seed}: radius {}", p.radius);
            let a = w.position();
            assert!(plan.contains(a), "seed {seed}");
            assert!((a - c).norm() <= p.radius + 1e-4);
            assert!((0.0..TAU).contains(&w.truth().theta.rem_euclid(TAU)));
        }
    }

    #[test]
    fn square_visual_centre_is_the_middle() {
        let sq = crate::fixtures::rect(8.0, 8.0);
        let p = placement(&sq);
        assert!(p.visual_centre[0].abs() < 0.02 && p.visual_centre[1].abs() < 0.02);
        assert!((p.radius - 4.0).abs() < 0.02);
    }
}
