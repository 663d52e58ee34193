//! The simulated world's contract (issue "Workspace, simulated floor-plan world and the
//! baseline sampling agents"): every generated plan is valid, inside the documented extents
//! and reproducible byte for byte; ray casts agree with closed-form answers.

use activesense_core::world::geometry::{unit, v2};
use activesense_core::FloorPlan;
use activesense_instrument::world::plans::{
    self, generate, MAX_GEN_VERTICES, MAX_SIDE, MIN_SIDE, MIN_VERTICES, TEST_SEEDS, TRAIN_SEEDS,
};
use proptest::prelude::*;

fn plan_bytes(p: &FloorPlan) -> Vec<u8> {
    p.raw()
        .iter()
        .flat_map(|v| [v[0].to_le_bytes(), v[1].to_le_bytes()])
        .flatten()
        .collect()
}

fn check_plan(seed: u32) {
    let p = generate(seed);
    p.validate().unwrap_or_else(|e| panic!("seed {seed}: {e}"));
    let (lo, hi) = p.bounds();
    let ext = hi - lo;
    assert!(
        (MIN_SIDE..=MAX_SIDE).contains(&ext.x) && (MIN_SIDE..=MAX_SIDE).contains(&ext.y),
        "seed {seed}: extent {ext:?}"
    );
    assert!(
        (MIN_VERTICES..=MAX_GEN_VERTICES).contains(&p.len()),
        "seed {seed}: {} vertices",
        p.len()
    );
    assert!(
        p.perimeter_centroid().norm() < 1e-3,
        "seed {seed}: not centred"
    );
    assert_eq!(
        plan_bytes(&p),
        plan_bytes(&generate(seed)),
        "seed {seed}: not reproducible"
    );
}

/// 10,000 plans: all 1000 test plans and 9000 training plans spread over the range.
#[test]
fn ten_thousand_plans_valid_in_extent_and_reproducible() {
    for seed in TEST_SEEDS {
        check_plan(seed);
    }
    let stride = TRAIN_SEEDS.len() as u32 / 9000;
    for i in 0..9000u32 {
        check_plan(TRAIN_SEEDS.start + i * stride);
    }
}

/// The test set must be the same on every machine and with every build. FNV-1a over the
/// little-endian bytes of all 1000 test plans; if the generator changes on purpose, update
/// this value *and* regenerate every published result.
#[test]
fn test_set_fingerprint() {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for seed in TEST_SEEDS {
        for b in plan_bytes(&generate(seed)) {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    let expected = include_str!("../../docs/test-set.fingerprint").trim();
    assert_eq!(format!("{h:016x}"), expected);
}

#[test]
fn symmetric_rooms_are_part_of_the_test_set() {
    use activesense_instrument::world::plans::Shape;
    let mut squares = 0;
    let mut rects = 0;
    for s in TEST_SEEDS {
        match plans::generate_detailed(s, None).shape {
            Shape::Square => squares += 1,
            Shape::Rectangle => rects += 1,
            _ => {}
        }
    }
    assert!(
        squares >= 20 && rects >= 60,
        "squares {squares}, rectangles {rects}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn any_seed_gives_a_valid_plan(seed in any::<u32>()) {
        check_plan(seed);
    }

    /// In a w × h rectangle the first hit from an interior point is the nearest of the four
    /// axis-aligned walls along the ray: min over walls of the slab distance.
    #[test]
    fn ray_cast_matches_rectangle_slabs(
        w in 3.0f32..30.0, h in 3.0f32..30.0,
        fx in 0.05f32..0.95, fy in 0.05f32..0.95, angle in -std::f32::consts::PI..std::f32::consts::PI,
    ) {
        let r = FloorPlan::new(&[v2(0.0, 0.0), v2(w, 0.0), v2(w, h), v2(0.0, h)]).unwrap();
        let o = v2(fx * w, fy * h);
        let d = unit(angle);
        let tx = if d.x > 1e-6 { (w - o.x) / d.x } else if d.x < -1e-6 { -o.x / d.x } else { f32::INFINITY };
        let ty = if d.y > 1e-6 { (h - o.y) / d.y } else if d.y < -1e-6 { -o.y / d.y } else { f32::INFINITY };
        let expect = tx.min(ty);
        let hit = r.ray_cast(o, d).unwrap();
        prop_assert!((hit.range - expect).abs() < 1e-3 * expect.max(1.0), "{} vs {}", hit.range, expect);
    }

    /// In the L-room (6 × 4 minus the 3 × 2 top-right corner) a ray cast from the lower arm
    /// hits the same wall as a brute-force march along the ray.
    #[test]
    fn ray_cast_l_room_matches_march(fx in 0.05f32..0.95, fy in 0.05f32..0.95, angle in -std::f32::consts::PI..std::f32::consts::PI) {
        let l = FloorPlan::new(&[v2(0.0, 0.0), v2(6.0, 0.0), v2(6.0, 2.0), v2(3.0, 2.0), v2(3.0, 4.0), v2(0.0, 4.0)]).unwrap();
        let o = v2(fx * 6.0, fy * 2.0);
        let d = unit(angle);
        // A ray through (or within a march step of) the reflex corner (3, 2) grazes it: the
        // cast stops at the corner, the march slips past into the upper arm, and both are
        // right. Such rays are measure-zero for an EDM; they are not what this compares
        // (found by a CI run: fx = 0.594, fy = 0.799, angle = 2.524 passes 0.2 mm from it).
        let c = v2(3.0, 2.0) - o;
        let ahead = c.x * d.x + c.y * d.y > 0.0;
        prop_assume!(!(ahead && (c.x * d.y - c.y * d.x).abs() < 0.005));
        let hit = l.ray_cast(o, d).unwrap();
        // March in 1 mm steps until leaving the room.
        let mut t = 0.0f32;
        while l.contains(o + d * (t + 0.001)) { t += 0.001; }
        prop_assert!((hit.range - t).abs() < 0.003, "{} vs march {}", hit.range, t);
    }
}
