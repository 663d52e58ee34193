//! The evaluation's line charts, drawn from plain numbers (the caller, [`crate::eval`],
//! picks them out of its report): the utility-vs-cost curves (`utility-k{K}.svg`), the
//! reliability diagram (`reliability-k{K}.svg`) and the pose error past the minimal set
//! (`extra.svg`). All three are [`line_panels`] charts.

use super::{line_panels, LinePanel, Series};

/// One agent's utility-vs-cost curves: mean belief entropy, recognition and pose error at
/// each accumulated cost.
pub struct UtilityLine<'a> {
    /// Legend label (the agent).
    pub agent: &'a str,
    /// Accumulated cost of each point.
    pub cost: &'a [f64],
    /// Mean belief entropy (nats) at each point.
    pub entropy: &'a [f64],
    /// Fraction of episodes recognised at each point.
    pub recognition: &'a [f64],
    /// Mean pose error of the recognised episodes at each point (`None`: none yet).
    pub pose_error: &'a [Option<f64>],
}

/// The utility-vs-cost curves of rotation setting `k` over `plans` plans (the pose error over
/// the first `pose_error_plans`), costs up to `max_cost`, one line per agent.
pub fn utility_svg(
    k: u8,
    plans: u32,
    pose_error_plans: u32,
    max_cost: f64,
    lines: &[UtilityLine<'_>],
) -> String {
    let series = |get: &dyn Fn(&UtilityLine<'_>, usize) -> Option<f64>| -> Vec<Series> {
        lines
            .iter()
            .map(|r| Series {
                name: r.agent.to_string(),
                points: (0..r.cost.len()).map(|i| (r.cost[i], get(r, i))).collect(),
            })
            .collect()
    };
    let hmax = lines
        .iter()
        .flat_map(|r| r.entropy.iter().copied())
        .fold(0.0f64, f64::max)
        .ceil();
    let emax = {
        let mut all: Vec<f64> = lines
            .iter()
            .flat_map(|r| r.pose_error.iter().flatten().copied())
            .collect();
        all.sort_by(f64::total_cmp);
        let p90 = all.get(all.len() * 9 / 10).copied().unwrap_or(0.1);
        [0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0]
            .into_iter()
            .find(|v| *v >= p90)
            .unwrap_or(10.0)
    };
    let xlabel = "accumulated action cost (measurement 0.05, rotation 0.005)".to_string();
    let panels = vec![
        LinePanel {
            title: "mean belief entropy".into(),
            xlabel: xlabel.clone(),
            ylabel: "entropy (nats)".into(),
            x: (0.0, max_cost),
            y: (0.0, hmax.max(1.0)),
            series: series(&|c, i| Some(c.entropy[i])),
        },
        LinePanel {
            title: "recognition (coarse success so far)".into(),
            xlabel: xlabel.clone(),
            ylabel: "fraction of episodes".into(),
            x: (0.0, max_cost),
            y: (0.0, 1.0),
            series: series(&|c, i| Some(c.recognition[i])),
        },
        LinePanel {
            title: format!("pose error of recognised ({pose_error_plans} plans)"),
            xlabel,
            ylabel: "mean pose error (m)".into(),
            x: (0.0, max_cost),
            y: (0.0, emax),
            series: series(&|c, i| c.pose_error[i]),
        },
    ];
    let tag = if k == 1 {
        "1 rotation bin (heading known)".to_string()
    } else {
        format!("{k} rotation bins")
    };
    line_panels(
        &format!("Utility against cost, {tag}, {plans} plans"),
        &panels,
        3,
    )
}

/// One agent's reliability diagram: per confidence bin, the episodes in it, their mean
/// stated confidence and the fraction recognised (`None` for an empty bin).
pub struct ReliabilityLine<'a> {
    /// Legend label (the agent).
    pub agent: &'a str,
    /// Mean stated confidence per bin.
    pub stated: &'a [Option<f64>],
    /// Fraction recognised per bin.
    pub observed: &'a [Option<f64>],
    /// Episodes per bin.
    pub episodes: &'a [u32],
}

/// The reliability diagram of rotation setting `k` (`termination` names the rule in the
/// title), one line per agent over the bins with at least `min_episodes` episodes.
pub fn reliability_svg(
    k: u8,
    termination: &str,
    min_episodes: u32,
    lines: &[ReliabilityLine<'_>],
) -> String {
    let mut series = vec![Series {
        name: "calibrated (stated = observed)".into(),
        points: vec![(0.0, Some(0.0)), (1.0, Some(1.0))],
    }];
    for r in lines {
        series.push(Series {
            name: r.agent.to_string(),
            points: r
                .stated
                .iter()
                .zip(r.observed)
                .zip(r.episodes)
                .filter(|(_, &n)| n >= min_episodes)
                .filter_map(|((s, o), _)| s.map(|s| (s, *o)))
                .collect(),
        });
    }
    let tag = if k == 1 {
        "1 rotation bin"
    } else {
        "10 rotation bins"
    };
    line_panels(
        &format!("Final belief's confidence vs correctness, {tag}, termination {termination}"),
        &[LinePanel {
            title: format!("bins with ≥ {min_episodes} episodes"),
            xlabel: "stated confidence: final belief's peak mass (bin mean)".into(),
            ylabel: "fraction of episodes recognised".into(),
            x: (0.0, 1.0),
            y: (0.0, 1.0),
            series,
        }],
        1,
    )
}

/// One agent and rotation setting of the extra-measurements chart: mean and median pose
/// error after `j = 0..=extra` ranges past the minimal set.
pub struct ExtraLine<'a> {
    /// Legend label (the agent).
    pub agent: &'a str,
    /// Rotation bins.
    pub rot_bins: u8,
    /// Mean pose error after `j` extra ranges (m).
    pub mean: &'a [Option<f64>],
    /// Median pose error after `j` extra ranges (m).
    pub median: &'a [Option<f64>],
}

/// `extra.svg`: mean and median pose error against extra ranges, a row of two panels per
/// rotation setting in `settings`, over `plans` plans.
pub fn extra_svg(plans: u32, extra: usize, settings: &[u8], lines: &[ExtraLine<'_>]) -> String {
    let mut panels = Vec::new();
    for &k in settings {
        let groups: Vec<&ExtraLine<'_>> = lines.iter().filter(|g| g.rot_bins == k).collect();
        for (what, get) in [
            (
                "mean",
                &(|g: &ExtraLine<'_>, j: usize| g.mean[j])
                    as &dyn Fn(&ExtraLine<'_>, usize) -> Option<f64>,
            ),
            ("median", &|g: &ExtraLine<'_>, j: usize| g.median[j]),
        ] {
            let ymax = groups
                .iter()
                .flat_map(|g| (0..=extra).filter_map(|j| get(g, j)))
                .fold(0.0f64, f64::max);
            panels.push(LinePanel {
                title: format!("{what} pose error, K = {k}"),
                xlabel: "ranges beyond the minimal set".into(),
                ylabel: format!("{what} pose error (m)"),
                x: (0.0, extra as f64),
                y: (0.0, ymax * 1.05),
                series: groups
                    .iter()
                    .map(|g| Series {
                        name: g.agent.to_string(),
                        points: (0..=extra).map(|j| (j as f64, get(g, j))).collect(),
                    })
                    .collect(),
            });
        }
    }
    line_panels(
        &format!("Pose error after each measurement beyond the minimal set ({plans} plans)"),
        &panels,
        2,
    )
}
