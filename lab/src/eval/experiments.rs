//! The extra-measurements experiment (`eval --extra-measurements N`, paper §4.3's to-do):
//! follow every episode past its minimal set and register after each further range; writes
//! extra.json, extra.md and extra.svg.

use super::harness::{episode_bar, groups_and_jobs, EvalOptions};
use super::report::{opt, plan_source};
use super::stats::{quantile, MeanCi};
use crate::plot::{self, ExtraLine};
use activesense_instrument::agents::run_agent_episode_observed;
use activesense_instrument::episode::{score, EpisodeView, Termination};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// Pose error after each measurement beyond the minimal set (paper §4.3's to-do: "how the
/// final registration error changes with each new measurement action performed after a
/// minimal set"). The minimal set of an episode is the ranges it had when the oracle rule
/// would have stopped it (coarse success with the pipeline's minimum number of ranges);
/// the episode then goes on with the same agent, and the pipeline registers after every
/// further range.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExtraReport {
    /// Options it ran with (termination is overridden to the action limit).
    pub options: EvalOptions,
    /// Extra measurements followed.
    pub extra: usize,
    /// One entry per (agent, rot_bins).
    pub results: Vec<ExtraGroup>,
}

/// One agent and rotation setting of [`ExtraReport`].
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExtraGroup {
    /// Agent name.
    pub agent: String,
    /// Rotation bins.
    pub rot_bins: u8,
    /// Episodes that reached the minimal set (oracle stop) within the action limit.
    pub stopped: u32,
    /// Mean size of the minimal set (ranges).
    pub minimal_set: f64,
    /// Per extra measurement `j = 0..=extra`: episodes that got that far.
    pub episodes: Vec<u32>,
    /// Mean pose error after `j` extra ranges (m).
    pub mean: Vec<Option<f64>>,
    /// Median pose error (m).
    pub median: Vec<Option<f64>>,
    /// 90th percentile (m).
    pub p90: Vec<Option<f64>>,
    /// Fraction of those episodes whose belief argmax is still a coarse success.
    #[serde(default)]
    pub still_recognised: Vec<f64>,
    /// Mean pose error over the episodes still recognised (m).
    #[serde(default)]
    pub mean_still_recognised: Vec<Option<f64>>,
}

/// Follows one episode for [`extra_measurements`].
struct ExtraRecorder {
    extra: usize,
    minimal: Option<usize>,
    /// (pose error, argmax still a coarse success) after each registration.
    errors: Vec<(f32, bool)>,
}

impl ExtraRecorder {
    fn observe(&mut self, v: EpisodeView<'_>) {
        let Some(step) = v.step else { return };
        let pipe = v.runner.pipeline();
        let ranges = pipe.observations().len();
        let register = match self.minimal {
            None if step.coarse_success && ranges >= pipe.min_measurements() => {
                self.minimal = Some(ranges);
                true
            }
            Some(_) => step.range.is_some() && self.errors.len() <= self.extra,
            None => false,
        };
        if register {
            // A registered episode has a pose; without one there is nothing to follow.
            if let Some(e) = score(v.plan, v.truth, &v.runner.finish(v.plan)).pose_error {
                self.errors.push((e, step.coarse_success));
            }
        }
    }
}

/// One followed episode: group, minimal-set size, (error, still recognised) per registration.
type ExtraRow = (usize, Option<usize>, Vec<(f32, bool)>);

