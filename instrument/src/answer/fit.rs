//! The readings against the plan at the answer: each one explained, short (something in front
//! of the wall the plan does not draw), long (through the wall: a door, glass, or a wrong
//! answer) or with no wall along it ([`ReadingFit`]), and, when too many are off the plan, the
//! words that say the room does not match it ([`Answer::mismatch`]).

use super::{Answer, Reading, ReadingFit, MISMATCH_MIN_READINGS, MISMATCH_SHARE, PRECISION_GATE};
use crate::world::planfile::PlanFrame;
use activesense_core::registration::Measurement;
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
        let hit = plan.ray_cast(pose.translation(), unit(pose.theta + m.bearing));
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
        .filter(|r| r.fit != ReadingFit::Explained)
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
