//! Unit tests of the GHT localizer on hand-written rooms.

use super::*;
use crate::fixtures::{centred, centred_rect, l_room_8x6};
use crate::world::geometry::{length, rotate, unit, v2};
use crate::world::math::{cos, ln, sqrt, TAU};
use crate::{FloorPlan, Pose2};
use core::f32::consts::PI;
use heapless::Vec as HVec;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;

extern crate std;
use std::boxed::Box;
use std::vec::Vec;

/// The firmware keeps the localizer in a `static`: this must compile.
static _IN_PLACE: GhtLocalizer = GhtLocalizer::new_empty();

fn odd_room() -> FloorPlan {
    centred(&[(0., 0.), (7., 0.), (9., 4.), (5., 7.), (1., 6.), (-1., 3.)])
}

fn t_room() -> FloorPlan {
    centred(&[
        (0., 0.),
        (3., 0.),
        (3., 4.),
        (7., 4.),
        (7., 7.),
        (-3., 7.),
        (-3., 4.),
        (0., 4.),
    ])
}

pub(super) fn boxed(p: &FloorPlan, cfg: &LocalizerConfig) -> Box<GhtLocalizer> {
    let mut l = Box::new(GhtLocalizer::new_empty());
    l.reset(p, cfg).unwrap();
    l
}

/// Noise-free range at encoder bearing index `k` (54 steps), `None` for a no-return
/// (incidence beyond 70°).
pub(super) fn measure(p: &FloorPlan, truth: &Pose2, k: i32) -> Option<(f32, f32)> {
    let beta = k as f32 * TAU / 54.0;
    let hit = p.ray_cast(truth.translation(), unit(truth.theta + beta))?;
    (hit.incidence <= 70f32.to_radians()).then_some((beta, hit.range))
}

/// Feeds `n` returned measurements at bearings 0, 5, 10, … (mod 54) steps.
fn feed(l: &mut GhtLocalizer, p: &FloorPlan, truth: &Pose2, n: usize) {
    let mut done = 0;
    let mut k = 0;
    while done < n && k < 54 * 5 {
        if let Some((b, r)) = measure(p, truth, k) {
            l.update(b, r).unwrap();
            done += 1;
        }
        k += 5;
    }
    assert_eq!(done, n);
}

fn gauss(rng: &mut Pcg32) -> f32 {
    let u1 = ((rng.next_u32() >> 8) as f32 + 0.5) / 16_777_216.0;
    let u2 = (rng.next_u32() >> 8) as f32 / 16_777_216.0;
    sqrt(-2.0 * ln(u1)) * cos(TAU * u2)
}

pub(super) fn uniform(rng: &mut Pcg32) -> f32 {
    (rng.next_u32() >> 8) as f32 / 16_777_216.0
}

#[test]
fn state_fits_48_kib() {
    let s = core::mem::size_of::<GhtLocalizer>();
    assert!(s <= 48 * 1024, "{s} bytes");
}

#[test]
fn rebase_keeps_weights_monotone_over_long_episodes() {
    // 60 exact measurements: far more than a u8 slot holds without rebasing.
    let p = l_room_8x6();
    let truth = Pose2::new(-1.2, -0.6, 0.4);
    let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
    let mut prev: Vec<f32> = l.weights().collect();
    let mut n = 0;
    for k in 0..200 {
        if n == 60 {
            break;
        }
        let Some((b, r)) = measure(&p, &truth, k % 54) else {
            continue;
        };
        l.update(b, r).unwrap();
        n += 1;
        let now: Vec<f32> = l.weights().collect();
        assert!(now.iter().zip(&prev).all(|(a, b)| a >= b));
        prev = now;
    }
    assert_eq!(n, 60);
    let c = l.argmax().unwrap();
    // the peak has about one measurement of evidence per exact reading
    assert!(
        l.weight(l.grid().index(c)) > 50.0,
        "{}",
        l.weight(l.grid().index(c))
    );
    assert!(l.coarse_success_within(&truth, 1, 1));
    assert!(l.entropy().is_finite() && l.peak_mass(1) > 0.5);
}

