//! `activesense answer-coverage`: is the printed precision honest, and how often is the
//! answer ambiguous? Runs simulated episodes, builds each one's [`Answer`] and counts how
//! often the true pose lies within the printed 2σ (easting, northing and heading, each
//! against the candidate nearest the truth, over the answers that have a precision), how
//! many answers are underdetermined, how many are ambiguous, and how often the truth is one
//! of the listed candidates.

use activesense_core::episode::AgentKind;
use activesense_core::episode::EpisodeConfig;
use activesense_core::registration::pose_distance::{PoseErrors, Tolerance};
use activesense_instrument::answer::{Answer, Determination, HeadingHint};
use activesense_instrument::episode::{run_episode, EpisodeSpec, Termination};
use activesense_instrument::world::planfile::NamedPlan;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// What to run.
#[derive(Clone, Debug)]
pub struct CoverageRun {
    /// Generated plan seeds (ignored when `rooms` is not empty).
    pub seeds: std::ops::Range<u32>,
    /// The user's rooms (`--plans-from`), `episodes` episodes in each.
    pub rooms: Vec<NamedPlan>,
    /// Episodes per room.
    pub episodes: u32,
    /// Rotation bins.
    pub rot_bins: u8,
    /// The agent.
    pub agent: AgentKind,
    /// The termination rule.
    pub termination: Termination,
    /// The episodes' configuration (action limit, stop risk, ...).
    pub config: EpisodeConfig,
    /// The room the EDM hits (`--site`).
    pub site: activesense_instrument::world::site::SiteLevel,
    /// The first episode seed: a room's episodes take this and the next ones.
    pub episode_seed: u64,
    /// A heading hint derived from each episode's truth (`truth + offset ± tol`), to
    /// measure the tie-break: `(offset, tol)` in degrees.
    pub hint: Option<(f64, f64)>,
}

/// The counts.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CoverageReport {
    /// Rotation bins.
    pub rot_bins: u8,
    /// Episodes run.
    pub episodes: u32,
    /// Answers with a precision (σ printed).
    pub with_precision: u32,
    /// Of those, exactly determined (no spare reading).
    pub exact: u32,
    /// Answers that said "underdetermined".
    pub underdetermined: u32,
    /// Answers without any pose.
    pub no_pose: u32,
    /// Of the answers with a precision: |easting error| ≤ 2σ_E.
    pub within_2sigma_e: u32,
    /// … |northing error| ≤ 2σ_N.
    pub within_2sigma_n: u32,
    /// … |heading error| ≤ 2σ_heading (heading unknown only).
    pub within_2sigma_heading: u32,
    /// … answers whose heading was estimated (the heading coverage's denominator).
    pub heading_estimated: u32,
    /// … all estimated components within 2σ.
    pub within_2sigma_all: u32,
    /// Answers with a precision whose truth is among the candidates (within 5 cm and 0.5°, `Tolerance::SURVEYOR`):
    /// the σ describe these; a wrong answer is what the stated risk is for.
    pub right_with_precision: u32,
    /// … of those, every estimated component within 2σ.
    pub right_within_2sigma_all: u32,
    /// … of those, easting, northing and heading (when estimated) within 2σ.
    pub right_within_2sigma: [u32; 3],
    /// Answers listing more than one candidate.
    pub ambiguous: u32,
    /// Answers where the truth is one of the candidates (position within 5 cm, heading
    /// within 0.5°, `Tolerance::SURVEYOR`).
    pub truth_among_candidates: u32,
    /// Of the ambiguous answers, those whose first candidate is not the true one.
    pub ambiguous_first_wrong: u32,
    /// Median printed σ_E and σ_N (m) over the answers with a precision.
    pub median_sigma_m: f64,
}

impl CoverageReport {
    /// One markdown table row.
    pub fn row(&self) -> String {
        let pct = |k: u32, n: u32| {
            if n == 0 {
                "–".to_string()
            } else {
                format!("{:.1} % ({k}/{n})", 100.0 * k as f64 / n as f64)
            }
        };
        format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} mm | {} | {} |",
            self.rot_bins,
            self.episodes,
            pct(self.with_precision, self.episodes),
            pct(self.underdetermined, self.episodes),
            pct(self.within_2sigma_e, self.with_precision),
            pct(self.within_2sigma_n, self.with_precision),
            pct(self.within_2sigma_heading, self.heading_estimated),
            pct(self.within_2sigma_all, self.with_precision),
            {
                let n = self.right_with_precision;
                let p = |k: u32| format!("{:.1}", 100.0 * k as f64 / n.max(1) as f64);
                let w = self.right_within_2sigma;
                if self.rot_bins == 1 {
                    format!("{} / {} / – % of {n}", p(w[0]), p(w[1]))
                } else {
                    format!("{} / {} / {} % of {n}", p(w[0]), p(w[1]), p(w[2]))
                }
            },
            1000.0 * self.median_sigma_m,
            pct(self.ambiguous, self.episodes),
            pct(self.truth_among_candidates, self.episodes),
        )
    }

    /// The table header matching [`CoverageReport::row`].
    pub fn header() -> &'static str {
        "| K | episodes | with σ | underdetermined | E within 2σ | N within 2σ | heading within 2σ | all within 2σ | right answers: E / N / heading within 2σ | median σ | ambiguous | truth among candidates |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    }
}

