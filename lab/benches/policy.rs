//! Criterion benchmarks of the learnt policy on the host (paper §3.1): one decision of the
//! float network (features from the core's `PolicyInput` + forward pass) at K = 1 and
//! K = 10, the forward pass alone, and one training step's forward + backward over a batch
//! of 256 states (both cores), plus a whole simulated heuristic-1 episode for the
//! environment's cost per step.
//!
//! `cargo bench -p activesense-lab --bench policy`

use activesense_core::episode::AgentKind;
use activesense_core::pipeline::runner::EpisodeRunner;
use activesense_core::policy::{BELIEF_PLANE, SIDE_FEATURES};
use activesense_instrument::episode::{run_episode, start_episode, EpisodeSpec};
use activesense_instrument::learn::agent::{features, shape_for, LearntAgent};
use activesense_instrument::learn::net::{BatchCache, PolicyNet, Scratch};
use activesense_instrument::world::plans;
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use std::sync::Arc;

fn bench(c: &mut Criterion) {
    for k in [1u8, 10] {
        let net = PolicyNet::new(shape_for(k), 1);
        let mut spec = EpisodeSpec::new(plans::TEST_SEEDS.start, AgentKind::Learnt);
        spec.rot_bins = k;
        let mut runner = Box::new(EpisodeRunner::new_empty());
        start_episode(&spec, &mut runner);
        let (mut b, mut s) = (
            vec![0.0; k as usize * BELIEF_PLANE],
            vec![0.0; SIDE_FEATURES],
        );
        features(&runner.input(), &mut b, &mut s);
        let mut scratch = Scratch::new(net.shape);
        c.bench_function(&format!("forward K={k}"), |bch| {
            bch.iter(|| net.forward_with(black_box(&b), black_box(&s), &mut scratch))
        });
        let mut agent = LearntAgent::new(Arc::new(net.clone()));
        c.bench_function(&format!("decision (features + forward) K={k}"), |bch| {
            bch.iter(|| runner.decide(&mut agent))
        });
        let n = 256;
        let bb: Vec<f32> = b.iter().cycle().take(n * b.len()).copied().collect();
        let ss: Vec<f32> = s.iter().cycle().take(n * s.len()).copied().collect();
        let mut cache = BatchCache::new();
        let mut grad = vec![0.0; net.shape.param_count()];
        c.bench_function(&format!("train step fwd+bwd batch 256 K={k}"), |bch| {
            bch.iter(|| {
                net.forward_batch(&bb, &ss, n, &mut cache);
                let dl = vec![0.01; n * 3];
                let dv = vec![0.01; n];
                net.backward_batch(&mut cache, &dl, &dv, &mut grad);
            })
        });
        let mut h1 = EpisodeSpec::new(plans::TEST_SEEDS.start + 1, AgentKind::Heuristic1);
        h1.rot_bins = k;
        c.bench_function(&format!("heuristic-1 episode K={k}"), |bch| {
            bch.iter(|| run_episode(black_box(&h1)))
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
