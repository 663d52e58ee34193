//! The Fig.-4 analysis (paper §5.1): which belief cells drive the learnt policy's
//! measurement and rotation decisions, averaged over many test-plan episodes.
//!
//! Every decision of every episode gives one guided-back-propagation map over the belief
//! ([`activesense_instrument::learn::net::PolicyNet::guided_backprop`] of the chosen action's logit). Each map
//! is reduced to its positive part, summed over the rotation channels, and normalised by its
//! own largest value (a decision whose map is all ≤ 0 is counted but adds nothing), so every
//! decision weighs the same. The maps are averaged separately over measure and rotate
//! decisions in two frames:
//!
//! - **grid**: the raw 30 × 30 belief grid, which spans each room's bounding box (so a cell
//!   is a relative position in the room, whatever its size);
//! - **centred**: the same cells shifted so that the cell of the room's visual centre (where
//!   the agent is placed, uniformly within the placement disc) sits in the middle of a 59 × 59
//!   frame; a frame cell's mean is over the decisions that cover it.
//!
//! The radial profile answers the paper's reading directly: the mean normalised activation
//! of the cells inside the room, binned by the cell centre's distance from the visual centre
//! in units of the placement radius (r < 1 is the disc the agent starts in), beside the mean
//! normalised belief of the same cells.

use super::record_episode;
use activesense_core::episode::EpisodeConfig;
use activesense_core::episode::{Action, AgentKind};
use activesense_core::policy::BELIEF_SIDE;
use activesense_core::world::geometry::{length, v2};
use activesense_instrument::episode::{EpisodeSpec, Termination, Trajectory};
use activesense_instrument::learn::agent::LearntPolicy;
use activesense_instrument::world::plans;
use anyhow::{Context, Result};
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write;
use std::path::{Path, PathBuf};

const S: usize = BELIEF_SIDE;
/// Side of the centred frame.
pub const CENTRED: usize = 2 * BELIEF_SIDE - 1;
/// Upper edges of the radial bins, in placement radii (the last is open).
pub const RADIAL_EDGES: [f32; 6] = [0.5, 1.0, 1.5, 2.0, 3.0, f32::INFINITY];

/// What to aggregate.
#[derive(Clone, Debug)]
pub struct AggregateOptions {
    /// Test plans (seeds from `first_seed` on).
    pub plans: u32,
    /// First plan seed.
    pub first_seed: u32,
    /// Episode seed.
    pub episode_seed: u64,
    /// Rotation bins.
    pub rot_bins: u8,
    /// Show a progress bar.
    pub progress: bool,
}

/// Sums for one decision kind.
#[derive(Clone, Debug, Serialize)]
pub struct KindSums {
    /// Decisions of this kind.
    pub decisions: u64,
    /// Decisions whose guided map had no positive value (added nothing).
    pub empty_maps: u64,
    /// Mean normalised activation per grid cell, `[y][x]` row-major, y up.
    pub grid_mean: Vec<f32>,
    /// Mean normalised activation per centred-frame cell (`CENTRED²`), over the decisions
    /// covering the cell; 0 where fewer than 5 % of the decisions do.
    pub centred_mean: Vec<f32>,
    /// Mean normalised belief per grid cell over the same decisions.
    pub belief_grid_mean: Vec<f32>,
    /// Per radial bin: mean normalised activation of the room cells in it.
    pub radial_activation: Vec<f32>,
    /// Per radial bin: mean normalised belief of the room cells in it.
    pub radial_belief: Vec<f32>,
    /// Per radial bin: mean of the belief-weighted guided map (positive part × belief,
    /// normalised per decision by its max): where the mass that drove the decision lay.
    pub radial_contribution: Vec<f32>,
    /// Per radial bin: room cells counted (over all decisions).
    pub radial_cells: Vec<u64>,
    #[serde(skip)]
    acc: Acc,
}

#[derive(Clone, Debug, Default)]
struct Acc {
    grid: Vec<f64>,
    belief: Vec<f64>,
    centred: Vec<f64>,
    centred_belief: Vec<f64>,
    centred_n: Vec<u64>,
    radial: Vec<f64>,
    radial_belief: Vec<f64>,
    radial_contribution: Vec<f64>,
    radial_n: Vec<u64>,
    decisions: u64,
    empty: u64,
}