/// Runs the episodes and counts.
pub fn coverage(run: &CoverageRun) -> CoverageReport {
    let specs: Vec<EpisodeSpec> = if run.rooms.is_empty() {
        run.seeds
            .clone()
            .map(|seed| spec_of(run, seed, None, 0))
            .collect()
    } else {
        run.rooms
            .iter()
            .flat_map(|room| {
                (0..run.episodes).map(move |i| spec_of(run, room.seed(), Some(room), i as u64))
            })
            .collect()
    };
    let answers: Vec<Answer> = specs
        .par_iter()
        .map(|spec| {
            let t = run_episode(spec);
            let hint = run.hint.map(|(off, tol)| HeadingHint {
                deg: (t.truth.theta as f64).to_degrees() + off,
                tol,
            });
            Answer::of_trajectory(&t, hint)
        })
        .collect();
    let mut r = CoverageReport {
        rot_bins: run.rot_bins,
        episodes: answers.len() as u32,
        ..Default::default()
    };
    let mut sigmas = Vec::new();
    for a in &answers {
        match a.determination {
            Determination::None => r.no_pose += 1,
            Determination::Underdetermined => r.underdetermined += 1,
            Determination::Exact => r.exact += 1,
            Determination::Redundant => {}
        }
        if a.ambiguous {
            r.ambiguous += 1;
        }
        let Some(t) = &a.truth else { continue };
        let e = t.nearest_errors;
        // Right: the candidate nearest the truth within the surveyor's tolerance, the
        // criterion of the no-oracle table (`Tolerance::SURVEYOR`).
        let right = Tolerance::SURVEYOR.admits(&PoseErrors {
            position: ((e[0] * e[0] + e[1] * e[1]).sqrt() * a.metres_per_unit) as f32,
            heading: e[2].abs().to_radians() as f32,
        });
        if right {
            r.truth_among_candidates += 1;
        }
        if a.ambiguous && t.nearest != 0 {
            r.ambiguous_first_wrong += 1;
        }
        let c = &a.candidates.get(t.nearest);
        let (Some(c), Some(sh)) = (c, a.sigma_heading_deg) else {
            continue;
        };
        let (Some(se), Some(sn)) = (c.sigma_e, c.sigma_n) else {
            continue;
        };
        r.with_precision += 1;
        sigmas.push(se * a.metres_per_unit);
        sigmas.push(sn * a.metres_per_unit);
        let ok_e = e[0].abs() <= 2.0 * se;
        let ok_n = e[1].abs() <= 2.0 * sn;
        r.within_2sigma_e += ok_e as u32;
        r.within_2sigma_n += ok_n as u32;
        let ok_h = if a.heading_given {
            true
        } else {
            r.heading_estimated += 1;
            let ok = e[2].abs() <= 2.0 * sh;
            r.within_2sigma_heading += ok as u32;
            ok
        };
        r.within_2sigma_all += (ok_e && ok_n && ok_h) as u32;
        if right {
            r.right_with_precision += 1;
            r.right_within_2sigma_all += (ok_e && ok_n && ok_h) as u32;
            r.right_within_2sigma[0] += ok_e as u32;
            r.right_within_2sigma[1] += ok_n as u32;
            r.right_within_2sigma[2] += (ok_h && !a.heading_given) as u32;
        }
    }
    sigmas.sort_by(f64::total_cmp);
    r.median_sigma_m = sigmas.get(sigmas.len() / 2).copied().unwrap_or(0.0);
    r
}

fn spec_of(run: &CoverageRun, seed: u32, room: Option<&NamedPlan>, episode: u64) -> EpisodeSpec {
    let mut spec = EpisodeSpec::new(seed, run.agent);
    spec.rot_bins = run.rot_bins;
    spec.termination = run.termination;
    spec.config = run.config;
    spec.sensor.site = run.site;
    spec.episode_seed = run.episode_seed.wrapping_add(episode);
    spec.user_plan = room.cloned();
    spec
}
