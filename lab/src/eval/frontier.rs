//! The risk–cost frontier of the calibrated stop: the same evaluation run at
//! several `--stop-risk` settings, and per agent and rotation setting what each setting
//! costs against the wrong-answer rate it is observed to give. A surveyor picks their risk
//! from it; the *stated* column (the setting, and the mean estimate the stop claimed when it
//! stopped) beside the *observed* one (wrong answers of answered, with a Wilson interval)
//! says whether the knob means what it says, in both directions.

use super::harness::{self, EvalOptions};
use super::report::opt;
use crate::plot::{line_panels, LinePanel, Series};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;

/// One (agent, rotation setting, stop risk) point of the frontier.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrontierPoint {
    /// Agent name.
    pub agent: String,
    /// Rotation bins.
    pub rot_bins: u8,
    /// The `--stop-risk` setting: the stated largest chance of a wrong answer.
    pub stop_risk: f32,
    /// Mean calibrated estimate at the confident stops (what the stop claimed).
    pub mean_risk_at_stop: Option<f64>,
    /// Episodes answered.
    pub answered: u32,
    /// Wrong answers (outside the tolerance).
    pub wrong: u32,
    /// Observed wrong answers of answered.
    pub wrong_of_answered: f64,
    /// Its Wilson 95 % interval.
    pub wrong_of_answered_ci95: [f64; 2],
    /// Fraction of all episodes answered right.
    pub right: f64,
    /// Fraction of all episodes unanswered at the action limit.
    pub unanswered: f64,
    /// Mean measurements.
    pub measurements: f64,
    /// Mean rotations.
    pub rotations: f64,
    /// Mean cost.
    pub cost: f64,
    /// [`verdict`] of stated against observed.
    pub verdict: String,
}

/// Stated risk `p` against the observed wrong answers: "above" when the interval lies wholly
/// above `p` (the knob promises more than it gives), "far below" when it lies wholly below
/// `p / 3` (the user pays for far less risk than they asked for), "as stated" otherwise.
pub fn verdict(p: f64, ci: [f64; 2]) -> &'static str {
    if ci[0] > p {
        "above"
    } else if ci[1] < p / 3.0 {
        "far below"
    } else {
        "as stated"
    }
}

/// The whole frontier.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Frontier {
    /// The options of every run (its `stop_risk` is the first setting's).
    pub options: EvalOptions,
    /// The settings, in run order.
    pub stop_risks: Vec<f32>,
    /// One point per (setting, agent, rotation setting), settings outer.
    pub points: Vec<FrontierPoint>,
}

/// Runs `opts` (termination confident) once per setting of `risks`.
pub fn run(opts: &EvalOptions, risks: &[f32]) -> Frontier {
    let mut points = Vec::new();
    for &p in risks {
        let mut o = opts.clone();
        o.config.stop_risk = p;
        eprintln!("frontier: --stop-risk {p}");
        let (report, _) = harness::run(&o);
        for r in &report.results {
            let a = &r.answers;
            points.push(FrontierPoint {
                agent: r.agent.clone(),
                rot_bins: r.rot_bins,
                stop_risk: p,
                mean_risk_at_stop: r.mean_risk_at_stop,
                answered: a.answered,
                wrong: a.wrong,
                wrong_of_answered: a.wrong_of_answered,
                wrong_of_answered_ci95: a.wrong_of_answered_ci95,
                right: a.right,
                unanswered: a.unanswered,
                measurements: r.measurements,
                rotations: r.rotations,
                cost: r.cost,
                verdict: verdict(p as f64, a.wrong_of_answered_ci95).to_string(),
            });
        }
    }
    Frontier {
        options: opts.clone(),
        stop_risks: risks.to_vec(),
        points,
    }
}