#[test]
fn rtable_discretises_perimeter() {
    let p = centred_rect(9.0, 5.0);
    let mut t = RTable::new_empty();
    t.rebuild(&p, 0.25).unwrap();
    // 9 m walls -> 36 points, 5 m walls -> 20 points
    assert_eq!(t.len(), 2 * 36 + 2 * 20);
    for q in t.points() {
        let m = v2(q.m[0], q.m[1]);
        let n = v2(q.n[0], q.n[1]);
        assert!((length(n) - 1.0).abs() < 1e-5);
        // the point is on the outline and the normal points out of the room
        assert!(p.nearest_point(m).distance < 1e-4);
        assert!(!p.contains(m + n * 0.05) && p.contains(m - n * 0.05));
    }
    assert!(matches!(
        t.rebuild(&p, 0.01),
        Err(LocError::PlanTooLarge { needed: 2800, .. })
    ));
}

#[test]
fn typed_errors() {
    let mut l = Box::new(GhtLocalizer::new_empty());
    assert_eq!(l.update(0.0, 1.0), Err(LocError::NotReady));
    assert_eq!(l.stage(0.0, 1.0).err(), Some(LocError::NotReady));
    let p = l_room_8x6();
    let bad = LocalizerConfig {
        nx: 31,
        ..LocalizerConfig::DEFAULT
    };
    assert_eq!(
        l.reset(&p, &bad),
        Err(LocError::BadConfig(ConfigError::GridSize))
    );
    let bad = LocalizerConfig {
        rot_bins: 11,
        ..LocalizerConfig::DEFAULT
    };
    assert_eq!(
        l.reset(&p, &bad),
        Err(LocError::BadConfig(ConfigError::RotBins))
    );
    let bad = LocalizerConfig {
        max_incidence: 2.0,
        ..LocalizerConfig::DEFAULT
    };
    assert_eq!(
        l.reset(&p, &bad),
        Err(LocError::BadConfig(ConfigError::Incidence))
    );
    let tight = LocalizerConfig {
        perimeter_spacing: 0.02,
        ..LocalizerConfig::DEFAULT
    };
    assert!(matches!(
        l.reset(&p, &tight),
        Err(LocError::PlanTooLarge { .. })
    ));
    assert!(!l.is_ready());
    assert_eq!(
        l.reset(&p.translated(v2(3.0, 0.0)), &LocalizerConfig::DEFAULT),
        Err(LocError::PlanNotCentred)
    );
    l.reset(&p, &LocalizerConfig::DEFAULT).unwrap();
    assert_eq!(l.update(0.0, f32::NAN), Err(LocError::BadMeasurement));
    assert_eq!(l.update(0.0, -1.0), Err(LocError::BadMeasurement));
    assert_eq!(l.update(f32::INFINITY, 1.0), Err(LocError::BadMeasurement));
    // auto spacing fits a large plan into the fixed table
    let big = centred(&[(0., 0.), (120., 0.), (120., 90.), (0., 90.)]);
    l.reset(&big, &LocalizerConfig::DEFAULT).unwrap();
    assert!(l.rtable().len() <= MAX_RTABLE_POINTS);
}

#[test]
fn uniform_before_votes() {
    let l = boxed(&l_room_8x6(), &LocalizerConfig::DEFAULT);
    let n = l.interior_cells() * 10;
    assert!((l.entropy() - ln(n as f32)).abs() < 1e-4);
    assert_eq!(l.argmax(), None);
    let mut buf = std::vec![0.0f32; l.grid().len()];
    assert_eq!(l.pmf_into(&mut buf).unwrap(), 9000);
    let s: f32 = buf.iter().sum();
    assert!((s - 1.0).abs() < 1e-3);
}

