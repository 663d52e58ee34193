//! The evaluation's files: `results.md` (the Table-4 layout with 95 % intervals, Perf(π),
//! reliability and calibrated-stop tables, the paper side by side), and [`write_outputs`],
//! which writes it with results.json, timing.json and the charts (drawn by
//! [`crate::plot`] from the report's numbers).

use super::harness::{EvalOptions, EvalReport, Timing};
use super::paper;
use super::record::{CURVE_MAX_COST, MAX_BUDGET};
use super::stats::{RELIABILITY_BINS, RELIABILITY_MIN_EPISODES};
use crate::plot::{self, BudgetLine, ReliabilityLine, UtilityLine};
use activesense_instrument::episode::Termination;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::PathBuf;

/// β values of the Perf(π) = U + β·C table (eq. 15).
pub const PERF_BETAS: [f64; 4] = [-0.25, -0.5, -1.0, -2.0];

pub(crate) fn opt(x: Option<f64>, digits: usize) -> String {
    x.map(|v| format!("{v:.digits$}"))
        .unwrap_or_else(|| "–".into())
}

/// "N plans from seed S", or the user's rooms by name.
pub(crate) fn plan_source(o: &EvalOptions) -> String {
    if o.user_plans.is_empty() {
        return format!("{} plans from seed {}", o.plans, o.first_seed);
    }
    let names: Vec<&str> = o.user_plans.iter().map(|p| p.name.as_str()).collect();
    format!("{} user plans ({})", names.len(), names.join(", "))
}