impl Acc {
    fn new() -> Self {
        Acc {
            grid: vec![0.0; S * S],
            belief: vec![0.0; S * S],
            centred: vec![0.0; CENTRED * CENTRED],
            centred_belief: vec![0.0; CENTRED * CENTRED],
            centred_n: vec![0; CENTRED * CENTRED],
            radial: vec![0.0; RADIAL_EDGES.len()],
            radial_belief: vec![0.0; RADIAL_EDGES.len()],
            radial_contribution: vec![0.0; RADIAL_EDGES.len()],
            radial_n: vec![0; RADIAL_EDGES.len()],
            decisions: 0,
            empty: 0,
        }
    }

    fn add(&mut self, o: &Acc) {
        let add = |a: &mut Vec<f64>, b: &Vec<f64>| a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        add(&mut self.grid, &o.grid);
        add(&mut self.belief, &o.belief);
        add(&mut self.centred, &o.centred);
        add(&mut self.centred_belief, &o.centred_belief);
        add(&mut self.radial, &o.radial);
        add(&mut self.radial_belief, &o.radial_belief);
        add(&mut self.radial_contribution, &o.radial_contribution);
        self.centred_n
            .iter_mut()
            .zip(&o.centred_n)
            .for_each(|(x, y)| *x += y);
        self.radial_n
            .iter_mut()
            .zip(&o.radial_n)
            .for_each(|(x, y)| *x += y);
        self.decisions += o.decisions;
        self.empty += o.empty;
    }

    fn finish(self) -> KindSums {
        let n = self.decisions.max(1) as f64;
        let mean = |v: &[f64]| v.iter().map(|x| (x / n) as f32).collect::<Vec<f32>>();
        let per = |v: &[f64], c: &[u64]| {
            v.iter()
                .zip(c)
                .map(|(x, &k)| if k > 0 { (x / k as f64) as f32 } else { 0.0 })
                .collect::<Vec<f32>>()
        };
        // Centred-frame cells covered by under 5 % of the decisions are left out (0): a
        // mean over a handful of maps is noise.
        let min_cover = (self.decisions / 20).max(1);
        let centred_mean = self
            .centred
            .iter()
            .zip(&self.centred_n)
            .map(|(x, &k)| {
                if k >= min_cover {
                    (x / k as f64) as f32
                } else {
                    0.0
                }
            })
            .collect::<Vec<f32>>();
        KindSums {
            decisions: self.decisions,
            empty_maps: self.empty,
            grid_mean: mean(&self.grid),
            centred_mean,
            belief_grid_mean: mean(&self.belief),
            radial_activation: per(&self.radial, &self.radial_n),
            radial_belief: per(&self.radial_belief, &self.radial_n),
            radial_contribution: per(&self.radial_contribution, &self.radial_n),
            radial_cells: self.radial_n.clone(),
            acc: self,
        }
    }
}

/// A map's positive part divided by its maximum; `None` when no value is positive.
fn normalised(map: &[f32]) -> Option<Vec<f32>> {
    let m = map.iter().copied().fold(0.0f32, f32::max);
    (m > 0.0).then(|| map.iter().map(|v| v.max(0.0) / m).collect())
}

/// Positive part summed over the `K` channels of a `K·S²` map.
fn over_channels(map: &[f32], k: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; S * S];
    for c in 0..k {
        for (o, v) in out.iter_mut().zip(&map[c * S * S..(c + 1) * S * S]) {
            *o += v.max(0.0);
        }
    }
    out
}

