//! Criterion benchmarks of the localization kernels (paper §3.2, Table 1): GHT reset
//! (grid + interior mask + R-table), GHT update, staging and entropy at 30 × 30 × {1, 10},
//! and the classical localizer's precomputation and update on the same plan.
//!
//! `cargo bench -p activesense-lab --bench localization`

use activesense_core::localization::{GhtLocalizer, LocalizerConfig};
use activesense_core::world::math::TAU;
use activesense_instrument::world::plans;
use activesense_instrument::world::SimWorld;
use activesense_lab::baselines::classical::{ClassicalConfig, ClassicalLocalizer};
use criterion::{black_box, criterion_group, criterion_main, Criterion};

fn measurements(
    seed: u32,
) -> (
    activesense_core::FloorPlan,
    activesense_core::Pose2,
    Vec<(f32, f32)>,
) {
    let plan = plans::generate(seed);
    let world = SimWorld::new(plan.clone(), Default::default(), Default::default(), 7);
    let t = world.truth();
    let ms = (0..54)
        .filter_map(|k| {
            let b = k as f32 * TAU / 54.0;
            plan.ray_cast(
                t.translation(),
                activesense_core::world::geometry::unit(t.theta + b),
            )
            .filter(|h| h.incidence < 1.3)
            .map(|h| (b, h.range))
        })
        .collect();
    (plan, t, ms)
}

fn bench(c: &mut Criterion) {
    let (plan, truth, ms) = measurements(plans::TEST_SEEDS.start);
    for (name, cfg) in [
        ("k10_s4", LocalizerConfig::DEFAULT),
        ("k1", LocalizerConfig::known_heading(truth.theta)),
    ] {
        let mut g = Box::new(GhtLocalizer::new_empty());
        c.bench_function(&format!("ght_reset_{name}"), |b| {
            b.iter(|| g.reset(black_box(&plan), &cfg).unwrap())
        });
        let mut i = 0;
        c.bench_function(&format!("ght_update_{name}"), |b| {
            b.iter(|| {
                let (be, r) = ms[i % ms.len()];
                i += 1;
                g.update(be, r).unwrap()
            })
        });
        c.bench_function(&format!("ght_stage_{name}"), |b| {
            b.iter(|| {
                let (be, r) = ms[i % ms.len()];
                i += 1;
                g.stage(be, r).unwrap()
            })
        });
        c.bench_function(&format!("ght_entropy_{name}"), |b| b.iter(|| g.entropy()));
        let mut cl = ClassicalLocalizer::new(&plan, &cfg, &ClassicalConfig::default()).unwrap();
        c.bench_function(&format!("classical_update_{name}"), |b| {
            b.iter(|| {
                let (be, r) = ms[i % ms.len()];
                i += 1;
                cl.update(be, r).unwrap()
            })
        });
    }
    let mut group = c.benchmark_group("precompute");
    group.sample_size(10);
    group.bench_function("classical_new_k10_s4", |b| {
        b.iter(|| {
            ClassicalLocalizer::new(
                black_box(&plan),
                &LocalizerConfig::DEFAULT,
                &ClassicalConfig::default(),
            )
            .unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
