//! The readings against the plan at the answer: each one explained, short (something in front
//! of the wall the plan does not draw), long (through the wall: a door, glass, or a wrong
//! answer) or with no wall along it ([`ReadingFit`]), and, when too many are off the plan, the
//! words that say the room does not match it ([`Answer::mismatch`]).

use super::{Answer, Reading, ReadingFit, MISMATCH_MIN_READINGS, MISMATCH_SHARE, PRECISION_GATE};
use crate::world::planfile::PlanFrame;
use activesense_core::registration::precision::{WallInformation, WallLeverage};
use activesense_core::registration::{Measurement, Observations};
use activesense_core::stop::{
    LeverageVeto, MAX_WALL_LEVERAGE, VETO_WALL_HEADING_LEVERAGE, VETO_WALL_LEVERAGE,
};
use activesense_core::{FloorPlan, Pose2};

/// Compares every reading with the range the plan predicts from `pose` ([`ReadingFit`]) and,
/// when too many are not explained ([`MISMATCH_SHARE`], [`MISMATCH_MIN_READINGS`]), says in
/// words that the room does not match its plan.
pub(super) fn compare_with_plan(
    a: &mut Answer,
    plan: &FloorPlan,
    pose: &Pose2,
    readings: &[Measurement],
    frame: &PlanFrame,
) {
    use activesense_core::world::geometry::unit;
    for (r, m) in a.readings.iter_mut().zip(readings) {
        let dir = unit(pose.theta + m.bearing);
        let hit = plan.ray_cast(pose.translation(), dir);
        let wall_range = hit.map_or(f32::INFINITY, |h| h.range);
        if crate::world::site::through_plan_door(plan, pose.translation(), dir, wall_range)
            .is_some()
        {
            r.fit = ReadingFit::ThroughDoor;
            continue;
        }
        let Some(hit) = hit else {
            r.fit = ReadingFit::NoWall;
            continue;
        };
        r.expected = Some(frame.length_to_plan(hit.range as f64));
        r.wall = Some(hit.wall + 1);
        let residual = m.range - hit.range;
        r.fit = if residual.abs() <= PRECISION_GATE {
            ReadingFit::Explained
        } else if residual < 0.0 {
            ReadingFit::Short
        } else {
            ReadingFit::Long
        };
    }
    let off: Vec<&Reading> = a
        .readings
        .iter()
        .filter(|r| !matches!(r.fit, ReadingFit::Explained | ReadingFit::ThroughDoor))
        .collect();
    if off.len() < MISMATCH_MIN_READINGS
        || (off.len() as f64) < MISMATCH_SHARE * a.readings.len() as f64
    {
        return;
    }
    let walls = |fit: ReadingFit| {
        let mut w: Vec<usize> = off
            .iter()
            .filter(|r| r.fit == fit)
            .filter_map(|r| r.wall)
            .collect();
        w.sort_unstable();
        w.dedup();
        w
    };
    let named = |w: &[usize]| match w {
        [] => String::new(),
        [one] => format!(" near wall {one}"),
        _ => format!(
            " near walls {}",
            w.iter()
                .map(|w| w.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let count = |fit: ReadingFit| off.iter().filter(|r| r.fit == fit).count();
    let mut parts = Vec::new();
    if count(ReadingFit::Short) > 0 {
        parts.push(format!(
            "{} hit something in front of the plan's walls{}",
            count(ReadingFit::Short),
            named(&walls(ReadingFit::Short))
        ));
    }
    if count(ReadingFit::Long) > 0 {
        parts.push(format!(
            "{} read beyond the plan's walls{} (an open door, glass, or a wrong answer)",
            count(ReadingFit::Long),
            named(&walls(ReadingFit::Long))
        ));
    }
    if count(ReadingFit::NoWall) > 0 {
        parts.push(format!(
            "{} point where the plan has no wall",
            count(ReadingFit::NoWall)
        ));
    }
    a.mismatch = Some(format!(
        "the room does not match its plan: {} of {} readings are not on the plan ({})",
        off.len(),
        a.readings.len(),
        parts.join("; ")
    ));
}

/// Why the calibrated stop would not answer from this geometry, in words (the two rules of
/// `Pipeline::features_with` and its veto): a direction that rests on one wall's readings
/// alone (with the heading known or not: the stop holds that rule either way); with the
/// heading known, a wall whose offset from its drawn line would carry into the answer by
/// more than [`MAX_WALL_LEVERAGE`]; with it unknown and `leverage_veto` (the EDM-only
/// profile), the same with the heading free ([`LeverageVeto`]). `None` when none holds, or
/// with too few readings to tell (the precision says so already).
///
/// **Why.** Such an answer can agree with every reading and still sit centimetres off:
/// the room's walls are not exactly where the plan draws them (`docs/EVALUATION.md`, "The
/// wall leverage"). The surveyor is told which wall and what reading would settle it, not
/// only that no risk is available.
pub(super) fn wall_reliance(
    plan: &FloorPlan,
    obs: &Observations,
    pose: &Pose2,
    heading_known: bool,
    leverage_veto: bool,
) -> Option<String> {
    let alone = WallInformation::of(plan, obs, pose, PRECISION_GATE).walls_alone(heading_known);
    if alone == usize::MAX {
        return None;
    }
    if alone > 0 {
        return Some(
            "one direction of the answer rests on the readings of a single wall: were that wall a few cm off its drawn line, the answer would be off by as much, and no reading would show it; take a reading on another wall along that direction".to_string(),
        );
    }
    if !heading_known {
        return leverage_veto
            .then(|| vetoed_leverage(plan, obs, pose))
            .flatten();
    }
    let lever = WallLeverage::of(plan, obs, pose, PRECISION_GATE);
    let worst = lever.worst(true);
    if worst <= MAX_WALL_LEVERAGE {
        return None;
    }
    let (wall, shift) = (0..plan.len())
        .filter_map(|w| lever.shift(w, true).map(|(dx, dy, _)| (w, dx.hypot(dy))))
        .fold((0, 0.0f64), |b, c| if c.1 > b.1 { c } else { b });
    Some(format!(
        "the answer rests on wall {}'s drawn position: it moves {shift:.2} cm for every cm that wall stands off its line (the stop answers only below {MAX_WALL_LEVERAGE:.2}), and its neighbours' readings near the shared corners move with it; take a reading on a wall facing it",
        wall + 1
    ))
}

/// With the heading unknown on the EDM-only profile, the stop's veto
/// ([`LeverageVeto`]) in words: which wall's offset would carry into the answer, by how
/// much, and the reading that would settle it; `None` when it does not hold.
fn vetoed_leverage(plan: &FloorPlan, obs: &Observations, pose: &Pose2) -> Option<String> {
    let lever = WallLeverage::of(plan, obs, pose, PRECISION_GATE);
    if !LeverageVeto::of(&lever).vetoes() {
        return None;
    }
    // The wall whose offset carries furthest, by the bound it breaks most.
    let (wall, dx, dy, dt) = (0..plan.len())
        .filter_map(|w| lever.shift(w, false).map(|(dx, dy, dt)| (w, dx, dy, dt)))
        .max_by(|a, b| {
            let size = |&(_, dx, dy, dt): &(usize, f64, f64, f64)| {
                (dx.hypot(dy) / f64::from(VETO_WALL_LEVERAGE))
                    .max(dt.abs() / f64::from(VETO_WALL_HEADING_LEVERAGE))
            };
            size(a).total_cmp(&size(b))
        })?;
    Some(format!(
        "the answer leans on wall {}'s drawn position: for every cm that wall stands off its line it moves {:.2} cm and turns {:.3}° (the stop answers only below {VETO_WALL_LEVERAGE:.2} cm and {:.3}°), and no reading would show it; take a reading on a wall facing it",
        wall + 1,
        dx.hypot(dy),
        (dt.abs() * 0.01).to_degrees(),
        (f64::from(VETO_WALL_HEADING_LEVERAGE) * 0.01).to_degrees(),
    ))
}

#[cfg(test)]
mod tests {
    use super::super::{AnswerInput, ReadingFit};
    use super::*;
    use activesense_core::episode::{AgentKind, InstrumentProfile};
    use activesense_core::world::geometry::{rotate, unit, v2};
    use std::f32::consts::{FRAC_PI_2, PI};

    /// A reading that hits a column of the plan is explained by the plan, and names the
    /// column's wall; without the column the same reading would be short of the far wall.
    #[test]
    fn a_reading_on_a_column_is_explained() {
        let plan = FloorPlan::with_columns_and_doors(
            &[v2(-6.0, -4.0), v2(6.0, -4.0), v2(6.0, 4.0), v2(-6.0, 4.0)],
            &[&[v2(2.0, -0.5), v2(3.0, -0.5), v2(3.0, 0.5), v2(2.0, 0.5)]],
            &[],
            0.02,
        )
        .unwrap()
        .centered();
        let pose = Pose2::new(-2.0, 0.0, 0.4);
        // Scene bearings: the first looks along the model's +x, at the column.
        let bearings = [-0.4f32, 1.2, 2.3, 3.0, 4.1, 5.0];
        let readings: Vec<Measurement> = bearings
            .iter()
            .map(|&b| {
                let hit = plan
                    .ray_cast(pose.translation(), rotate(unit(b), pose.theta))
                    .unwrap();
                Measurement::new(b, hit.range)
            })
            .collect();
        let frame = PlanFrame::default();
        let a = Answer::new(&AnswerInput {
            label: "column".into(),
            plan: &plan,
            frame: &frame,
            pose: Some(pose),
            refined: true,
            readings: &readings,
            heading_known: false,
            symmetry_order: 1,
            stop_risk: Some(0.004),
            stop_tables: None,
            truth: Some(pose),
            hint: None,
            range_sigma: 0.01,
        });
        let on_column = &a.readings[0];
        assert_eq!(on_column.fit, ReadingFit::Explained, "{on_column:?}");
        // Walls are numbered from 1 in the answer; the column's are 5 to 8.
        assert!(on_column.wall.is_some_and(|w| w > 4), "{on_column:?}");
        // The column's face, not the far wall 8 m from it.
        assert!(readings[0].range < 4.0, "{:?}", readings[0]);
        assert!(a.readings.iter().all(|r| r.fit == ReadingFit::Explained));
        assert_eq!(a.mismatch, None);
        // The plain room would not explain it.
        let plain = crate::fixtures::rect(12.0, 8.0);
        let b = Answer::new(&AnswerInput {
            plan: &plain,
            ..AnswerInput {
                label: "rect".into(),
                plan: &plan,
                frame: &frame,
                pose: Some(pose),
                refined: true,
                readings: &readings,
                heading_known: false,
                symmetry_order: 2,
                stop_risk: Some(0.004),
                stop_tables: None,
                truth: Some(pose),
                hint: None,
                range_sigma: 0.01,
            }
        });
        assert_eq!(b.readings[0].fit, ReadingFit::Short);
    }

    /// A reading through a door of the plan (a corridor 3 m long beyond it) is neither
    /// explained nor held against the plan: two such readings do not make the room unlike
    /// its plan, where two as long through a plain wall do.
    #[test]
    fn readings_through_a_door_of_the_plan_are_not_held_against_it() {
        let outline = [v2(-6.0, -4.0), v2(6.0, -4.0), v2(6.0, 4.0), v2(-6.0, 4.0)];
        let door = (v2(6.0, -1.0), v2(6.0, 1.0));
        let plan = FloorPlan::with_columns_and_doors(&outline, &[], &[door], 0.02).unwrap();
        let plain = FloorPlan::new(&outline).unwrap();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let bearings = [-0.1f32, 0.1, 1.2, 2.3, 3.0, 4.1, 5.0];
        let readings: Vec<Measurement> = bearings
            .iter()
            .map(|&b| {
                let r = plain.ray_cast(pose.translation(), unit(b)).unwrap().range;
                // Through the door (x = 6, |y| < 1): the corridor's far wall 3 m beyond.
                let through = b.abs() < 0.15;
                Measurement::new(b, if through { r + 3.0 } else { r })
            })
            .collect();
        let frame = PlanFrame::default();
        let input = |plan| AnswerInput {
            label: "door".into(),
            plan,
            frame: &frame,
            pose: Some(pose),
            refined: true,
            readings: &readings,
            heading_known: false,
            symmetry_order: 1,
            stop_risk: Some(0.004),
            stop_tables: None,
            truth: Some(pose),
            hint: None,
            range_sigma: 0.01,
        };
        let a = Answer::new(&input(&plan));
        assert_eq!(a.readings[0].fit, ReadingFit::ThroughDoor);
        assert_eq!(a.readings[1].fit, ReadingFit::ThroughDoor);
        assert!(a.readings[2..]
            .iter()
            .all(|r| r.fit == ReadingFit::Explained));
        assert_eq!(a.mismatch, None);
        assert!(!a.to_text().contains("does not explain"), "{}", a.to_text());
        let b = Answer::new(&input(&plain));
        assert_eq!(b.readings[0].fit, ReadingFit::Long);
        assert!(b.mismatch.is_some());
    }

    /// The answer at (3, 0.3, 0) from exact readings of `plan` at `bearings`.
    fn answer_from(
        plan: &FloorPlan,
        bearings: &[f32],
        heading_known: bool,
        stop_risk: Option<f32>,
        stop_tables: Option<(AgentKind, InstrumentProfile, u8)>,
    ) -> Answer {
        let pose = Pose2::new(3.0, 0.3, 0.0);
        let readings: Vec<Measurement> = bearings
            .iter()
            .map(|&b| {
                let hit = plan.ray_cast(pose.translation(), unit(b)).unwrap();
                Measurement::new(b, hit.range)
            })
            .collect();
        let frame = PlanFrame::default();
        Answer::new(&AnswerInput {
            label: "walls".into(),
            plan,
            frame: &frame,
            pose: Some(pose),
            refined: true,
            readings: &readings,
            heading_known,
            symmetry_order: 1,
            stop_risk,
            stop_tables,
            truth: None,
            hint: None,
            range_sigma: 0.01,
        })
    }

    /// With the heading given, an answer whose geometry the stop does not answer says so in
    /// words: a direction fixed by one wall alone; a wall whose offset carries into the
    /// answer (the readings on it and on its neighbours near the shared corners); and once
    /// a reading on the facing wall checks it, nothing. Not with the heading unknown.
    #[test]
    fn an_answer_that_rests_on_one_wall_says_which_and_what_would_settle_it() {
        let answer = |plan: &FloorPlan, bearings: &[f32], heading_known: bool| {
            answer_from(plan, bearings, heading_known, None, None)
        };
        // x by the east wall alone (two readings), y by the north and south walls.
        let rect =
            FloorPlan::new(&[v2(-6.0, -4.0), v2(6.0, -4.0), v2(6.0, 4.0), v2(-6.0, 4.0)]).unwrap();
        let one = answer(&rect, &[0.0, 0.2, FRAC_PI_2, -FRAC_PI_2], true);
        let words = one.wall_reliance.as_deref().unwrap_or_default();
        assert!(words.contains("a single wall"), "{words}");
        let text = one.to_text();
        assert!(text.contains("RESTS ON ONE WALL"), "{text}");
        assert!(text.contains("the stop does not answer while"), "{text}");
        // The stop holds that rule with the heading unknown too.
        let unknown = answer(&rect, &[0.0, 0.2, 0.4, FRAC_PI_2, -FRAC_PI_2], false);
        let words = unknown.wall_reliance.as_deref().unwrap_or_default();
        assert!(words.contains("a single wall"), "{words}");
        // A room narrowing to the east: the slanting walls share their east corners with
        // the east wall (wall 2), so readings near those corners move with its offset.
        let narrowing =
            FloorPlan::new(&[v2(-6.0, -4.0), v2(6.0, -2.0), v2(6.0, 2.0), v2(-6.0, 4.0)]).unwrap();
        let lever = answer(&narrowing, &[0.0, -1.0, 1.0, -0.8], true);
        let words = lever.wall_reliance.as_deref().unwrap_or_default();
        assert!(
            words.contains("rests on wall 2's drawn position"),
            "{words}"
        );
        assert!(words.contains("a wall facing it"), "{words}");
        // The west wall, facing it, checks it.
        assert_eq!(
            answer(&narrowing, &[0.0, -1.0, 1.0, -0.8, PI], true).wall_reliance,
            None
        );
    }

    /// With the heading unknown on the EDM-only profile, an answer whose heading one
    /// wall's offset would turn past the stop's bound says so in words, names the wall and
    /// states no risk; with the paper's sensor or no stop tables it does not, and readings
    /// all round the room clear it.
    #[test]
    fn an_answer_past_the_leverage_veto_says_which_wall_on_the_edm_profile() {
        let rect =
            FloorPlan::new(&[v2(-6.0, -4.0), v2(6.0, -4.0), v2(6.0, 4.0), v2(-6.0, 4.0)]).unwrap();
        let answer = |bearings: &[f32], instrument: Option<InstrumentProfile>| {
            let tables = instrument.map(|i| (AgentKind::Learnt, i, 10));
            answer_from(&rect, bearings, false, Some(0.001), tables)
        };
        // Two readings on the east wall fix the heading: its offset turns the answer.
        let turned = [0.0, 0.3, 1.5, -1.5, PI];
        let edm = answer(&turned, Some(InstrumentProfile::Edm));
        let words = edm.wall_reliance.as_deref().unwrap_or_default();
        assert!(
            words.contains("leans on wall 2's drawn position"),
            "{words}"
        );
        assert!(words.contains("turns"), "{words}");
        assert_eq!(edm.risk, None);
        assert!(edm.to_text().contains("RESTS ON ONE WALL"));
        let scan = answer(&turned, Some(InstrumentProfile::EdmScan));
        assert_eq!(scan.wall_reliance, None);
        assert!(scan.risk.is_some());
        assert_eq!(answer(&turned, None).wall_reliance, None);
        // Readings all round the room: no wall carries far.
        let round = [0.0, 1.5, -1.5, PI, 2.5, -2.5];
        let edm = answer(&round, Some(InstrumentProfile::Edm));
        assert_eq!(edm.wall_reliance, None);
        assert!(edm.risk.is_some());
    }
}