/// The measure and rotate sums of one episode.
fn episode_sums(t: &Trajectory) -> [Acc; 2] {
    let mut acc = [Acc::new(), Acc::new()];
    let Some(h) = &t.inspection else {
        return acc;
    };
    let g = h.grid;
    let k = g.rot_bins as usize;
    let vc = v2(t.placement.visual_centre[0], t.placement.visual_centre[1]);
    let radius = t.placement.radius.max(1e-6);
    let (vcx, vcy) = g
        .cell_of(vc)
        .map(|(x, y)| (x as isize, y as isize))
        .unwrap_or((g.nx as isize / 2, g.ny as isize / 2));
    // Cells inside the room and their radial bin.
    let mut bin_of = vec![None; S * S];
    for y in 0..g.ny as usize {
        for x in 0..g.nx as usize {
            let c = g.cell_centre(x, y);
            if t.plan.contains(c) {
                let r = length(c - vc) / radius;
                bin_of[y * S + x] = RADIAL_EDGES.iter().position(|&e| r < e);
            }
        }
    }
    for s in &t.steps {
        let Some(ins) = &s.inspect else { continue };
        let a = &mut acc[usize::from(s.action != Action::Measure)];
        a.decisions += 1;
        let belief = normalised(&over_channels(&ins.belief, k)).unwrap_or(vec![0.0; S * S]);
        let Some(m) = normalised(&over_channels(&ins.gbp_belief, k)) else {
            a.empty += 1;
            continue;
        };
        // Positive guided map times the belief, per channel, summed, normalised.
        let mut weighted = vec![0.0f32; S * S];
        for c in 0..k {
            let plane = c * S * S..(c + 1) * S * S;
            for ((w, gv), bv) in weighted
                .iter_mut()
                .zip(&ins.gbp_belief[plane.clone()])
                .zip(&ins.belief[plane])
            {
                *w += gv.max(0.0) * bv;
            }
        }
        let contribution = normalised(&weighted).unwrap_or(vec![0.0; S * S]);
        for y in 0..S {
            for x in 0..S {
                let i = y * S + x;
                a.grid[i] += f64::from(m[i]);
                a.belief[i] += f64::from(belief[i]);
                if x < g.nx as usize && y < g.ny as usize {
                    let cx = x as isize - vcx + (S as isize - 1);
                    let cy = y as isize - vcy + (S as isize - 1);
                    if (0..CENTRED as isize).contains(&cx) && (0..CENTRED as isize).contains(&cy) {
                        let j = cy as usize * CENTRED + cx as usize;
                        a.centred[j] += f64::from(m[i]);
                        a.centred_belief[j] += f64::from(belief[i]);
                        a.centred_n[j] += 1;
                    }
                }
                if let Some(b) = bin_of[i] {
                    a.radial[b] += f64::from(m[i]);
                    a.radial_belief[b] += f64::from(belief[i]);
                    a.radial_contribution[b] += f64::from(contribution[i]);
                    a.radial_n[b] += 1;
                }
            }
        }
    }
    acc
}

/// The whole analysis.
#[derive(Clone, Debug, Serialize)]
pub struct AggregateReport {
    /// The command that made it.
    pub command: String,
    /// The float policy (file and checksum).
    pub policy: String,
    pub rot_bins: u8,
    pub plans: u32,
    pub first_seed: u32,
    pub episode_seed: u64,
    /// Episodes that ended on coarse success.
    pub recognised: u32,
    /// Episodes with at least one rotation (§5.1's second observation: the paper's agent
    /// turns one way only within an episode).
    pub rotating_episodes: u32,
    /// Of those, episodes that turned both left and right.
    pub both_directions: u32,
    /// Of those, episodes that turned right only.
    pub right_only: u32,
    /// Upper edges of the radial bins (placement radii; the last is `null` = open).
    pub radial_edges: Vec<Option<f32>>,
    pub measure: KindSums,
    pub rotate: KindSums,
}