/// Runs the extra-measurement analysis (termination forced to the action limit).
pub fn extra_measurements(opts: &EvalOptions, extra: usize) -> ExtraReport {
    let (groups, jobs) = groups_and_jobs(opts);
    let bar = episode_bar(jobs.len() as u64, opts.progress);
    let rows: Vec<ExtraRow> = jobs
        .par_iter()
        .map(|&(g, i)| {
            let (agent, rot_bins) = groups[g];
            let spec = opts.spec(agent, rot_bins, i, Termination::ActionLimit);
            let mut rec = ExtraRecorder {
                extra,
                minimal: None,
                errors: Vec::new(),
            };
            run_agent_episode_observed(&spec, &opts.policies, &mut |v| rec.observe(v))
                .expect("policy loaded for every K");
            bar.inc(1);
            (g, rec.minimal, rec.errors)
        })
        .collect();
    bar.finish_and_clear();
    let results = groups
        .iter()
        .enumerate()
        .map(|(g, &(a, k))| {
            let mine: Vec<&ExtraRow> = rows.iter().filter(|r| r.0 == g).collect();
            let stopped: Vec<usize> = mine.iter().filter_map(|r| r.1).collect();
            let mut out = ExtraGroup {
                agent: a.name().to_string(),
                rot_bins: k,
                stopped: stopped.len() as u32,
                minimal_set: stopped.iter().sum::<usize>() as f64 / stopped.len().max(1) as f64,
                episodes: Vec::new(),
                mean: Vec::new(),
                median: Vec::new(),
                p90: Vec::new(),
                still_recognised: Vec::new(),
                mean_still_recognised: Vec::new(),
            };
            for j in 0..=extra {
                let at_j: Vec<(f32, bool)> =
                    mine.iter().filter_map(|r| r.2.get(j).copied()).collect();
                let kept: Vec<f64> = at_j.iter().filter(|x| x.1).map(|x| x.0 as f64).collect();
                out.still_recognised
                    .push(kept.len() as f64 / at_j.len().max(1) as f64);
                out.mean_still_recognised
                    .push(MeanCi::of(&kept).map(|m| m.mean));
                let mut e: Vec<f64> = at_j.iter().map(|x| x.0 as f64).collect();
                e.sort_by(f64::total_cmp);
                out.episodes.push(e.len() as u32);
                out.mean.push(MeanCi::of(&e).map(|m| m.mean));
                out.median.push(quantile(&e, 0.5));
                out.p90.push(quantile(&e, 0.9));
            }
            out
        })
        .collect();
    ExtraReport {
        options: opts.clone(),
        extra,
        results,
    }
}

/// `extra.md`: one table per rotation setting.
pub fn extra_markdown(r: &ExtraReport, command: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Pose error after each measurement beyond the minimal set\n"
    );
    let _ = writeln!(s, "Produced by `{command}`.\n");
    let _ = writeln!(
        s,
        "{}, action limit {}. The minimal set is the ranges an episode had when the oracle rule \
         would have stopped it; the agent then carries on and the pipeline registers after every further range. \
         Cells: mean / median / p90 pose error (m) over the episodes that got that far (their number in the last \
         column group).\n",
        plan_source(&r.options),
        r.options.config.max_actions
    );
    for &k in &r.options.rot_bins {
        let _ = writeln!(s, "## K = {k}\n");
        let groups: Vec<&ExtraGroup> = r.results.iter().filter(|g| g.rot_bins == k).collect();
        let mut head = String::from("| extra ranges |");
        let mut rule = String::from("|---|");
        for g in &groups {
            let _ = write!(head, " {} (minimal set {:.2}) |", g.agent, g.minimal_set);
            rule.push_str("---|");
        }
        let table = |s: &mut String, cell: &dyn Fn(&ExtraGroup, usize) -> String| {
            let _ = writeln!(s, "{head}\n{rule}");
            for j in 0..=r.extra {
                let mut line = format!("| +{j} |");
                for g in &groups {
                    let _ = write!(line, " {} |", cell(g, j));
                }
                let _ = writeln!(s, "{line}");
            }
            let _ = writeln!(s);
        };
        table(&mut s, &|g, j| {
            format!(
                "{} / {} / {} (n = {})",
                opt(g.mean[j], 4),
                opt(g.median[j], 4),
                opt(g.p90[j], 4),
                g.episodes[j]
            )
        });
        let _ = writeln!(
            s,
            "Still recognised (the belief argmax is still a coarse success) / mean pose error over those (m):\n"
        );
        table(&mut s, &|g, j| {
            format!(
                "{:.3} / {}",
                g.still_recognised.get(j).copied().unwrap_or(0.0),
                opt(g.mean_still_recognised.get(j).copied().flatten(), 4)
            )
        });
    }
    s
}

/// `extra.svg` from the report's mean and median pose errors.
pub fn extra_svg(r: &ExtraReport) -> String {
    let lines: Vec<ExtraLine<'_>> = r
        .results
        .iter()
        .map(|g| ExtraLine {
            agent: &g.agent,
            rot_bins: g.rot_bins,
            mean: &g.mean,
            median: &g.median,
        })
        .collect();
    plot::extra_svg(r.options.plans, r.extra, &r.options.rot_bins, &lines)
}