/// Renders `results.md`.
pub fn markdown(report: &EvalReport, timing: &Timing, command: &str) -> String {
    let o = &report.options;
    let mut s = String::new();
    let _ = writeln!(s, "# Evaluation results\n");
    let _ = writeln!(s, "Produced by `{command}`.\n");
    let _ = writeln!(
        s,
        "{}, episode seed {}, action limit {}, rotation step 360°/{}, termination `{:?}`; \
         EDM σ = {} m, outliers {:.0} %, max range {} m, max incidence {:.0}°. \
         Wall time {:.1} s on {} threads.\n",
        plan_source(o),
        o.episode_seed,
        o.config.max_actions,
        o.config.steps_per_turn,
        o.termination,
        o.sensor.sigma,
        o.sensor.outlier_prob * 100.0,
        o.sensor.max_range,
        o.sensor.max_incidence.to_degrees(),
        timing.total_s,
        timing.threads
    );
    if !o.refused_plans.is_empty() {
        let _ = writeln!(s, "Plan files refused (not evaluated):\n");
        for r in &o.refused_plans {
            let _ = writeln!(s, "- {r}");
        }
        let _ = writeln!(s);
    }
    for &k in &o.rot_bins {
        let _ = writeln!(
            s,
            "## {} rotation bin{}\n",
            k,
            if k == 1 { " (heading known)" } else { "s" }
        );
        let _ = writeln!(
            s,
            "| agent | recognition rate [95% CI] | pose error (m) [95% CI] | median pose error (m) | p95 pose error (m) | pose error, all episodes (m) | coarse error (m) | measurements [95% CI] | rotations [95% CI] | cost | repeated bearings | episode time (s) | time per decision (ms) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for (g, r) in report
            .results
            .iter()
            .enumerate()
            .filter(|(_, r)| r.rot_bins == k)
        {
            let _ = writeln!(
                s,
                "| {} | {:.3} [{:.3}, {:.3}] | {} [{}, {}] | {} | {} | {} | {} | {:.2} [{:.2}, {:.2}] | {:.2} [{:.2}, {:.2}] | {:.3} | {:.2} | {:.1} | {:.3} |",
                r.agent,
                r.recognition_rate,
                r.recognition_ci95[0],
                r.recognition_ci95[1],
                opt(r.pose_error, 4),
                opt(r.pose_error_ci95.map(|c| c[0]), 4),
                opt(r.pose_error_ci95.map(|c| c[1]), 4),
                opt(r.pose_error_median, 4),
                opt(r.pose_error_p95, 4),
                opt(r.pose_error_all, 4),
                opt(r.coarse_error, 3),
                r.measurements,
                r.measurements_ci95[0],
                r.measurements_ci95[1],
                r.rotations,
                r.rotations_ci95[0],
                r.rotations_ci95[1],
                r.cost,
                r.repeated_bearing_fraction,
                timing.group_episode_s.get(g).copied().unwrap_or(0.0),
                timing.group_decision_ms.get(g).copied().unwrap_or(0.0)
            );
        }
        let _ = writeln!(s);
        perf_table(&mut s, report, k);
        reliability_table(&mut s, report, k);
        if o.termination == Termination::Confident {
            answer_table(&mut s, report, k);
        }
    }
    paper::side_by_side(&mut s, report);
    s
}

/// The Perf(π) = U + β·C table (eq. 15) of one rotation setting: U the recognition rate,
/// C the mean action cost per episode, β < 0 the price of a unit of cost.
fn perf_table(s: &mut String, report: &EvalReport, k: u8) {
    let _ = writeln!(
        s,
        "Perf(π) = U + β·C (eq. 15) with U = recognition rate and C = mean action cost per episode, for a few β \
         (how much recognition one unit of cost is worth); utility-vs-cost curves in `utility-k{k}.svg`.\n"
    );
    let mut head = String::from("| agent | U | C |");
    let mut rule = String::from("|---|---|---|");
    for b in PERF_BETAS {
        let _ = write!(head, " β = {b} |");
        rule.push_str("---|");
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        let mut line = format!(
            "| {} | {:.3} | {:.3} |",
            r.agent, r.recognition_rate, r.cost
        );
        for b in PERF_BETAS {
            let _ = write!(line, " {:.3} |", r.recognition_rate + b * r.cost);
        }
        let _ = writeln!(s, "{line}");
    }
    let _ = writeln!(s);
}

/// What the instrument answered by itself, per agent, judged by the surveyor's tolerance
/// (`--tolerance`): the no-oracle table. Also the calibrated stop's own record (wrong stops
/// by the grid cell, the estimated risk it claimed), for continuity with the cell-based
/// recognition.
pub(crate) fn answer_table(s: &mut String, report: &EvalReport, k: u8) {
    let a = report.results.first().map(|r| &r.answers);
    let (m, d) = a.map_or((0.0, 0.0), |a| (a.tolerance_m, a.tolerance_deg));
    let _ = writeln!(
        s,
        "Answers without an oracle (termination `{:?}`, `--stop-risk {}`): an episode is answered when the rule \
         stopped it, unanswered when it reached the action limit; an answer is right when its pose is within \
         {:.1} cm and {:.2}° of the truth (modulo the room's symmetry). Pose errors are of the right answers. \
         Wrong stops (of stops) count by the grid cell, as recognition does.\n",
        report.options.termination,
        report.options.config.stop_risk,
        100.0 * m,
        d
    );
    let _ = writeln!(
        s,
        "| agent | right [95% CI] | wrong (of answered) [95% CI] | unanswered | measurements | rotations | cost | position error mean / median / p95 (m) | heading error mean (°) | recognition (cell) | wrong stops, cell (of stops) | mean estimated risk at stop |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        let a = &r.answers;
        let _ = writeln!(
            s,
            "| {} | {:.3} [{:.3}, {:.3}] | {} ({:.4}) [{:.4}, {:.4}] | {:.3} | {:.2} | {:.2} | {:.3} | {} / {} / {} | {} | {:.3} | {} ({:.4}) | {} |",
            r.agent,
            a.right,
            a.right_ci95[0],
            a.right_ci95[1],
            a.wrong,
            a.wrong_of_answered,
            a.wrong_of_answered_ci95[0],
            a.wrong_of_answered_ci95[1],
            a.unanswered,
            r.measurements,
            r.rotations,
            r.cost,
            opt(a.right_position_error, 4),
            opt(a.right_position_error_median, 4),
            opt(a.right_position_error_p95, 4),
            opt(a.right_heading_error_deg, 3),
            r.recognition_rate,
            r.wrong_stops,
            r.wrong_stops as f64 / r.stops.max(1) as f64,
            opt(r.mean_risk_at_stop, 4),
        );
    }
    let _ = writeln!(s);
}

/// Stated confidence against observed recognition per agent (`reliability-k{K}.svg` has
/// the diagram).
fn reliability_table(s: &mut String, report: &EvalReport, k: u8) {
    let _ = writeln!(
        s,
        "Reliability of the final belief's stated confidence (peak mass around the argmax) against recognition; \
         diagram in `reliability-k{k}.svg`. ECE = expected calibration error over {RELIABILITY_BINS} bins.\n"
    );
    let _ = writeln!(
        s,
        "| agent | mean stated confidence | observed recognition | ECE |\n|---|---|---|---|"
    );
    for r in report.results.iter().filter(|r| r.rot_bins == k) {
        let _ = writeln!(
            s,
            "| {} | {:.3} | {:.3} | {:.3} |",
            r.agent, r.reliability.mean_stated, r.recognition_rate, r.reliability.ece
        );
    }
    let _ = writeln!(s);
}

/// Writes results.json, results.md, timing.json and budget.svg into `out`.
pub fn write_outputs(
    report: &EvalReport,
    timing: &Timing,
    out: &std::path::Path,
    command: &str,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut files = vec![
        (
            "results.json".to_string(),
            serde_json::to_string_pretty(report)? + "\n",
        ),
        ("results.md".to_string(), markdown(report, timing, command)),
        (
            "timing.json".to_string(),
            serde_json::to_string_pretty(timing)? + "\n",
        ),
        ("budget.svg".to_string(), budget_svg(report)),
    ];
    for &k in &report.options.rot_bins {
        files.push((format!("utility-k{k}.svg"), utility_svg(report, k)));
        files.push((format!("reliability-k{k}.svg"), reliability_svg(report, k)));
    }
    let mut written = Vec::new();
    for (name, body) in files {
        let p = out.join(name);
        std::fs::write(&p, body).with_context(|| format!("cannot write {}", p.display()))?;
        written.push(p);
    }
    Ok(written)
}

/// `budget.svg` from the report's per-budget numbers.
pub fn budget_svg(report: &EvalReport) -> String {
    let agents: Vec<String> = report
        .options
        .agents
        .iter()
        .map(|a| a.name().to_string())
        .collect();
    let lines: Vec<BudgetLine<'_>> = report
        .results
        .iter()
        .map(|r| BudgetLine {
            agent: &r.agent,
            rot_bins: r.rot_bins,
            recognition: &r.recognition_by_budget,
            pose_error: &r.pose_error_by_budget,
        })
        .collect();
    plot::budget_svg(
        report.options.plans,
        MAX_BUDGET,
        &report.options.rot_bins,
        &agents,
        &lines,
    )
}

/// `utility-k{k}.svg` from the utility curves of rotation setting `k`.
pub fn utility_svg(report: &EvalReport, k: u8) -> String {
    let groups: Vec<_> = report.results.iter().filter(|r| r.rot_bins == k).collect();
    let lines: Vec<UtilityLine<'_>> = groups
        .iter()
        .map(|r| UtilityLine {
            agent: &r.agent,
            cost: &r.curve.cost,
            entropy: &r.curve.entropy,
            recognition: &r.curve.recognition,
            pose_error: &r.curve.pose_error,
        })
        .collect();
    let plans = groups.first().map(|r| r.plans).unwrap_or(0);
    let reg_plans = groups
        .first()
        .map(|r| r.curve.pose_error_plans)
        .unwrap_or(0);
    plot::utility_svg(k, plans, reg_plans, CURVE_MAX_COST, &lines)
}

/// `reliability-k{k}.svg` from the reliability bins of rotation setting `k`.
pub fn reliability_svg(report: &EvalReport, k: u8) -> String {
    let lines: Vec<ReliabilityLine<'_>> = report
        .results
        .iter()
        .filter(|r| r.rot_bins == k)
        .map(|r| ReliabilityLine {
            agent: &r.agent,
            stated: &r.reliability.stated,
            observed: &r.reliability.observed,
            episodes: &r.reliability.episodes,
        })
        .collect();
    plot::reliability_svg(
        k,
        &format!("{:?}", report.options.termination),
        RELIABILITY_MIN_EPISODES,
        &lines,
    )
}