/// Runs `opts.plans` learnt-policy episodes with inspection and aggregates their guided maps.
pub fn run(opts: &AggregateOptions, policy: &LearntPolicy, command: &str) -> AggregateReport {
    let bar = crate::eval::harness::episode_bar(u64::from(opts.plans), opts.progress);
    // Per-episode sums come back in plan order and are added in that order: the result
    // does not depend on the thread count.
    let per: Vec<([Acc; 2], bool, [bool; 2])> = (0..opts.plans)
        .into_par_iter()
        .map(|i| {
            let spec = EpisodeSpec {
                plan_seed: opts.first_seed.wrapping_add(i),
                episode_seed: opts.episode_seed,
                agent: AgentKind::Learnt,
                rot_bins: opts.rot_bins,
                config: EpisodeConfig::default(),
                sensor: Default::default(),
                termination: Termination::Oracle,
                user_plan: None,
            };
            let t = record_episode(&spec, policy);
            bar.inc(1);
            let turned = |a| t.steps.iter().any(|s| s.action == a);
            (
                episode_sums(&t),
                t.outcome.recognised,
                [turned(Action::RotateLeft), turned(Action::RotateRight)],
            )
        })
        .collect();
    bar.finish_and_clear();
    let (mut measure, mut rotate) = (Acc::new(), Acc::new());
    let (mut recognised, mut rotating_episodes, mut both_directions, mut right_only) = (0, 0, 0, 0);
    for ([m, r], ok, [left, right]) in &per {
        measure.add(m);
        rotate.add(r);
        recognised += u32::from(*ok);
        rotating_episodes += u32::from(*left || *right);
        both_directions += u32::from(*left && *right);
        right_only += u32::from(!*left && *right);
    }
    AggregateReport {
        command: command.to_string(),
        policy: policy.describe(),
        rot_bins: opts.rot_bins,
        plans: opts.plans,
        first_seed: opts.first_seed,
        episode_seed: opts.episode_seed,
        recognised,
        rotating_episodes,
        both_directions,
        right_only,
        radial_edges: RADIAL_EDGES
            .iter()
            .map(|e| e.is_finite().then_some(*e))
            .collect(),
        measure: measure.finish(),
        rotate: rotate.finish(),
    }
}

// ---------------------------------------------------------------------------------------
// Pictures

/// Viridis sampled at 9 points (the page uses the same ramp).
const VIRIDIS: [[f32; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 44.0, 122.0],
    [59.0, 81.0, 139.0],
    [44.0, 113.0, 142.0],
    [33.0, 144.0, 141.0],
    [39.0, 173.0, 129.0],
    [92.0, 200.0, 99.0],
    [170.0, 220.0, 50.0],
    [253.0, 231.0, 37.0],
];

fn viridis(v: f32) -> String {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = v * (VIRIDIS.len() - 1) as f32;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let c = |j: usize| (a[j] + f * (b[j] - a[j])).round() as u8;
    format!("#{:02x}{:02x}{:02x}", c(0), c(1), c(2))
}

/// One heat-map panel: `side²` values `[y][x]` (y up), scaled by their own maximum, at
/// `(x0, y0)`, `px` pixels per cell; `mark` draws a ring around one cell.
fn panel(
    s: &mut String,
    title: &str,
    map: &[f32],
    side: usize,
    (x0, y0): (f32, f32),
    px: f32,
    mark: Option<(usize, usize)>,
) -> f32 {
    let max = map.iter().copied().fold(0.0f32, f32::max);
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" font-weight="bold">{title}</text>"#,
        x0,
        y0 - 8.0
    );
    // Cells in unit coordinates inside a scaled group; zero cells are the background.
    let _ = writeln!(
        s,
        r#"<g transform="translate({x0:.2} {y0:.2}) scale({px:.4})"><rect width="{side}" height="{side}" fill="{}"/>"#,
        viridis(0.0)
    );
    for y in 0..side {
        for x in 0..side {
            let v = if max > 0.0 {
                map[y * side + x] / max
            } else {
                0.0
            };
            let fill = viridis(v);
            if fill != viridis(0.0) {
                let _ = writeln!(
                    s,
                    r#"<rect x="{x}" y="{}" width="1" height="1" fill="{fill}"/>"#,
                    side - 1 - y
                );
            }
        }
    }
    s.push_str("</g>\n");
    if let Some((mx, my)) = mark {
        let _ = writeln!(
            s,
            r##"<circle cx="{:.1}" cy="{:.1}" r="{:.1}" fill="none" stroke="#ff4081" stroke-width="2"/>"##,
            x0 + (mx as f32 + 0.5) * px,
            y0 + (side as f32 - 1.0 - my as f32 + 0.5) * px,
            2.0 * px
        );
    }
    max
}