fn asymmetric_cases() -> Vec<(FloorPlan, Pose2)> {
    std::vec![
        (l_room_8x6(), Pose2::new(-1.1, -0.5, 0.4)),
        (l_room_8x6(), Pose2::new(-1.0, 1.1, 2.9)),
        (odd_room(), Pose2::new(0.6, 0.3, -1.3)),
        (odd_room(), Pose2::new(-1.0, -0.42, 1.0)),
        (t_room(), Pose2::new(0.3, 0.93, 0.9)),
        (t_room(), Pose2::new(-3.0, 1.43, -2.2)),
    ]
}

#[test]
fn noise_free_true_cell_is_argmax_known_heading() {
    let mut exact = 0;
    for (p, truth) in asymmetric_cases() {
        let mut l = boxed(&p, &LocalizerConfig::known_heading(truth.theta));
        assert!(p.contains(truth.translation()));
        feed(&mut l, &p, &truth, 8);
        let want = l.grid().cell_of_pose(&truth).unwrap();
        let got = l.argmax().unwrap();
        assert!(l.coarse_success_within(&truth, 1, 1));
        if clear_of_cell_edges(l.grid(), &truth) {
            assert_eq!(got, want, "truth {truth:?}");
            exact += 1;
        }
    }
    assert!(exact >= 4, "only {exact} poses were clear of cell edges");
}

/// True when the pose lies at least 0.15 cell from every cell edge (at an edge the two
/// neighbouring cells explain the measurements equally well and either may win).
fn clear_of_cell_edges(g: &GridSpec, t: &Pose2) -> bool {
    let fx = (t.x - g.origin[0]) / g.cell[0];
    let fy = (t.y - g.origin[1]) / g.cell[1];
    let edge = |f: f32| {
        let r = f - crate::world::math::floor(f);
        (0.15..=0.85).contains(&r)
    };
    edge(fx) && edge(fy)
}

#[test]
fn noise_free_true_cell_is_argmax_ten_bins() {
    let mut exact = 0;
    for (p, truth) in asymmetric_cases() {
        let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
        feed(&mut l, &p, &truth, 10);
        let want = l.grid().cell_of_pose(&truth).unwrap();
        let got = l.argmax().unwrap();
        // headings anywhere in a bin: the argmax is within the coarse tolerance
        assert!(
            l.grid().near(got, want, 1),
            "{got:?} vs {want:?} truth {truth:?} modes {:?}",
            l.top_modes::<3>(2)
        );
        assert!(l.coarse_success_within(&truth, 1, 1));
        // a heading that coincides with a rotation hypothesis (bin 3, sub-bin 1 of 4):
        // the argmax is exactly the true cell
        let h = 3.0 * TAU / 10.0 - TAU / 20.0 + 1.5 * TAU / 40.0;
        let truth = Pose2::new(truth.x, truth.y, h);
        l.clear();
        feed(&mut l, &p, &truth, 10);
        let want = l.grid().cell_of_pose(&truth).unwrap();
        assert!(l.coarse_success_within(&truth, 1, 1));
        if clear_of_cell_edges(l.grid(), &truth) {
            assert_eq!(l.argmax().unwrap(), want, "truth {truth:?}");
            exact += 1;
        }
    }
    assert!(exact >= 4, "only {exact} poses were clear of cell edges");
}

/// Runs `n` noisy measurements with outlier rate `q` (range uniform in [0.2, 12] m,
/// σ = 2 cm otherwise) at random encoder bearings.
fn feed_noisy(
    l: &mut GhtLocalizer,
    p: &FloorPlan,
    truth: &Pose2,
    n: usize,
    q: f32,
    rng: &mut Pcg32,
) {
    let mut done = 0;
    while done < n {
        let k = (rng.next_u32() % 54) as i32;
        let Some((b, r)) = measure(p, truth, k) else {
            continue;
        };
        let r = if uniform(rng) < q {
            0.2 + 11.8 * uniform(rng)
        } else {
            r + 0.02 * gauss(rng)
        };
        l.update(b, r.max(0.05)).unwrap();
        done += 1;
    }
}