/// `frontier.md`: one table per rotation setting, agents outer, settings inner.
pub fn markdown(f: &Frontier, command: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Risk–cost frontier of the calibrated stop\n");
    let _ = writeln!(s, "Produced by `{command}`.\n");
    let t = &f.options.tolerance;
    let _ = writeln!(
        s,
        "{} plans from seed {}, episode seed {}; an answer is wrong when its pose is outside {:.1} cm / {:.2}° of the truth \
         (modulo symmetry). *Stated*: the `--stop-risk` setting and the mean estimate the stop claimed when it stopped; \
         *observed*: wrong answers of answered, with the Wilson 95 % interval. Verdict: `above` when the interval lies \
         wholly above the setting, `far below` when wholly below a third of it, else `as stated`. `frontier.svg` plots it.\n",
        f.options.plans,
        f.options.first_seed,
        f.options.episode_seed,
        100.0 * t.position_m,
        t.heading_rad.to_degrees()
    );
    for &k in &f.options.rot_bins {
        let _ = writeln!(s, "## K = {k}\n");
        let _ = writeln!(
            s,
            "| agent | stated risk | mean estimate at stop | observed wrong (of answered) [95% CI] | verdict | right | unanswered | measurements | rotations | cost |\n|---|---|---|---|---|---|---|---|---|---|"
        );
        for a in &f.options.agents {
            for p in f
                .points
                .iter()
                .filter(|p| p.rot_bins == k && p.agent == a.name())
            {
                let _ = writeln!(
                    s,
                    "| {} | {:.1} % | {} | {} of {} ({:.2} %) [{:.2}, {:.2}] | {} | {:.3} | {:.3} | {:.2} | {:.2} | {:.3} |",
                    p.agent,
                    100.0 * p.stop_risk,
                    opt(p.mean_risk_at_stop.map(|r| 100.0 * r), 2) + " %",
                    p.wrong,
                    p.answered,
                    100.0 * p.wrong_of_answered,
                    100.0 * p.wrong_of_answered_ci95[0],
                    100.0 * p.wrong_of_answered_ci95[1],
                    p.verdict,
                    p.right,
                    p.unanswered,
                    p.measurements,
                    p.rotations,
                    p.cost
                );
            }
        }
        let _ = writeln!(s);
    }
    s
}

/// `frontier.svg`: per rotation setting, cost against observed wrong answers (one line per
/// agent through its settings), and observed against stated risk with the diagonal.
pub fn svg(f: &Frontier) -> String {
    let mut panels = Vec::new();
    for &k in &f.options.rot_bins {
        let of = |a: &str| -> Vec<&FrontierPoint> {
            f.points
                .iter()
                .filter(|p| p.rot_bins == k && p.agent == a)
                .collect()
        };
        let names: Vec<&str> = f.options.agents.iter().map(|a| a.name()).collect();
        let max_wrong = f
            .points
            .iter()
            .filter(|p| p.rot_bins == k)
            .map(|p| 100.0 * p.wrong_of_answered)
            .fold(0.0f64, f64::max);
        let max_cost = f
            .points
            .iter()
            .filter(|p| p.rot_bins == k)
            .map(|p| p.cost)
            .fold(0.0f64, f64::max);
        let max_stated = f
            .stop_risks
            .iter()
            .map(|&p| 100.0 * p as f64)
            .fold(0.0f64, f64::max);
        panels.push(LinePanel {
            title: format!("K = {k}: cost against wrong answers"),
            xlabel: "observed wrong answers (% of answered)".into(),
            ylabel: "cost per episode".into(),
            x: (0.0, (1.1 * max_wrong).max(1.0)),
            y: (0.0, 1.1 * max_cost),
            series: names
                .iter()
                .map(|&n| Series {
                    name: n.to_string(),
                    points: of(n)
                        .iter()
                        .map(|p| (100.0 * p.wrong_of_answered, Some(p.cost)))
                        .collect(),
                })
                .collect(),
        });
        let top = max_stated.max(max_wrong).max(1.0);
        let mut series: Vec<Series> = names
            .iter()
            .map(|&n| Series {
                name: n.to_string(),
                points: of(n)
                    .iter()
                    .map(|p| {
                        (
                            100.0 * p.stop_risk as f64,
                            Some(100.0 * p.wrong_of_answered),
                        )
                    })
                    .collect(),
            })
            .collect();
        series.push(Series {
            name: "observed = stated".into(),
            points: vec![(0.0, Some(0.0)), (top, Some(top))],
        });
        panels.push(LinePanel {
            title: format!("K = {k}: observed against stated risk"),
            xlabel: "stated risk, --stop-risk (%)".into(),
            ylabel: "observed wrong answers (%)".into(),
            x: (0.0, top),
            y: (0.0, top),
            series,
        });
    }
    line_panels("Risk–cost frontier of the calibrated stop", &panels, 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts() {
        // 1 % stated: an interval wholly above is "above"; wholly below 0.33 % is "far below".
        assert_eq!(verdict(0.01, [0.012, 0.03]), "above");
        assert_eq!(verdict(0.01, [0.0, 0.003]), "far below");
        assert_eq!(verdict(0.01, [0.002, 0.012]), "as stated");
        assert_eq!(verdict(0.01, [0.0, 0.0038]), "as stated");
    }
}