fn colour_bar(s: &mut String, x0: f32, y0: f32, w: f32) {
    for i in 0..100 {
        let _ = writeln!(
            s,
            r#"<rect x="{:.2}" y="{y0:.1}" width="{:.2}" height="12" fill="{}"/>"#,
            x0 + i as f32 * w / 100.0,
            w / 100.0 + 0.05,
            viridis(i as f32 / 99.0)
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{x0:.1}" y="{:.1}">0</text><text x="{:.1}" y="{:.1}" text-anchor="end">panel maximum</text>"#,
        y0 + 26.0,
        x0 + w,
        y0 + 26.0
    );
}

/// Three panels side by side (mean belief, measure, rotate), Fig. 4's layout.
fn figure(
    title: &str,
    note: &str,
    maps: [(&str, &[f32]); 3],
    side: usize,
    mark: Option<(usize, usize)>,
) -> String {
    let px = 270.0 / side as f32;
    let (w, h) = (3.0 * 270.0 + 4.0 * 30.0, 270.0 + 130.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="13" shape-rendering="crispEdges">"#
    );
    let _ = writeln!(s, r##"<rect width="100%" height="100%" fill="#ffffff"/>"##);
    let _ = writeln!(
        s,
        r#"<text x="30" y="22" font-size="15" font-weight="bold">{}</text>"#,
        super::html_escape(title)
    );
    for (i, (name, map)) in maps.iter().enumerate() {
        let x0 = 30.0 + i as f32 * 300.0;
        let max = panel(&mut s, name, map, side, (x0, 60.0), px, mark);
        let _ = writeln!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="11">max {max:.3}</text>"#,
            x0,
            60.0 + 270.0 + 16.0
        );
    }
    colour_bar(&mut s, 30.0, 60.0 + 270.0 + 28.0, 270.0);
    let _ = writeln!(
        s,
        r#"<text x="330" y="{:.1}" font-size="11">{}</text>"#,
        60.0 + 270.0 + 40.0,
        super::html_escape(note)
    );
    s.push_str("</svg>\n");
    s
}

/// Markdown summary of the radial profile.
pub fn markdown(r: &AggregateReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Guided back-propagation over the belief, {} test plans from seed {} (K = {}, policy {}): {} episodes recognised; {} measure and {} rotate decisions ({} / {} with an all-zero map).\n",
        r.plans, r.first_seed, r.rot_bins, r.policy, r.recognised, r.measure.decisions, r.rotate.decisions, r.measure.empty_maps, r.rotate.empty_maps
    );
    let _ = writeln!(
        s,
        "Rotation directions (§5.1): of {} episodes that rotate, {} turn both left and right, {} right only, {} left only.\n",
        r.rotating_episodes,
        r.both_directions,
        r.right_only,
        r.rotating_episodes - r.both_directions - r.right_only
    );
    let _ = writeln!(s, "`{}`\n", r.command);
    s.push_str("| distance from the visual centre (placement radii) | room cells × decisions | activation, measure | activation, rotate | belief × activation, measure | belief × activation, rotate | belief, measure | belief, rotate |\n|---|---:|---:|---:|---:|---:|---:|---:|\n");
    let mut lo = 0.0;
    for (i, e) in RADIAL_EDGES.iter().enumerate() {
        let range = if e.is_finite() {
            format!("{lo:.1} – {e:.1}")
        } else {
            format!("≥ {lo:.1}")
        };
        let _ = writeln!(
            s,
            "| {range} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            r.measure.radial_cells[i] + r.rotate.radial_cells[i],
            r.measure.radial_activation[i],
            r.rotate.radial_activation[i],
            r.measure.radial_contribution[i],
            r.rotate.radial_contribution[i],
            r.measure.radial_belief[i],
            r.rotate.radial_belief[i]
        );
        lo = *e;
    }
    s
}