#[test]
fn thirty_percent_outliers_still_localize() {
    let mut rng = Pcg32::seed_from_u64(7);
    for (k_bins, expect_min) in [(1u8, 11usize), (10, 10)] {
        let mut ok = 0;
        let mut trials = 0;
        for (p, truth) in asymmetric_cases() {
            for t in 0..2 {
                let cfg = if k_bins == 1 {
                    LocalizerConfig::known_heading(truth.theta)
                } else {
                    LocalizerConfig::DEFAULT
                };
                let mut l = boxed(&p, &cfg);
                let truth = Pose2::new(truth.x, truth.y, truth.theta + 0.37 * t as f32);
                l.set_known_heading(truth.theta);
                feed_noisy(&mut l, &p, &truth, 20, 0.3, &mut rng);
                ok += l.coarse_success_within(&truth, 1, 1) as usize;
                trials += 1;
            }
        }
        assert!(ok >= expect_min, "K={k_bins}: {ok}/{trials}");
    }
}

#[test]
fn outliers_cannot_zero_the_belief() {
    let p = l_room_8x6();
    let truth = Pose2::new(-1.2, -0.6, 0.4);
    let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
    feed(&mut l, &p, &truth, 6);
    let c = l.argmax().unwrap();
    let before = l.weight(l.grid().index(c));
    let snapshot: Vec<f32> = l.weights().collect();
    for (b, r) in [(0.1, 0.3), (1.0, 11.0), (2.0, 0.05), (4.0, 7.7)] {
        l.update(b, r).unwrap();
    }
    // non-destructive: no weight ever decreases, so the true cell keeps its votes
    assert!(l.weights().zip(&snapshot).all(|(a, b)| a >= *b));
    assert!(l.weight(l.grid().index(c)) >= before);
    assert!(l.coarse_success_within(&truth, 1, 1));
}

#[test]
fn staging_never_changes_the_committed_belief() {
    let p = odd_room();
    let truth = Pose2::new(0.5, 0.3, -1.3);
    let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
    // staging before any vote
    let h0 = l.entropy();
    let s = l.stage(0.3, 2.0).unwrap();
    assert_eq!(l.total_weight(), 0.0);
    assert_eq!(l.entropy(), h0);
    assert!(s.entropy < h0);
    feed(&mut l, &p, &truth, 3);
    let snap: Vec<u32> = l.weights().map(|w| w.to_bits()).collect();
    let (h, tot, upd) = (l.entropy(), l.total_weight(), l.updates());
    for k in 0..54 {
        let b = k as f32 * TAU / 54.0;
        for r in [0.5f32, 2.0, 4.5] {
            let st = l.stage(b, r).unwrap();
            // the staged entropy is exactly what committing would give
            if k % 9 == 0 {
                let mut c = Box::new((*l).clone());
                c.update(b, r).unwrap();
                assert!(
                    (c.entropy() - st.entropy).abs() < 5e-4,
                    "{} vs {}",
                    c.entropy(),
                    st.entropy
                );
            }
        }
    }
    assert!(l.weights().map(|w| w.to_bits()).eq(snap.into_iter()));
    assert_eq!((l.entropy(), l.total_weight(), l.updates()), (h, tot, upd));
    // a hypothetical measurement that casts no vote stages to the committed entropy
    let none = l.stage(0.0, 1000.0).unwrap();
    assert_eq!(none.stats.votes, 0);
    assert!((none.entropy - h).abs() < 5e-4, "{} vs {h}", none.entropy);
}

#[test]
fn entropy_follows_evidence() {
    let p = t_room();
    let truth = Pose2::new(0.3, 1.0, 0.9);
    let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
    let mut last = l.entropy();
    let mut rng = Pcg32::seed_from_u64(3);
    for _ in 0..4 {
        feed_noisy(&mut l, &p, &truth, 3, 0.0, &mut rng);
        let h = l.entropy();
        assert!(h < last, "{h} !< {last}");
        last = h;
    }
    let pm = l.peak_mass(1);
    assert!(pm > 0.0 && pm <= 1.0);
    feed_noisy(&mut l, &p, &truth, 30, 0.0, &mut rng);
    assert!(l.coarse_success_within(&truth, 1, 1));
}

