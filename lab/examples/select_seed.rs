//! Which of the seeds of one training configuration is committed, and how far apart the
//! seeds are (at least three seeds stand behind every reported configuration, the committed
//! one picked on validation plans, never on the test plans).
//!
//! `cargo run --release -p activesense-lab --example select_seed -- K DIR [VALIDATION_PLANS] [pick]`
//! evaluates the learnt agent of every `DIR/seeds/S/policy.policy` (oracle stop, the paper's
//! protocol) on the first `VALIDATION_PLANS` (default 500) validation plans
//! ([`VALIDATION_SEEDS`]: drawn neither for training nor for the test) and picks one by the
//! rule below.
//!
//! * With `pick`, it copies the pick's `policy.policy`, `log.csv`, `log.json` and `curve.svg`
//!   into `DIR` and prints the validation table (`DIR/pick.md`). `cargo xtask reproduce` runs
//!   this right after training: the int8 blob, the stop's calibration and every `results/`
//!   run use the committed policy.
//! * Without, it checks that `DIR/policy.policy` is the pick's and prints the report
//!   (`DIR/seeds.md`): every seed on the validation plans and, for the report only, on the
//!   1000 test plans under the oracle stop and under the calibrated stop (the instrument's
//!   own, fitted after the pick), with the mean and the standard deviation over the seeds.
//!
//! **The rule.** The lowest validation cost among the seeds whose validation recognition is
//! within half a percentage point of the best seed's: recognition first (a cheap policy that
//! fails is no policy), then cost (what the paper and a surveyor pay).

use activesense_core::episode::{AgentKind, EpisodeConfig};
use activesense_instrument::agents::Policies;
use activesense_instrument::episode::Termination;
use activesense_instrument::world::plans::{TEST_SEEDS, VALIDATION_SEEDS};
use activesense_instrument::world::sensor::SensorModel;
use activesense_lab::eval::harness::{self, EvalOptions};
use std::path::{Path, PathBuf};

/// Recognition within this of the best seed's counts as equal.
const RECOGNITION_SLACK: f64 = 0.005;
/// The files of a training run that the configuration's directory holds for the chosen seed.
const COPIED: &[&str] = &["policy.policy", "log.csv", "log.json", "curve.svg"];

/// One seed's figures on one plan set.
#[derive(Clone, Copy)]
struct Figures {
    recognition: f64,
    cost: f64,
    measurements: f64,
    rotations: f64,
    pose_error: f64,
    /// Answers right within the surveyor's tolerance (fraction of episodes).
    right: f64,
    /// Wrong answers (outside the tolerance), of `answered`.
    wrong: u32,
    answered: u32,
}

fn evaluate(
    policy: &Path,
    k: u8,
    first_seed: u32,
    plans: u32,
    termination: Termination,
) -> Figures {
    // The instrument the seed was trained for (a scan-blind network is the EDM-only one's):
    // its sensor and its stop's tables.
    let (_, meta) = activesense_instrument::learn::file::load(policy).expect("seed policy");
    let instrument = activesense_instrument::learn::agent::InputMask::of_metadata(&meta)
        .instrument()
        .expect("an instrument's policy");
    let opts = EvalOptions {
        agents: vec![AgentKind::Learnt],
        rot_bins: vec![k],
        plans,
        first_seed,
        episode_seed: 0,
        config: EpisodeConfig::default().on(instrument),
        sensor: SensorModel::default(),
        termination,
        policy_files: vec![policy.display().to_string()],
        policies: Policies::load_for(instrument, &[policy.to_path_buf()], &[k])
            .expect("seed policy"),
        progress: false,
        curve_plans: 0,
        tolerance: Default::default(),
        user_plans: Vec::new(),
        refused_plans: Vec::new(),
    };
    let (report, _) = harness::run(&opts);
    let r = &report.results[0];
    Figures {
        recognition: r.recognition_rate,
        cost: r.cost,
        measurements: r.measurements,
        rotations: r.rotations,
        pose_error: r.pose_error.unwrap_or(f64::NAN),
        right: r.answers.right,
        wrong: r.answers.wrong,
        answered: r.answers.answered,
    }
}

/// A seed's name and its figures on the validation plans, the test plans (oracle stop) and
/// the test plans (calibrated stop).
type SeedRow = (String, Figures, Figures, Figures);

fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, var.sqrt())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(k), Some(dir)) = (args.get(1).and_then(|a| a.parse::<u8>().ok()), args.get(2)) else {
        eprintln!("usage: select_seed K DIR [VALIDATION_PLANS]");
        std::process::exit(2);
    };
    let validation_plans: u32 = args.get(3).and_then(|a| a.parse().ok()).unwrap_or(500);
    let dir = PathBuf::from(dir);
    let mut seeds: Vec<(String, PathBuf)> = std::fs::read_dir(dir.join("seeds"))
        .expect("DIR/seeds")
        .filter_map(|e| e.ok())
        .map(|e| (e.file_name().to_string_lossy().into_owned(), e.path()))
        .filter(|(_, p)| p.join("policy.policy").is_file())
        .collect();
    seeds.sort_by_key(|(s, _)| s.parse::<u64>().unwrap_or(u64::MAX));
    assert!(
        seeds.len() >= 3,
        "at least three seeds in {}",
        dir.display()
    );
    let pick_only = args.get(4).map(String::as_str) == Some("pick");
    let test_plans = TEST_SEEDS.end - TEST_SEEDS.start;
    let validation: Vec<(String, Figures)> = seeds
        .iter()
        .map(|(s, p)| {
            eprintln!("select_seed: K = {k}, seed {s}, validation plans");
            let v = evaluate(
                &p.join("policy.policy"),
                k,
                VALIDATION_SEEDS.start,
                validation_plans,
                Termination::Oracle,
            );
            (s.clone(), v)
        })
        .collect();
    let best_recognition = validation
        .iter()
        .map(|r| r.1.recognition)
        .fold(f64::MIN, f64::max);
    let chosen = validation
        .iter()
        .filter(|r| r.1.recognition >= best_recognition - RECOGNITION_SLACK)
        .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))
        .map(|r| r.0.clone())
        .expect("a seed");
    let chosen_dir = dir.join("seeds").join(&chosen);
    let header = |what: &str| {
        println!(
            "# K = {k}: {what} `{}`\n",
            dir.join("policy.policy").display()
        );
        println!(
            "`cargo run --release -p activesense-lab --example select_seed -- {k} {} {validation_plans}{}`. \
             Learnt agent; validation: plans {}..{} (oracle stop). Committed: **seed {chosen}**, the \
             lowest validation cost among the seeds whose validation recognition is within {:.1} \
             percentage points of the best.\n",
            dir.display(),
            if pick_only { " pick" } else { "" },
            VALIDATION_SEEDS.start,
            VALIDATION_SEEDS.start + validation_plans,
            RECOGNITION_SLACK * 100.0
        );
    };
    if pick_only {
        for f in COPIED {
            let from = chosen_dir.join(f);
            std::fs::copy(&from, dir.join(f)).unwrap_or_else(|e| panic!("{}: {e}", from.display()));
        }
        header("the pick among the seeds for");
        println!("| seed | validation recognition | validation cost | validation pose error (m) |");
        println!("|---|---|---|---|");
        for (s, v) in &validation {
            let mark = if *s == chosen { " (committed)" } else { "" };
            println!(
                "| {s}{mark} | {:.3} | {:.3} | {:.4} |",
                v.recognition, v.cost, v.pose_error
            );
        }
        return;
    }
    let committed = std::fs::read(dir.join("policy.policy")).expect("DIR/policy.policy");
    let picked = std::fs::read(chosen_dir.join("policy.policy")).expect("the pick's policy");
    if committed != picked {
        eprintln!(
            "{}/policy.policy is not seed {chosen}'s: run the pick first (`select_seed -- {k} {} {validation_plans} pick`)",
            dir.display(),
            dir.display()
        );
        std::process::exit(1);
    }
    let rows: Vec<SeedRow> = validation
        .iter()
        .zip(&seeds)
        .map(|((s, v), (_, p))| {
            let policy = p.join("policy.policy");
            eprintln!("select_seed: K = {k}, seed {s}, test plans");
            (
                s.clone(),
                *v,
                evaluate(
                    &policy,
                    k,
                    TEST_SEEDS.start,
                    test_plans,
                    Termination::Oracle,
                ),
                evaluate(
                    &policy,
                    k,
                    TEST_SEEDS.start,
                    test_plans,
                    Termination::Confident,
                ),
            )
        })
        .collect();
    header("the seeds behind");
    println!(
        "Test: the {test_plans} test plans (oracle stop as in Table 4, and the calibrated stop at its \
         default 1 % risk; an answer is right within 5 cm and 0.5° of the truth), for the report only.\n"
    );
    println!(
        "| seed | validation recognition | validation cost | test recognition | test cost | test measurements | test rotations | test pose error (m) | calibrated stop: test cost | right answers | wrong answers (of answered) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (s, v, t, c) in &rows {
        let mark = if *s == chosen { " (committed)" } else { "" };
        println!(
            "| {s}{mark} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.4} | {:.3} | {:.3} | {}/{} |",
            v.recognition,
            v.cost,
            t.recognition,
            t.cost,
            t.measurements,
            t.rotations,
            t.pose_error,
            c.cost,
            c.right,
            c.wrong,
            c.answered
        );
    }
    let col = |f: &dyn Fn(&SeedRow) -> f64| -> (f64, f64) {
        mean_sd(&rows.iter().map(f).collect::<Vec<_>>())
    };
    let cols = [
        col(&|r| r.1.recognition),
        col(&|r| r.1.cost),
        col(&|r| r.2.recognition),
        col(&|r| r.2.cost),
        col(&|r| r.2.measurements),
        col(&|r| r.2.rotations),
        col(&|r| r.2.pose_error),
        col(&|r| r.3.cost),
        col(&|r| r.3.right),
        col(&|r| r.3.wrong as f64 / r.3.answered.max(1) as f64),
    ];
    let fmt = |(m, sd): (f64, f64), d: usize| format!("{m:.d$} ± {sd:.d$}");
    println!(
        "| mean ± sd over {} seeds | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} of answered |",
        rows.len(),
        fmt(cols[0], 3),
        fmt(cols[1], 3),
        fmt(cols[2], 3),
        fmt(cols[3], 3),
        fmt(cols[4], 2),
        fmt(cols[5], 2),
        fmt(cols[6], 4),
        fmt(cols[7], 3),
        fmt(cols[8], 3),
        fmt((cols[9].0 * 100.0, cols[9].1 * 100.0), 2) + " %",
    );
}