/// Writes `aggregate.json`, `aggregate.md`, `grid.svg` and `centred.svg` into `dir`.
pub fn write_outputs(r: &AggregateReport, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let c = S - 1;
    let files = [
        ("aggregate.json", serde_json::to_string_pretty(r)?),
        ("aggregate.md", markdown(r)),
        (
            "grid.svg",
            figure(
                &format!("Guided back-propagation over the belief grid (room bounding box), K = {}, {} test plans", r.rot_bins, r.plans),
                "each map: positive part / its max; mean over decisions",
                [
                    ("mean belief (all decisions)", &mean2(&r.measure, &r.rotate)),
                    ("measure decisions", &r.measure.grid_mean),
                    ("rotate decisions", &r.rotate.grid_mean),
                ],
                S,
                None,
            ),
        ),
        (
            "centred.svg",
            figure(
                &format!("Guided back-propagation centred on the visual centre (ring), K = {}, {} test plans", r.rot_bins, r.plans),
                "frame: cells shifted so the visual-centre cell is in the middle",
                [
                    ("mean belief (all decisions)", &centred_belief(r)),
                    ("measure decisions", &r.measure.centred_mean),
                    ("rotate decisions", &r.rotate.centred_mean),
                ],
                CENTRED,
                Some((c, c)),
            ),
        ),
    ];
    let mut out = Vec::new();
    for (name, text) in files {
        let p = dir.join(name);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
        out.push(p);
    }
    Ok(out)
}

fn mean2(a: &KindSums, b: &KindSums) -> Vec<f32> {
    let n = (a.decisions + b.decisions).max(1) as f64;
    a.acc
        .belief
        .iter()
        .zip(&b.acc.belief)
        .map(|(x, y)| ((x + y) / n) as f32)
        .collect()
}

/// Mean normalised belief per centred-frame cell over all decisions covering it (0 where
/// fewer than 5 % do).
fn centred_belief(r: &AggregateReport) -> Vec<f32> {
    let (a, b) = (&r.measure.acc, &r.rotate.acc);
    a.centred_belief
        .iter()
        .zip(&b.centred_belief)
        .zip(a.centred_n.iter().zip(&b.centred_n))
        .map(|((x, y), (n, m))| {
            let k = n + m;
            if k >= ((a.decisions + b.decisions) / 20).max(1) {
                ((x + y) / k as f64) as f32
            } else {
                0.0
            }
        })
        .collect()
}

/// `activesense inspect --aggregate`: runs the analysis, prints the table, writes the files.
pub fn cmd(
    opts: &AggregateOptions,
    policy: &LearntPolicy,
    out: &Path,
    command: &str,
) -> Result<()> {
    eprintln!(
        "aggregating guided back-propagation over {} test-plan episodes (K = {}, {})",
        opts.plans,
        opts.rot_bins,
        policy.describe()
    );
    let r = run(opts, policy, command);
    print!("{}", markdown(&r));
    for f in write_outputs(&r, out)? {
        println!("wrote {}", f.display());
    }
    Ok(())
}

impl Default for AggregateOptions {
    fn default() -> Self {
        AggregateOptions {
            plans: 200,
            first_seed: plans::TEST_SEEDS.start,
            episode_seed: 0,
            rot_bins: 1,
            progress: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use activesense_instrument::learn::agent::default_policy_path;

    #[test]
    fn aggregate_counts_every_decision_and_ignores_the_thread_count() {
        let policy = LearntPolicy::load(&default_policy_path(1), 1).unwrap();
        let opts = AggregateOptions {
            plans: 4,
            ..Default::default()
        };
        let in_pool = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| run(&opts, &policy, "test"))
        };
        let (one, two) = (in_pool(1), in_pool(2));
        assert_eq!(
            serde_json::to_string(&one).unwrap(),
            serde_json::to_string(&two).unwrap()
        );
        // Every decision of the four episodes is counted once, by the action it chose.
        let (mut measure, mut rotate) = (0, 0);
        for i in 0..4 {
            let spec = EpisodeSpec {
                plan_seed: opts.first_seed + i,
                ..EpisodeSpec::new(0, AgentKind::Learnt)
            };
            for s in record_episode(&spec, &policy).steps {
                if s.action == Action::Measure {
                    measure += 1;
                } else {
                    rotate += 1;
                }
            }
        }
        assert_eq!(
            (one.measure.decisions, one.rotate.decisions),
            (measure, rotate)
        );
        // Normalised maps: every mean lies in [0, 1], and some cell is active.
        for k in [&one.measure, &one.rotate] {
            assert!(k.grid_mean.iter().all(|v| (0.0..=1.0).contains(v)));
            assert!(k.grid_mean.iter().any(|v| *v > 0.1));
            assert!(k.radial_cells.iter().sum::<u64>() > 0);
        }
    }
}
