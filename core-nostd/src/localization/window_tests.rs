//! Unit tests of the coarse-to-fine argmax (`GhtLocalizer::refine_argmax`): the fine headings at
//! `K > 1`, the unquantised window votes at `K = 1`, and that both are incremental and exact.

use super::tests::{boxed, measure, uniform};
use super::*;
use crate::fixtures::l_room_8x6;
use crate::world::geometry::v2;
use crate::world::math::TAU;
use crate::Pose2;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;

extern crate std;
use std::vec::Vec;

/// Coarse-to-fine argmax: on poses whose heading lies between two tracked headings and
/// whose position is random, the fine argmax is right at least as often as the coarse one
/// and strictly more often over the set (noise-free ranges, K = 10). It stays within one
/// cell and bin of the coarse argmax, and an update forgets it.
#[test]
fn fine_argmax_corrects_heading_quantisation() {
    let p = l_room_8x6();
    let cfg = LocalizerConfig::default();
    let mut l = boxed(&p, &cfg);
    let mut rng = Pcg32::seed_from_u64(12);
    let (mut coarse_right, mut fine_right, mut tried) = (0, 0, 0);
    while tried < 40 {
        let a = v2(
            -3.5 + 7.0 * uniform(&mut rng),
            -2.5 + 5.0 * uniform(&mut rng),
        );
        if !p.contains(a) {
            continue;
        }
        // Midway between two of the four tracked headings of a random bin (9° apart).
        let bin = (rng.next_u32() % 10) as f32;
        let theta = bin * 36f32.to_radians();
        let truth = Pose2::new(a.x, a.y, theta);
        let Some(Played {
            readings,
            coarse_hit,
            fine_hit,
        }) = coarse_and_fine(&mut l, &p, &truth, 8)
        else {
            continue;
        };
        tried += 1;
        coarse_right += coarse_hit as u32;
        fine_right += fine_hit as u32;
        // A further update forgets the fine argmax until it is refined again.
        l.update(readings[0].0, readings[0].1).unwrap();
        assert_eq!(l.argmax(), l.coarse_argmax());
    }
    assert!(
        fine_right > coarse_right,
        "fine {fine_right} vs coarse {coarse_right} of 40"
    );
}

/// With the heading known, truths a few millimetres inside a cell's edge: the accumulator's
/// quantised votes often tie the two cells, and the coarse argmax then takes the first;
/// the window's unquantised votes take the cell nearer the truth more often.
#[test]
fn known_heading_window_argmax_takes_the_cell_near_an_edge() {
    let p = l_room_8x6();
    let heading = 0.3;
    let mut l = boxed(&p, &LocalizerConfig::known_heading(heading));
    let mut rng = Pcg32::seed_from_u64(5);
    let (mut coarse_right, mut fine_right, mut tried) = (0, 0, 0);
    while tried < 60 {
        let g = *l.grid();
        let (ix, iy) = (rng.next_u32() % g.nx as u32, rng.next_u32() % g.ny as u32);
        let c = g.cell_centre(ix as usize, iy as usize);
        // 2 to 10 mm inside one of the cell's four edges, anywhere along it.
        let inside = 0.002 + 0.008 * uniform(&mut rng);
        let along = uniform(&mut rng) - 0.5;
        let side = if rng.next_u32() % 2 == 0 { 1.0 } else { -1.0 };
        let a = if rng.next_u32() % 2 == 0 {
            v2(
                c.x + side * (0.5 * g.cell[0] - inside),
                c.y + along * g.cell[1],
            )
        } else {
            v2(
                c.x + along * g.cell[0],
                c.y + side * (0.5 * g.cell[1] - inside),
            )
        };
        if !p.contains(a) || !p.contains(c) {
            continue;
        }
        let truth = Pose2::new(a.x, a.y, heading);
        let Some(Played {
            coarse_hit,
            fine_hit,
            ..
        }) = coarse_and_fine(&mut l, &p, &truth, 12)
        else {
            continue;
        };
        tried += 1;
        coarse_right += coarse_hit as u32;
        fine_right += fine_hit as u32;
    }
    assert!(
        fine_right > coarse_right,
        "fine {fine_right} vs coarse {coarse_right} of 60"
    );
}