/// The modes of `l`, at least `n`, as the set of distinct AgentPoses they stand for.
fn modes<const N: usize>(l: &GhtLocalizer) -> heapless::Vec<Mode, N> {
    l.top_modes::<N>(2)
}

/// Square, K = 8: 90° is exactly two bins, so the belief layer `j + 2` is the 90° rotation
/// of layer `j` and the four C4-equivalent poses are four equal modes.
#[test]
fn square_keeps_four_equal_modes_k8() {
    let p = centred_rect(6.0, 6.0);
    let truth = Pose2::new(1.37, -0.77, 0.5);
    let cfg = LocalizerConfig {
        rot_bins: 8,
        ..LocalizerConfig::DEFAULT
    };
    let mut l = boxed(&p, &cfg);
    feed(&mut l, &p, &truth, 10);
    let m = modes::<5>(&l);
    let top = m[0].mass;
    for k in 0..4 {
        let rel = m[k].mass / top;
        assert!(rel > 0.98, "mode {k}: {:?} rel {rel}", m[k]);
        // each is a C4 equivalent of the truth, and together they cover all four
        assert!(l.grid().coarse_success_within(m[k].cell, &truth, 4, 1));
    }
    for k in 0..4 {
        let phi = k as f32 * PI / 2.0;
        let eq = Pose2::new(
            rotate(truth.translation(), phi).x,
            rotate(truth.translation(), phi).y,
            truth.theta + phi,
        );
        assert_eq!(
            m[..4]
                .iter()
                .filter(|x| l.grid().coarse_success_within(x.cell, &eq, 1, 1))
                .count(),
            1,
            "equivalent {k}"
        );
    }
    assert!(m[4].mass < 0.7 * top, "fifth mode {:?}", m[4]);
    assert!(l.coarse_success_within(&truth, 4, 1));
}

/// Square, K = 10 (default): 90° = 2.5 bins, so the equivalents fall at different offsets
/// inside their bins; the four modes are still the four equivalents, of similar strength.
#[test]
fn square_keeps_four_modes_k10() {
    let p = centred_rect(6.0, 6.0);
    let truth = Pose2::new(1.37, -0.77, 0.5);
    let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
    feed(&mut l, &p, &truth, 10);
    let m = modes::<5>(&l);
    let mut hit = [false; 4];
    for x in &m[..4] {
        assert!(x.mass > 0.7 * m[0].mass, "{:?} vs {:?}", x, m[0]);
        for (k, h) in hit.iter_mut().enumerate() {
            let phi = k as f32 * PI / 2.0;
            let a = rotate(truth.translation(), phi);
            if l.grid().coarse_success_within(
                x.cell,
                &Pose2::new(a.x, a.y, truth.theta + phi),
                1,
                1,
            ) {
                *h = true;
            }
        }
    }
    assert_eq!(hit, [true; 4]);
    assert!(l.coarse_success_within(&truth, 4, 1));
}

/// Square, K = 1: with the heading known there is exactly one mode; supplying the headings
/// of the four C4-equivalent poses as the known heading gives four beliefs that are 90°
/// rotations of each other, with equal peak weights.
#[test]
fn square_k1_known_heading_equivalents() {
    let p = centred_rect(6.0, 6.0);
    let truth = Pose2::new(1.37, -0.77, 0.5);
    let mut peaks = [0.0f32; 4];
    for (k, pk) in peaks.iter_mut().enumerate() {
        let phi = k as f32 * PI / 2.0;
        let mut l = boxed(&p, &LocalizerConfig::known_heading(truth.theta + phi));
        feed(&mut l, &p, &truth, 8);
        let c = l.argmax().unwrap();
        let a = rotate(truth.translation(), phi);
        let eq = Pose2::new(a.x, a.y, truth.theta + phi);
        assert_eq!(Some(c), l.grid().cell_of_pose(&eq), "k = {k}");
        assert!(l.coarse_success_within(&truth, 4, 1));
        assert_eq!(l.coarse_success_within(&truth, 1, 1), k == 0);
        *pk = l.weight(l.grid().index(c));
        let m = l.top_modes::<2>(2);
        assert!(m[1].mass < 0.7 * m[0].mass, "single mode expected: {m:?}");
    }
    for pk in &peaks {
        assert!((pk / peaks[0] - 1.0).abs() < 0.02, "{peaks:?}");
    }
}

