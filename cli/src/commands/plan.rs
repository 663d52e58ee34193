//! `activesense plan`: generate one floor-plan from its seed, print its shape, visual centre
//! and agent placement, and optionally write it as JSON and SVG.

use super::write_file;
use activesense_core::episode::AgentKind;
use activesense_core::episode::EpisodeConfig;
use activesense_instrument::episode::EpisodeSpec;
use activesense_instrument::plot::svg::{self, Scene};
use activesense_instrument::world::placement;
use activesense_instrument::world::plans::{self, Family};
use activesense_instrument::world::sensor::SensorModel;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct PlanArgs {
    /// Plan seed (u32). Test plans are 1000000..1001000, training plans 0..1000000.
    #[arg(long)]
    seed: u32,
    /// Restrict the generator to one family.
    #[arg(long, value_enum)]
    family: Option<Family>,
    /// Write an SVG picture here.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Write the plan as JSON here: a plan file `--plan` accepts (`vertices`, metres, the
    /// model frame), plus its shape, family, placement and the drawn agent.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Episode seed used to place the drawn agent.
    #[arg(long, default_value_t = 0)]
    episode_seed: u64,
}

pub fn run(a: PlanArgs) -> Result<()> {
    let g = plans::generate_detailed(a.seed, a.family);
    let p = placement(&g.plan);
    let (lo, hi) = g.plan.bounds();
    println!(
        "plan {}: {:?} ({:?}), {} vertices, {:.2} m x {:.2} m, perimeter {:.2} m, area {:.2} m²",
        g.seed,
        g.shape,
        g.family,
        g.plan.len(),
        hi.x - lo.x,
        hi.y - lo.y,
        g.plan.perimeter(),
        g.plan.signed_area()
    );
    println!(
        "visual centre ({:.3}, {:.3}), placement radius {:.3} m",
        p.visual_centre[0], p.visual_centre[1], p.radius
    );
    let world = activesense_instrument::world::SimWorld::new(
        g.plan.clone(),
        SensorModel::default(),
        EpisodeConfig::default(),
        EpisodeSpec {
            episode_seed: a.episode_seed,
            ..EpisodeSpec::new(a.seed, AgentKind::Heuristic1)
        }
        .world_seed(),
    );
    let truth = world.truth();
    println!(
        "agent ({:.3}, {:.3}), heading {:.1}°",
        truth.x,
        truth.y,
        truth.theta.to_degrees()
    );
    if let Some(path) = &a.json {
        // `vertices` and `name` first: the file is also a plan file that `--plan` reads
        // (our JSON, metres, model frame); the rest describes how it was generated.
        let doc = serde_json::json!({
            "name": format!("plan {}", g.seed),
            "vertices": g.plan.raw(),
            "generated": g,
            "placement": p,
            "agent": truth,
        });
        write_file(path, &serde_json::to_string_pretty(&doc)?)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &a.svg {
        let scene = Scene {
            title: format!("plan {} — {:?}, {} vertices", g.seed, g.shape, g.plan.len()),
            placement: Some(p),
            agent: Some(truth),
            ..Default::default()
        };
        write_file(path, &svg::render(&g.plan, &scene))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