/// The incremental, windowed coarse-to-fine argmax (refined after every reading, as the
/// pipeline does) picks the same cell as the full re-vote of every reading, at every step,
/// outliers included.
#[test]
fn fine_argmax_is_incremental_and_exact() {
    fine_argmax_is_incremental_and_exact_for(None);
}

/// The same with the heading known (`K = 1`, the window's unquantised votes).
#[test]
fn known_heading_window_argmax_is_incremental_and_exact() {
    fine_argmax_is_incremental_and_exact_for(Some(0.3));
}

/// [`fine_argmax_is_incremental_and_exact`] with `known_heading`: `K = 1` at that heading,
/// else the default `K = 10` with the truth's heading drawn.
fn fine_argmax_is_incremental_and_exact_for(known_heading: Option<f32>) {
    let p = l_room_8x6();
    let cfg = known_heading.map_or(LocalizerConfig::default(), LocalizerConfig::known_heading);
    let mut l = boxed(&p, &cfg);
    let mut reference = boxed(&p, &cfg);
    let mut rng = Pcg32::seed_from_u64(77);
    let (mut compared, mut episodes) = (0, 0);
    while episodes < 12 {
        let a = v2(
            -3.5 + 7.0 * uniform(&mut rng),
            -2.5 + 5.0 * uniform(&mut rng),
        );
        if !p.contains(a) {
            continue;
        }
        episodes += 1;
        let heading = known_heading.unwrap_or_else(|| TAU * uniform(&mut rng));
        let truth = Pose2::new(a.x, a.y, heading);
        l.clear();
        reference.clear();
        let mut readings: Vec<(f32, f32)> = Vec::new();
        let mut k = 0;
        while readings.len() < 14 && k < 54 * 5 {
            if let Some((b, r)) = measure(&p, &truth, k) {
                // Every fifth reading an outlier.
                let r = if readings.len() % 5 == 3 { 0.5 * r } else { r };
                l.update(b, r).unwrap();
                reference.update(b, r).unwrap();
                readings.push((b, r));
                l.refine_argmax(readings.iter().copied());
                reference.refine_argmax_reference(readings.iter().copied());
                assert_eq!(
                    l.argmax(),
                    reference.argmax(),
                    "after {} readings",
                    readings.len()
                );
                compared += 1;
            }
            k += 11;
        }
    }
    assert!(compared > 100, "{compared}");
}

/// From a cleared `l`: `n` noise-free readings of `truth` every 7 bearing steps (`None` when
/// the room returns fewer), then whether the coarse and the fine argmax are a coarse success;
/// the fine argmax stays within one cell and bin of the coarse one.
fn coarse_and_fine(
    l: &mut GhtLocalizer,
    p: &crate::FloorPlan,
    truth: &Pose2,
    n: usize,
) -> Option<Played> {
    l.clear();
    let mut readings: Vec<(f32, f32)> = Vec::new();
    let mut k = 0;
    while readings.len() < n && k < 54 * 5 {
        if let Some((b, r)) = measure(p, truth, k) {
            l.update(b, r).unwrap();
            readings.push((b, r));
        }
        k += 7;
    }
    if readings.len() < n {
        return None;
    }
    let coarse = l.coarse_argmax().unwrap();
    l.refine_argmax(readings.iter().copied());
    let fine = l.argmax().unwrap();
    assert!(l.grid().near(coarse, fine, 1), "{coarse:?} {fine:?}");
    Some(Played {
        coarse_hit: l.grid().coarse_success(coarse, truth, 1),
        fine_hit: l.coarse_success(truth, 1),
        readings,
    })
}

/// The readings [`coarse_and_fine`] played, and whether each argmax was a coarse success.
struct Played {
    readings: Vec<(f32, f32)>,
    coarse_hit: bool,
    fine_hit: bool,
}