#[test]
fn rectangle_keeps_two_modes() {
    let p = centred_rect(9.0, 5.0);
    let truth = Pose2::new(2.0, 0.9, -0.7);
    let mut l = boxed(&p, &LocalizerConfig::DEFAULT);
    feed(&mut l, &p, &truth, 10);
    let m = modes::<3>(&l);
    assert!(m[1].mass / m[0].mass > 0.98, "{m:?}");
    assert!(m[2].mass < 0.7 * m[0].mass, "{m:?}");
    let back = Pose2::new(-truth.x, -truth.y, truth.theta + PI);
    let a = [truth, back];
    for t in a {
        assert_eq!(
            m[..2]
                .iter()
                .filter(|x| l.grid().coarse_success_within(x.cell, &t, 1, 1))
                .count(),
            1
        );
    }
    assert!(l.coarse_success_within(&truth, 2, 1));
}

/// `grid::mass_near` visits only the rows near its centres; it must add the same cells in
/// the same order as the pass over every cell it replaced (bit for bit), with and without
/// symmetric equivalents, centres on the grid's edges and bins wrapping around.
#[test]
fn mass_near_equals_the_pass_over_every_cell() {
    use crate::localization::grid::{mass_near, CellIndex, GridSpec};
    let reference =
        |grid: &GridSpec, n: usize, centre: CellIndex, order: u8, prob: &dyn Fn(usize) -> f32| {
            let k = order.max(1);
            let mut centres: heapless::Vec<CellIndex, 16> = heapless::Vec::new();
            for j in 0..k.min(16) {
                if let Some(c) = grid.equivalent_cell(centre, j, k) {
                    if !centres.contains(&c) {
                        let _ = centres.push(c);
                    }
                }
            }
            let mut m = 0.0;
            for i in 0..n {
                let c = grid.cell_at(i);
                if centres.iter().any(|&k| grid.near(k, c, 1)) {
                    m += prob(i);
                }
            }
            m
        };
    let mut rng = Pcg32::new(7, 11);
    for rot_bins in [1u8, 2, 3, 10] {
        let grid = GridSpec {
            nx: 13,
            ny: 9,
            rot_bins,
            origin: [-6.5, -4.5],
            cell: [1.0, 1.0],
            known_heading: 0.0,
        };
        let n = grid.len();
        let weights: std::vec::Vec<f32> = (0..n).map(|_| uniform(&mut rng) * 1e-2).collect();
        let prob = |i: usize| weights[i];
        for trial in 0..200 {
            let centre = CellIndex {
                ix: (rng.next_u32() % 13) as u8,
                iy: (rng.next_u32() % 9) as u8,
                bin: (rng.next_u32() % rot_bins as u32) as u8,
            };
            let order = [1u8, 2, 4][trial % 3];
            let fast = mass_near(&grid, n, centre, order, prob);
            let slow = reference(&grid, n, centre, order, &prob);
            assert_eq!(
                fast.to_bits(),
                slow.to_bits(),
                "{centre:?} order {order} K {rot_bins}"
            );
        }
    }
}

