//! The paper's published Table 4, quoted ([`PAPER_TABLE_4`]), and the `results.md` section
//! that sets this run's numbers beside it.

use super::harness::EvalReport;
use super::stats::GroupResult;
use std::fmt::Write as _;

/// The paper's Table 4, quoted (the paper's published numbers, not ours):
/// (agent, recognition 1 bin, recognition 10 bins, pose error 1, pose error 10,
/// measurements 1, measurements 10, rotations 1, rotations 10).
pub const PAPER_TABLE_4: [(&str, [f64; 8]); 8] = [
    (
        "our approach (learnt)",
        [0.997, 0.966, 0.0541, 0.0627, 4.084, 8.524, 9.777, 26.552],
    ),
    (
        "blind-0",
        [0.987, 0.862, 0.0595, 0.1740, 5.354, 13.355, 16.214, 39.891],
    ),
    (
        "blind-1",
        [0.977, 0.794, 0.0706, 0.2549, 11.179, 27.894, 11.146, 27.941],
    ),
    (
        "blind-2",
        [0.698, 0.243, 0.2150, 0.8040, 15.468, 28.837, 30.079, 56.506],
    ),
    (
        "heuristic-0",
        [0.989, 0.891, 0.0651, 0.1525, 9.323, 24.026, 8.544, 23.429],
    ),
    (
        "heuristic-1",
        [0.994, 0.940, 0.0507, 0.0921, 3.199, 7.248, 11.539, 32.390],
    ),
    (
        "heuristic-2",
        [0.951, 0.640, 0.0644, 0.3861, 2.439, 4.577, 25.506, 65.097],
    ),
    (
        "heuristic-3",
        [0.639, 0.115, 0.2117, 0.9036, 1.713, 1.961, 54.447, 93.563],
    ),
];

/// (measurement, rotation) costs of the run, for the paper's cost column.
fn opts_costs(report: &EvalReport) -> (f64, f64) {
    let c = report.options.config.costs;
    (c.measure as f64, c.rotate as f64)
}

/// Appends "Side by side with the paper's Table 4" to `results.md`.
pub(crate) fn side_by_side(s: &mut String, report: &EvalReport) {
    let _ = writeln!(s, "## Side by side with the paper's Table 4\n");
    let _ = writeln!(
        s,
        "Format as in the paper: 1 rotation bin, (10 rotation bins) in parentheses. \"paper\" rows are the paper's \
         published numbers, quoted; \"ours\" rows come from this run.\n"
    );
    let _ = writeln!(
        s,
        "| agent | | recognition rate | pose error (m) | measurements | rotations | cost |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    let find = |agent: &str, k: u8| {
        report
            .results
            .iter()
            .find(|r| r.agent == agent && r.rot_bins == k)
    };
    let costs = opts_costs(report);
    for (name, p) in PAPER_TABLE_4.iter() {
        let _ = writeln!(
            s,
            "| {name} | paper | {:.3} ({:.3}) | {:.4} ({:.4}) | {:.3} ({:.3}) | {:.3} ({:.3}) | {:.3} ({:.3}) |",
            p[0],
            p[1],
            p[2],
            p[3],
            p[4],
            p[5],
            p[6],
            p[7],
            costs.0 * p[4] + costs.1 * p[6],
            costs.0 * p[5] + costs.1 * p[7]
        );
        let ours: &[(&str, &str)] = if name.starts_with("our approach") {
            &[("learnt", "**ours**"), ("learnt-int8", "**ours, int8**")]
        } else {
            &[(name, "**ours**")]
        };
        for (agent, label) in ours {
            let (a, b) = (find(agent, 1), find(agent, 10));
            if a.is_none() && b.is_none() {
                continue;
            }
            let f =
                |r: Option<&GroupResult>, get: &dyn Fn(&GroupResult) -> Option<f64>, d: usize| {
                    r.and_then(get)
                        .map(|v| format!("{v:.d$}"))
                        .unwrap_or_else(|| "–".into())
                };
            let _ = writeln!(
                s,
                "| | {label} | {} ({}) | {} ({}) | {} ({}) | {} ({}) | {} ({}) |",
                f(a, &|r| Some(r.recognition_rate), 3),
                f(b, &|r| Some(r.recognition_rate), 3),
                f(a, &|r| r.pose_error, 4),
                f(b, &|r| r.pose_error, 4),
                f(a, &|r| Some(r.measurements), 3),
                f(b, &|r| Some(r.measurements), 3),
                f(a, &|r| Some(r.rotations), 3),
                f(b, &|r| Some(r.rotations), 3),
                f(a, &|r| Some(r.cost), 3),
                f(b, &|r| Some(r.cost), 3),
            );
        }
    }
}
