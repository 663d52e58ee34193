//! `activesense dataset`: summarise a seed range of generated plans (shapes, vertex counts,
//! extents) as a markdown table.

use activesense_instrument::world::plans;
use anyhow::Result;
use clap::Args;

#[derive(Args)]
pub struct DatasetArgs {
    /// Which published seed range to summarise.
    #[arg(long, value_enum, default_value = "test")]
    split: Split,
    /// Summarise only the first N plans of the split.
    #[arg(long)]
    plans: Option<u32>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Split {
    /// Seeds 1000000..1001000.
    Test,
    /// Seeds 0..1000000.
    Train,
}

pub fn run(a: DatasetArgs) -> Result<()> {
    let range = match a.split {
        Split::Test => plans::TEST_SEEDS,
        Split::Train => plans::TRAIN_SEEDS,
    };
    let n = a
        .plans
        .unwrap_or(range.end - range.start)
        .min(range.end - range.start);
    let mut by_shape: std::collections::BTreeMap<String, (u32, usize, usize, f32, f32)> =
        Default::default();
    for seed in range.start..range.start + n {
        let g = plans::generate_detailed(seed, None);
        let (lo, hi) = g.plan.bounds();
        let side = (hi - lo).x.max((hi - lo).y);
        let e = by_shape
            .entry(format!("{:?} ({:?})", g.shape, g.family))
            .or_insert((0, usize::MAX, 0, f32::INFINITY, 0.0));
        e.0 += 1;
        e.1 = e.1.min(g.plan.len());
        e.2 = e.2.max(g.plan.len());
        e.3 = e.3.min(side);
        e.4 = e.4.max(side);
    }
    println!("{n} plans from seed {}", range.start);
    println!("| shape (family) | plans | share | vertices | longest side (m) |");
    println!("|---|---:|---:|---|---|");
    for (k, (c, vmin, vmax, smin, smax)) in by_shape {
        println!(
            "| {k} | {c} | {:.1}% | {vmin}–{vmax} | {smin:.1}–{smax:.1} |",
            100.0 * c as f32 / n as f32
        );
    }
    Ok(())
}