/// The interleaved belief writer (four cells per step, a caller's per-byte maximum, no
/// interior test where level 0 maps to the outside value) against the cell-by-cell values
/// of `for_each_level`, with a table whose level 0 differs from the outside value and one
/// where it does not.
#[test]
fn interleaved_levels_equal_for_each_level() {
    use crate::localization::ght::max_u8x4;
    let p = odd_room();
    let cfg = LocalizerConfig::default();
    let mut l = boxed(&p, &cfg);
    feed(&mut l, &p, &Pose2::new(0.7, -0.4, 0.9), 6);
    let grid = *l.grid();
    let (nx, k) = (grid.nx as usize, grid.rot_bins as usize);
    let (max_side, side) = (nx.max(grid.ny as usize) - 1, nx.max(grid.ny as usize) + 1);
    for zero_differs in [true, false] {
        let table: [u16; 256] = core::array::from_fn(|m| 1000 + m as u16);
        let outside = if zero_differs { 7 } else { table[0] };
        let mut out = std::vec![0u16; side * side * k];
        l.write_levels_interleaved_with(&mut out, side, max_side, &table, outside, max_u8x4);
        let mut expected = std::vec![0u16; side * side * k];
        l.for_each_level(|i, level| {
            let (bin, cell) = (i / grid.layer_len(), i % grid.layer_len());
            let (x, y) = (cell % nx, cell / nx);
            if x < max_side && y < max_side {
                expected[((y + 1) * side + x + 1) * k + bin] =
                    level.map_or(outside, |m| table[m as usize]);
            }
        });
        assert_eq!(
            out, expected,
            "level 0 differs from outside: {zero_differs}"
        );
    }
}

/// Up to `N` modes in decreasing score (`score(i)` of flat cell `i < n`), by a scan of every
/// cell per mode with non-maximum suppression: a cell within `min_separation` (Chebyshev in
/// x, y and circular in bins, [`GridSpec::near`]) of an already chosen mode is not a new
/// mode, and zero-score cells are never modes. `prob(i)` is reported as [`Mode::mass`]. The
/// reference [`GhtLocalizer::top_modes`] is tested against.
fn top_modes_by<const N: usize, S: Fn(usize) -> f32, F: Fn(usize) -> f32>(
    grid: &GridSpec,
    n: usize,
    score: S,
    min_separation: u8,
    prob: F,
) -> HVec<Mode, N> {
    let mut out: HVec<Mode, N> = HVec::new();
    while !out.is_full() {
        let mut best: Option<(usize, f32)> = None;
        for (i, v) in (0..n).map(|i| (i, score(i))) {
            if v <= 0.0 || best.is_some_and(|(_, bv)| v <= bv) {
                continue;
            }
            let c = grid.cell_at(i);
            if out.iter().any(|m| grid.near(m.cell, c, min_separation)) {
                continue;
            }
            best = Some((i, v));
        }
        let Some((i, _)) = best else { break };
        let cell = grid.cell_at(i);
        let _ = out.push(Mode {
            cell,
            pose: grid.pose_of(cell),
            mass: prob(i),
        });
    }
    out
}

/// `GhtLocalizer::top_modes` (a walk comparing levels) finds the modes the scan of the
/// weights (`top_modes_by`) finds, before and after the accumulator rebases, with
/// the heading known and unknown, at every number of modes asked for.
#[test]
fn top_modes_match_the_weight_scan() {
    let scan = |l: &GhtLocalizer| {
        top_modes_by::<4, _, _>(l.grid(), l.grid().len(), |i| l.weight(i), 2, |i| l.prob(i))
    };
    let mut rng = Pcg32::seed_from_u64(7);
    for (p, truth) in asymmetric_cases() {
        for cfg in [
            LocalizerConfig::DEFAULT,
            LocalizerConfig::known_heading(truth.theta),
        ] {
            let mut l = boxed(&p, &cfg);
            assert_eq!(l.top_modes::<4>(2), scan(&l), "no vote yet");
            let mut rebased = false;
            for _ in 0..40 {
                feed_noisy(&mut l, &p, &truth, 3, 0.02, &mut rng);
                assert_eq!(l.top_modes::<4>(2), scan(&l));
                assert_eq!(l.top_modes::<1>(2)[..], scan(&l)[..1]);
                // Cells outside the room hold level 0: a positive least weight is the base.
                rebased |= l.weights().fold(f32::INFINITY, f32::min) > 0.0;
            }
            assert!(rebased, "the accumulator rebased at least once");
        }
    }
}
