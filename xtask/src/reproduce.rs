//! `cargo xtask reproduce`: every committed artifact, regenerated from the committed code in
//! dependency order, and `--check`, the cheap part of that proof that CI runs.
//!
//! The steps are data ([`STEPS`]): a name, what it writes, the command that writes it and a
//! measured time on 2 cores. A full run executes them in order (policies → int8 blobs →
//! agreement → the stop's calibration → every `results/` run → inspection aggregates → MCU
//! tables → sizes), writes a `manifest.json` into each artifact directory (the command, the
//! commit, the date, the wall time, per step) and can be resumed (`--resume` skips a step whose
//! manifest entry is from the current commit). `--only`/`--skip` pick steps; `--list` prints
//! them with their estimates.
//!
//! `--check` regenerates what is cheap into a scratch directory and compares it byte for byte
//! with what is committed ([`CHECKS`]): the int8 blobs from the float policies, a prefix of every
//! committed evaluation (episodes are independent, so the first plans of a run are a run of their
//! own: the first episodes of every `results.json` must come out again), and the firmware size
//! table. A change that moves a committed artifact fails CI until the artifact is regenerated.
//!
//! The calibration step rewrites `core-nostd/src/stop/calibration.rs` (the stop's fitted
//! models), so it runs before every run that stops by the calibrated rule; the binary is rebuilt
//! after it.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

/// How a step's command runs.
#[derive(Clone, Copy)]
pub enum Runner {
    /// The release `activesense` binary with these arguments.
    Cli,
    /// `cargo run --release -p activesense-lab --example NAME -- ARGS`, stdout into the file.
    Example(&'static str),
    /// `cargo xtask ARGS`, stdout into the file.
    Xtask,
}

/// One artifact-producing step.
pub struct Step {
    /// Name used by `--only`, `--skip` and the manifests.
    pub name: &'static str,
    /// The directory whose manifest records the step (created if missing).
    pub dir: &'static str,
    /// The command's arguments (for [`Runner::Cli`]: after `activesense`).
    pub args: &'static [&'static str],
    /// How the command runs.
    pub runner: Runner,
    /// Where stdout goes (relative to the root), for commands that print their table.
    pub stdout_to: Option<&'static str>,
    /// Measured wall time on 2 cores, seconds (the estimate `--list` and progress show).
    pub estimate_s: u32,
    /// The step rewrites core source: rebuild the binary after it.
    pub rebuilds: bool,
}

const fn cli(
    name: &'static str,
    dir: &'static str,
    args: &'static [&'static str],
    estimate_s: u32,
) -> Step {
    Step {
        name,
        dir,
        args,
        runner: Runner::Cli,
        stdout_to: None,
        estimate_s,
        rebuilds: false,
    }
}

/// Every committed artifact, in dependency order (one step a line: a table, not prose).
#[rustfmt::skip]
pub const STEPS: &[Step] = &[
    cli("policy-k1-seed1", "policies/k1/seeds/1", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "1", "--log-every", "50", "--out", "policies/k1/seeds/1"], 215),
    cli("policy-k1-seed2", "policies/k1/seeds/2", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "2", "--log-every", "50", "--out", "policies/k1/seeds/2"], 215),
    cli("policy-k1-seed3", "policies/k1/seeds/3", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "3", "--log-every", "50", "--out", "policies/k1/seeds/3"], 215),
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/k1/pick.md"), ..cli("select-k1", "policies/k1", &["1", "policies/k1", "500", "pick"], 15) },
    cli("policy-k10-seed1", "policies/k10/seeds/1", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--out", "policies/k10/seeds/1"], 780),
    cli("policy-k10-seed2", "policies/k10/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--out", "policies/k10/seeds/2"], 780),
    cli("policy-k10-seed3", "policies/k10/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--out", "policies/k10/seeds/3"], 780),
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/k10/pick.md"), ..cli("select-k10", "policies/k10", &["10", "policies/k10", "500", "pick"], 30) },
    cli("ablation-k1-no-registration-reward", "policies/ablations/k1-no-registration-reward", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "1", "--log-every", "50", "--registration-reward", "0", "--out", "policies/ablations/k1-no-registration-reward"], 210),
    cli("ablation-k1-no-scans", "policies/ablations/k1-no-scans", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "1", "--log-every", "50", "--inputs", "no-scans", "--out", "policies/ablations/k1-no-scans"], 210),
    cli("ablation-k1-no-belief", "policies/ablations/k1-no-belief", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "1", "--log-every", "50", "--inputs", "no-belief", "--out", "policies/ablations/k1-no-belief"], 210),
    cli("ablation-k1-no-registration-reward-seed2", "policies/ablations/k1-no-registration-reward/seeds/2", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "2", "--log-every", "50", "--registration-reward", "0", "--out", "policies/ablations/k1-no-registration-reward/seeds/2"], 210),
    cli("ablation-k1-no-scans-seed2", "policies/ablations/k1-no-scans/seeds/2", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "2", "--log-every", "50", "--inputs", "no-scans", "--out", "policies/ablations/k1-no-scans/seeds/2"], 210),
    cli("ablation-k1-no-belief-seed2", "policies/ablations/k1-no-belief/seeds/2", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "2", "--log-every", "50", "--inputs", "no-belief", "--out", "policies/ablations/k1-no-belief/seeds/2"], 210),
    cli("ablation-k1-no-registration-reward-seed3", "policies/ablations/k1-no-registration-reward/seeds/3", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "3", "--log-every", "50", "--registration-reward", "0", "--out", "policies/ablations/k1-no-registration-reward/seeds/3"], 210),
    cli("ablation-k1-no-scans-seed3", "policies/ablations/k1-no-scans/seeds/3", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "3", "--log-every", "50", "--inputs", "no-scans", "--out", "policies/ablations/k1-no-scans/seeds/3"], 210),
    cli("ablation-k1-no-belief-seed3", "policies/ablations/k1-no-belief/seeds/3", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "3", "--log-every", "50", "--inputs", "no-belief", "--out", "policies/ablations/k1-no-belief/seeds/3"], 210),
    cli("ablation-k10-no-registration-reward", "policies/ablations/k10-no-registration-reward", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--registration-reward", "0", "--out", "policies/ablations/k10-no-registration-reward"], 1500),
    cli("ablation-k10-no-scans", "policies/ablations/k10-no-scans", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--inputs", "no-scans", "--out", "policies/ablations/k10-no-scans"], 1500),
    cli("ablation-k10-no-belief", "policies/ablations/k10-no-belief", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--inputs", "no-belief", "--out", "policies/ablations/k10-no-belief"], 1500),
    cli("ablation-k10-no-registration-reward-seed2", "policies/ablations/k10-no-registration-reward/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--registration-reward", "0", "--out", "policies/ablations/k10-no-registration-reward/seeds/2"], 450),
    cli("ablation-k10-no-scans-seed2", "policies/ablations/k10-no-scans/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--inputs", "no-scans", "--out", "policies/ablations/k10-no-scans/seeds/2"], 450),
    cli("ablation-k10-no-belief-seed2", "policies/ablations/k10-no-belief/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--inputs", "no-belief", "--out", "policies/ablations/k10-no-belief/seeds/2"], 450),
    cli("ablation-k10-no-registration-reward-seed3", "policies/ablations/k10-no-registration-reward/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--registration-reward", "0", "--out", "policies/ablations/k10-no-registration-reward/seeds/3"], 450),
    cli("ablation-k10-no-scans-seed3", "policies/ablations/k10-no-scans/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--inputs", "no-scans", "--out", "policies/ablations/k10-no-scans/seeds/3"], 450),
    cli("ablation-k10-no-belief-seed3", "policies/ablations/k10-no-belief/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--inputs", "no-belief", "--out", "policies/ablations/k10-no-belief/seeds/3"], 450),
    cli("ablation-k10-ppo-no-registration-reward", "policies/ablations/k10-ppo-no-registration-reward", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--registration-reward", "0", "--out", "policies/ablations/k10-ppo-no-registration-reward"], 780),
    cli("ablation-k10-ppo-no-scans", "policies/ablations/k10-ppo-no-scans", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-scans", "--out", "policies/ablations/k10-ppo-no-scans"], 780),
    cli("ablation-k10-ppo-no-belief", "policies/ablations/k10-ppo-no-belief", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-belief", "--out", "policies/ablations/k10-ppo-no-belief"], 780),
    cli("ablation-k10-ppo-no-registration-reward-seed2", "policies/ablations/k10-ppo-no-registration-reward/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--registration-reward", "0", "--out", "policies/ablations/k10-ppo-no-registration-reward/seeds/2"], 780),
    cli("ablation-k10-ppo-no-scans-seed2", "policies/ablations/k10-ppo-no-scans/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-scans", "--out", "policies/ablations/k10-ppo-no-scans/seeds/2"], 780),
    cli("ablation-k10-ppo-no-belief-seed2", "policies/ablations/k10-ppo-no-belief/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-belief", "--out", "policies/ablations/k10-ppo-no-belief/seeds/2"], 780),
    cli("ablation-k10-ppo-no-registration-reward-seed3", "policies/ablations/k10-ppo-no-registration-reward/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--registration-reward", "0", "--out", "policies/ablations/k10-ppo-no-registration-reward/seeds/3"], 780),
    cli("ablation-k10-ppo-no-scans-seed3", "policies/ablations/k10-ppo-no-scans/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-scans", "--out", "policies/ablations/k10-ppo-no-scans/seeds/3"], 780),
    cli("ablation-k10-ppo-no-belief-seed3", "policies/ablations/k10-ppo-no-belief/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-belief", "--out", "policies/ablations/k10-ppo-no-belief/seeds/3"], 780),
    cli("ablation-k10-full-a2c-seed1", "policies/ablations/k10-full-a2c/seeds/1", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--out", "policies/ablations/k10-full-a2c/seeds/1"], 420),
    cli("ablation-k10-full-a2c-seed2", "policies/ablations/k10-full-a2c/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--out", "policies/ablations/k10-full-a2c/seeds/2"], 420),
    cli("ablation-k10-full-a2c-seed3", "policies/ablations/k10-full-a2c/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--out", "policies/ablations/k10-full-a2c/seeds/3"], 420),
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/ablations/k10-full-a2c/pick.md"), ..cli("select-ablation-k10-full-a2c", "policies/ablations/k10-full-a2c", &["10", "policies/ablations/k10-full-a2c", "500", "pick"], 30) },
    cli("policy-edm-k1-seed1", "policies/edm/k1/seeds/1", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "1", "--log-every", "50", "--inputs", "no-scans", "--instrument", "edm", "--out", "policies/edm/k1/seeds/1"], 210),
    cli("policy-edm-k1-seed2", "policies/edm/k1/seeds/2", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "2", "--log-every", "50", "--inputs", "no-scans", "--instrument", "edm", "--out", "policies/edm/k1/seeds/2"], 210),
    cli("policy-edm-k1-seed3", "policies/edm/k1/seeds/3", &["train", "--rot-bins", "1", "--updates", "12000", "--seed", "3", "--log-every", "50", "--inputs", "no-scans", "--instrument", "edm", "--out", "policies/edm/k1/seeds/3"], 210),
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/edm/k1/pick.md"), ..cli("select-edm-k1", "policies/edm/k1", &["1", "policies/edm/k1", "500", "pick"], 15) },
    cli("policy-edm-k10-seed1", "policies/edm/k10/seeds/1", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "1", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-scans", "--instrument", "edm", "--out", "policies/edm/k10/seeds/1"], 780),
    cli("policy-edm-k10-seed2", "policies/edm/k10/seeds/2", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "2", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-scans", "--instrument", "edm", "--out", "policies/edm/k10/seeds/2"], 780),
    cli("policy-edm-k10-seed3", "policies/edm/k10/seeds/3", &["train", "--rot-bins", "10", "--updates", "8000", "--seed", "3", "--lr", "1e-4", "--log-every", "50", "--update-epochs", "4", "--inputs", "no-scans", "--instrument", "edm", "--out", "policies/edm/k10/seeds/3"], 780),
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/edm/k10/pick.md"), ..cli("select-edm-k10", "policies/edm/k10", &["10", "policies/edm/k10", "500", "pick"], 30) },
    cli("int8-k1", "policies/k1", &["policy", "quantize", "--policy", "policies/k1/policy.policy", "--out", "policies/k1/policy.q8"], 1),
    cli("int8-k10", "policies/k10", &["policy", "quantize", "--policy", "policies/k10/policy.policy", "--out", "policies/k10/policy.q8"], 2),
    cli("int8-edm-k1", "policies/edm/k1", &["policy", "quantize", "--policy", "policies/edm/k1/policy.policy", "--out", "policies/edm/k1/policy.q8"], 1),
    cli("int8-edm-k10", "policies/edm/k10", &["policy", "quantize", "--policy", "policies/edm/k10/policy.policy", "--out", "policies/edm/k10/policy.q8"], 2),
    cli("agreement-edm", "results/edm", &["policy", "agreement", "--instrument", "edm", "--rot-bins", "1,10", "--plans", "200", "--int8", "policies/edm/k1/policy.q8", "--int8", "policies/edm/k10/policy.q8", "--json", "results/edm/policy-agreement.json"], 60),
    cli("agreement", "results", &["policy", "agreement", "--rot-bins", "1,10", "--plans", "200", "--int8", "policies/k1/policy.q8", "--int8", "policies/k10/policy.q8", "--json", "results/policy-agreement.json"], 60),
    Step { rebuilds: true, ..cli("calibration", "results/calibration", &["calibrate"], 720) },
    Step { rebuilds: true, ..cli("calibration-edm", "results/calibration/edm", &["calibrate", "--instrument", "edm", "--site", "mixed", "--no-progress"], 1915) },
    cli("main-job", "results", &["eval", "--agents", "all", "--rot-bins", "1,10", "--plans", "1000", "--with-no-oracle", "--out", "results/", "--no-progress"], 100),
    cli("confident", "results/confident", &["eval", "--agents", "heuristic-1,learnt,learnt-int8,eem", "--rot-bins", "1,10", "--plans", "1000", "--termination", "confident", "--curve-plans", "0", "--out", "results/confident"], 100),
    cli("frontier-edm", "results/edm/frontier", &["eval", "--agents", "learnt,heuristic-1", "--rot-bins", "1,10", "--plans", "1000", "--termination", "confident", "--instrument", "edm", "--stop-risks", "0.001,0.003,0.01,0.03,0.1", "--curve-plans", "0", "--no-progress", "--out", "results/edm/frontier"], 300),
    Step { runner: Runner::Example("station_sweep"), stdout_to: Some("results/edm/station-sweep.md"), ..cli("station-sweep-edm", "results/edm", &["--episodes", "10"], 60) },
    Step { runner: Runner::Example("station_sweep"), stdout_to: Some("results/edm/station-sweep-furnished.md"), ..cli("station-sweep-edm-furnished", "results/edm", &["--episodes", "10", "--site", "furnished"], 90) },
    Step { runner: Runner::Example("station_sweep"), stdout_to: Some("results/edm/station-sweep-site.md"), ..cli("station-sweep-edm-site", "results/edm", &["--episodes", "10", "--site", "site"], 90) },
    cli("frontier", "results/frontier", &["eval", "--agents", "learnt,heuristic-1,eem", "--rot-bins", "1,10", "--plans", "1000", "--termination", "confident", "--stop-risks", "0.001,0.003,0.01,0.03,0.1", "--curve-plans", "0", "--no-progress", "--out", "results/frontier"], 430),
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/k1/seeds.md"), ..cli("seeds-k1", "policies/k1", &["1", "policies/k1"], 60) },
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/k10/seeds.md"), ..cli("seeds-k10", "policies/k10", &["10", "policies/k10"], 150) },
    Step { runner: Runner::Example("select_seed"), stdout_to: Some("policies/ablations/k10-full-a2c/seeds.md"), ..cli("seeds-ablation-k10-full-a2c", "policies/ablations/k10-full-a2c", &["10", "policies/ablations/k10-full-a2c"], 150) },
    cli("greedy", "results/greedy", &["eval", "--agents", "oigm,oigm-cost,eem,heuristic-1", "--rot-bins", "1,10", "--plans", "1000", "--out", "results/greedy", "--no-progress"], 423),
    cli("greedy-confident", "results/greedy-confident", &["eval", "--agents", "oigm,oigm-cost,eem,heuristic-1", "--rot-bins", "1,10", "--plans", "1000", "--termination", "confident", "--out", "results/greedy-confident"], 380),
    cli("eval-ablation-k1-no-registration-reward", "results/ablations/k1-no-registration-reward", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-registration-reward/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-registration-reward", "--no-progress"], 15),
    cli("eval-ablation-k1-no-scans", "results/ablations/k1-no-scans", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-scans/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-scans", "--no-progress"], 15),
    cli("eval-ablation-k1-no-belief", "results/ablations/k1-no-belief", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-belief/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-belief", "--no-progress"], 15),
    cli("eval-ablation-k1-no-registration-reward-seed2", "results/ablations/k1-no-registration-reward/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-registration-reward/seeds/2/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-registration-reward/seeds/2", "--no-progress"], 15),
    cli("eval-ablation-k1-no-scans-seed2", "results/ablations/k1-no-scans/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-scans/seeds/2/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-scans/seeds/2", "--no-progress"], 15),
    cli("eval-ablation-k1-no-belief-seed2", "results/ablations/k1-no-belief/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-belief/seeds/2/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-belief/seeds/2", "--no-progress"], 15),
    cli("eval-ablation-k1-no-registration-reward-seed3", "results/ablations/k1-no-registration-reward/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-registration-reward/seeds/3/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-registration-reward/seeds/3", "--no-progress"], 15),
    cli("eval-ablation-k1-no-scans-seed3", "results/ablations/k1-no-scans/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-scans/seeds/3/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-scans/seeds/3", "--no-progress"], 15),
    cli("eval-ablation-k1-no-belief-seed3", "results/ablations/k1-no-belief/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k1-no-belief/seeds/3/policy.policy", "--rot-bins", "1", "--plans", "1000", "--out", "results/ablations/k1-no-belief/seeds/3", "--no-progress"], 15),
    cli("eval-ablation-k10-no-registration-reward", "results/ablations/k10-no-registration-reward", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-registration-reward/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-registration-reward", "--no-progress"], 40),
    cli("eval-ablation-k10-no-scans", "results/ablations/k10-no-scans", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-scans/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-scans", "--no-progress"], 40),
    cli("eval-ablation-k10-no-belief", "results/ablations/k10-no-belief", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-belief/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-belief", "--no-progress"], 40),
    cli("eval-ablation-k10-no-registration-reward-seed2", "results/ablations/k10-no-registration-reward/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-registration-reward/seeds/2/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-registration-reward/seeds/2", "--no-progress"], 40),
    cli("eval-ablation-k10-no-scans-seed2", "results/ablations/k10-no-scans/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-scans/seeds/2/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-scans/seeds/2", "--no-progress"], 40),
    cli("eval-ablation-k10-no-belief-seed2", "results/ablations/k10-no-belief/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-belief/seeds/2/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-belief/seeds/2", "--no-progress"], 40),
    cli("eval-ablation-k10-no-registration-reward-seed3", "results/ablations/k10-no-registration-reward/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-registration-reward/seeds/3/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-registration-reward/seeds/3", "--no-progress"], 40),
    cli("eval-ablation-k10-no-scans-seed3", "results/ablations/k10-no-scans/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-scans/seeds/3/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-scans/seeds/3", "--no-progress"], 40),
    cli("eval-ablation-k10-no-belief-seed3", "results/ablations/k10-no-belief/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-no-belief/seeds/3/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-no-belief/seeds/3", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-registration-reward", "results/ablations/k10-ppo-no-registration-reward", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-registration-reward/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-registration-reward", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-scans", "results/ablations/k10-ppo-no-scans", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-scans/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-scans", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-belief", "results/ablations/k10-ppo-no-belief", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-belief/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-belief", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-registration-reward-seed2", "results/ablations/k10-ppo-no-registration-reward/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-registration-reward/seeds/2/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-registration-reward/seeds/2", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-scans-seed2", "results/ablations/k10-ppo-no-scans/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-scans/seeds/2/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-scans/seeds/2", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-belief-seed2", "results/ablations/k10-ppo-no-belief/seeds/2", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-belief/seeds/2/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-belief/seeds/2", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-registration-reward-seed3", "results/ablations/k10-ppo-no-registration-reward/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-registration-reward/seeds/3/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-registration-reward/seeds/3", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-scans-seed3", "results/ablations/k10-ppo-no-scans/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-scans/seeds/3/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-scans/seeds/3", "--no-progress"], 40),
    cli("eval-ablation-k10-ppo-no-belief-seed3", "results/ablations/k10-ppo-no-belief/seeds/3", &["eval", "--agents", "learnt", "--policy", "policies/ablations/k10-ppo-no-belief/seeds/3/policy.policy", "--rot-bins", "10", "--plans", "1000", "--out", "results/ablations/k10-ppo-no-belief/seeds/3", "--no-progress"], 40),
    Step { runner: Runner::Example("ablation_seeds"), stdout_to: Some("results/ablations/seeds-k1.md"), ..cli("ablation-seeds-k1", "results/ablations", &["1"], 5) },
    Step { runner: Runner::Example("ablation_seeds"), stdout_to: Some("results/ablations/seeds-k10.md"), ..cli("ablation-seeds-k10", "results/ablations", &["10"], 5) },
    Step { runner: Runner::Example("ablation_seeds"), stdout_to: Some("results/ablations/seeds-k10-ppo.md"), ..cli("ablation-seeds-k10-ppo", "results/ablations", &["10", "ppo"], 5) },
    cli("extra", "results/extra", &["eval", "--agents", "heuristic-1,oigm,learnt", "--rot-bins", "1,10", "--plans", "1000", "--extra-measurements", "10", "--max-actions", "300", "--no-progress", "--out", "results/extra"], 500),
    Step { stdout_to: Some("results/bench-localization.md"), ..cli("bench-localization", "results", &["bench-localization", "--plans", "100", "--json", "results/bench-localization.json"], 60) },
    cli("bench-registration", "results", &["bench-registration", "--plans", "1000", "--json", "results/bench-registration.json"], 120),
    cli("inspect-k1", "docs/inspect/k1", &["inspect", "--aggregate", "--agent", "learnt", "--rot-bins", "1", "--plans", "200", "--out", "docs/inspect/k1", "--no-progress"], 5),
    cli("inspect-k10", "docs/inspect/k10", &["inspect", "--aggregate", "--agent", "learnt", "--rot-bins", "10", "--plans", "200", "--out", "docs/inspect/k10", "--no-progress"], 10),
    Step { runner: Runner::Example("stop_trace"), stdout_to: Some("results/stop-trace/k10.txt"), ..cli("stop-trace", "results/stop-trace", &["1000", "10"], 160) },
    Step { runner: Runner::Example("refine_budget"), stdout_to: Some("results/refine-budget/budgets.md"), ..cli("refine-budget", "results/refine-budget", &["1000"], 100) },
    Step { runner: Runner::Xtask, stdout_to: Some("results/mcu-bench/heuristic-1-oracle.md"), ..cli("mcu-bench", "results/mcu-bench", &["mcu-bench", "--episodes", "20"], 120) },
    Step { runner: Runner::Xtask, stdout_to: Some("results/mcu-bench/learnt-int8-oracle.md"), ..cli("mcu-bench-int8", "results/mcu-bench", &["mcu-bench", "--episodes", "20", "--agent", "learnt-int8"], 30) },
    Step { runner: Runner::Xtask, stdout_to: Some("results/mcu-bench/heuristic-1-confident.md"), ..cli("mcu-bench-confident", "results/mcu-bench", &["mcu-bench", "--episodes", "20", "--termination", "confident"], 160) },
    Step { runner: Runner::Xtask, stdout_to: Some("results/mcu-bench/learnt-int8-confident.md"), ..cli("mcu-bench-int8-confident", "results/mcu-bench", &["mcu-bench", "--episodes", "20", "--agent", "learnt-int8", "--termination", "confident"], 40) },
    Step { runner: Runner::Xtask, stdout_to: Some("results/mcu-bench/learnt-int8-confident-edm.md"), ..cli("mcu-bench-int8-confident-edm", "results/mcu-bench", &["mcu-bench", "--episodes", "20", "--agent", "learnt-int8", "--termination", "confident", "--instrument", "edm"], 40) },
    Step { runner: Runner::Xtask, stdout_to: Some("results/size.md"), ..cli("size", "results", &["size"], 120) },
    Step { runner: Runner::Example("redraw"), ..cli("charts", "results", &["results", "policies"], 5) },
];

/// The root of the workspace.
fn root() -> PathBuf {
    super::root()
}

fn git(args: &[&str]) -> String {
    Command::new("git")
        .args(args)
        .current_dir(root())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

/// The command line a step runs, as a reader would type it.
pub fn command_line(s: &Step) -> String {
    let args = s.args.join(" ");
    match s.runner {
        Runner::Cli => format!("cargo run --release -p activesense -- {args}"),
        Runner::Example(e) => format!(
            "cargo run --release -p activesense-lab --example {e} -- {args} > {}",
            s.stdout_to.unwrap_or("-")
        ),
        Runner::Xtask => format!("cargo xtask {args} > {}", s.stdout_to.unwrap_or("-")),
    }
}

fn utc_now() -> String {
    // `date` is on every machine this runs on; no date crate for one line.
    Command::new("date")
        .args(["-u", "+%Y-%m-%dT%H:%M:%SZ"])
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into())
}

fn manifest_path(s: &Step) -> PathBuf {
    root().join(s.dir).join("manifest.json")
}

fn read_manifest(path: &Path) -> serde_json::Map<String, serde_json::Value> {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v.get("steps").and_then(|s| s.as_object()).cloned())
        .unwrap_or_default()
}

fn write_manifest(s: &Step, wall_s: f64, commit: &str, dirty: bool) -> Result<()> {
    let path = manifest_path(s);
    let mut steps = read_manifest(&path);
    steps.insert(
        s.name.to_string(),
        serde_json::json!({
            "command": command_line(s),
            "commit": commit,
            "dirty": dirty,
            "date": utc_now(),
            "wall_s": (wall_s * 10.0).round() / 10.0,
        }),
    );
    let text = serde_json::to_string_pretty(&serde_json::json!({ "steps": steps }))?;
    std::fs::create_dir_all(path.parent().unwrap())?;
    std::fs::write(&path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}

fn release_binary() -> Result<PathBuf> {
    super::run(super::cargo().args([
        "build",
        "--release",
        "-p",
        "activesense",
        "--bin",
        "activesense",
    ]))?;
    Ok(root().join("target/release/activesense"))
}

fn run_step(s: &Step, bin: &Path) -> Result<()> {
    let mut cmd = match s.runner {
        Runner::Cli => {
            let mut c = Command::new(bin);
            c.args(s.args);
            c
        }
        Runner::Example(e) => {
            let mut c = super::cargo();
            c.args([
                "run",
                "--quiet",
                "--release",
                "-p",
                "activesense-lab",
                "--example",
                e,
                "--",
            ]);
            c.args(s.args);
            c
        }
        Runner::Xtask => {
            // Through cargo, not `current_exe`: a `cargo test` in the same run may have
            // replaced this binary on disk.
            let mut c = super::cargo();
            c.args(["run", "--quiet", "-p", "xtask", "--"]);
            c.args(s.args);
            c
        }
    };
    cmd.current_dir(root());
    if let Some(out) = s.stdout_to {
        let path = root().join(out);
        std::fs::create_dir_all(path.parent().unwrap())?;
        cmd.stdout(Stdio::from(std::fs::File::create(&path)?));
    }
    super::run(&mut cmd)
}

struct Options {
    only: Vec<String>,
    skip: Vec<String>,
    resume: bool,
    list: bool,
    check: bool,
    /// `--check --artifacts DIR`: compare against the artifacts under DIR instead of the
    /// workspace's (the test that `--check` fails on a stale artifact uses a doctored copy).
    artifacts: Option<PathBuf>,
}

fn parse(args: &[String]) -> Result<Options> {
    let mut o = Options {
        only: vec![],
        skip: vec![],
        resume: false,
        list: false,
        check: false,
        artifacts: None,
    };
    let names = |v: Option<&String>, flag: &str| -> Result<Vec<String>> {
        let v = v.with_context(|| format!("{flag} needs step names (see --list)"))?;
        let names: Vec<String> = v.split(',').map(str::to_string).collect();
        for n in &names {
            if !STEPS.iter().any(|s| s.name == n) && !CHECKS.iter().any(|c| c.name == n) {
                bail!("{flag}: no step '{n}' (see `cargo xtask reproduce --list`)");
            }
        }
        Ok(names)
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--only" => o.only = names(it.next(), "--only")?,
            "--skip" => o.skip = names(it.next(), "--skip")?,
            "--resume" => o.resume = true,
            "--list" => o.list = true,
            "--check" => o.check = true,
            "--artifacts" => {
                o.artifacts = Some(PathBuf::from(it.next().context("--artifacts needs a directory")?))
            }
            other => bail!("reproduce: unknown argument '{other}' (--list, --only A,B, --skip A,B, --resume, --check, --artifacts DIR)"),
        }
    }
    Ok(o)
}

fn chosen(name: &str, o: &Options) -> bool {
    (o.only.is_empty() || o.only.iter().any(|n| n == name)) && !o.skip.iter().any(|n| n == name)
}

fn minutes(s: u32) -> String {
    if s < 90 {
        format!("{s} s")
    } else {
        format!("{:.0} min", s as f32 / 60.0)
    }
}

/// `cargo xtask reproduce [--list] [--only A,B] [--skip A,B] [--resume] [--check]`.
pub fn run(args: &[String]) -> Result<()> {
    let o = parse(args)?;
    if o.check {
        return check(&o);
    }
    let steps: Vec<&Step> = STEPS.iter().filter(|s| chosen(s.name, &o)).collect();
    if o.list {
        for s in STEPS {
            println!(
                "{:42} {:>7}  {}",
                s.name,
                minutes(s.estimate_s),
                command_line(s)
            );
        }
        let total: u32 = STEPS.iter().map(|s| s.estimate_s).sum();
        println!("{} steps, about {} on 2 cores", STEPS.len(), minutes(total));
        return Ok(());
    }
    let head = git(&["rev-parse", "--short=12", "HEAD"]);
    let mut bin = release_binary()?;
    let total: u32 = steps.iter().map(|s| s.estimate_s).sum();
    let (mut done_est, t0) = (0u32, Instant::now());
    for (i, s) in steps.iter().enumerate() {
        let previous = read_manifest(&manifest_path(s));
        let current = previous
            .get(s.name)
            .and_then(|e| e.get("commit"))
            .and_then(|c| c.as_str())
            == Some(head.as_str());
        if o.resume && current {
            eprintln!(
                "reproduce [{}/{}] {}: current (manifest from {head}), skipped",
                i + 1,
                steps.len(),
                s.name
            );
            done_est += s.estimate_s;
            continue;
        }
        let left = total.saturating_sub(done_est);
        eprintln!(
            "reproduce [{}/{}] {} (≈ {}; ≈ {} left in all; {} elapsed): {}",
            i + 1,
            steps.len(),
            s.name,
            minutes(s.estimate_s),
            minutes(left),
            minutes(t0.elapsed().as_secs() as u32),
            command_line(s)
        );
        // Dirty means the code the step ran was not the commit's (checked before the step,
        // which itself rewrites artifacts).
        let dirty = !git(&["status", "--porcelain", "--untracked-files=no"]).is_empty();
        let t = Instant::now();
        run_step(s, &bin).with_context(|| format!("step {} failed", s.name))?;
        write_manifest(s, t.elapsed().as_secs_f64(), &head, dirty)?;
        done_est += s.estimate_s;
        if s.rebuilds {
            bin = release_binary()?;
        }
    }
    eprintln!(
        "reproduce: {} steps in {}",
        steps.len(),
        minutes(t0.elapsed().as_secs() as u32)
    );
    Ok(())
}

/// One cheap comparison of `--check`.
pub struct Check {
    /// Name (for `--only`/`--skip`).
    pub name: &'static str,
    /// What it proves.
    pub what: &'static str,
}

/// The checks `--check` runs, cheapest first.
pub const CHECKS: &[Check] = &[
    Check { name: "int8-blobs", what: "policies/k*/policy.q8 equal `policy quantize` of the committed float policies" },
    Check { name: "eval-prefixes", what: "the first plans' episodes of every committed results/**/results.json come out of today's code" },
    Check { name: "size", what: "results/size.md equals `cargo xtask size`" },
    Check { name: "charts", what: "every committed chart (results/**/*.svg, policies/**/curve.svg) is what today's code draws from its JSON" },
    Check {
        name: "curves",
        what: "the first CHECK_UPDATES updates of every committed learning curve (log.csv, all columns but wall time and steps/s) replay",
    },
];

fn scratch() -> Result<PathBuf> {
    let dir = root().join("target/reproduce-check");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

/// What every check needs: the binary, a scratch directory, where the committed artifacts
/// are, and which steps to look at.
struct Ctx<'a> {
    bin: PathBuf,
    dir: PathBuf,
    committed: PathBuf,
    o: &'a Options,
}

impl Ctx<'_> {
    /// A step is checked unless `--only` names steps and not this one, or `--skip` names it.
    fn step(&self, s: &Step) -> bool {
        let names_steps = self
            .o
            .only
            .iter()
            .any(|n| STEPS.iter().any(|t| t.name == n));
        (!names_steps || self.o.only.iter().any(|n| n == s.name))
            && !self.o.skip.iter().any(|n| n == s.name)
    }
}

/// A check runs when nothing is picked, when it is picked, or when one of its steps is.
fn check_chosen(c: &Check, o: &Options, steps_of: &dyn Fn(&Step) -> bool) -> bool {
    if o.skip.iter().any(|n| n == c.name) {
        return false;
    }
    o.only.is_empty()
        || o.only.iter().any(|n| n == c.name)
        || STEPS
            .iter()
            .any(|s| steps_of(s) && o.only.iter().any(|n| n == s.name))
}

fn check(o: &Options) -> Result<()> {
    let ctx = Ctx {
        bin: release_binary()?,
        dir: scratch()?,
        committed: o.artifacts.clone().unwrap_or_else(root),
        o,
    };
    let mut stale = Vec::new();
    for c in CHECKS {
        let steps_of: &dyn Fn(&Step) -> bool = match c.name {
            "int8-blobs" => &|s: &Step| s.name.starts_with("int8-"),
            "eval-prefixes" => &|s: &Step| s.args.first() == Some(&"eval"),
            "curves" => &|s: &Step| s.args.first() == Some(&"train"),
            "charts" => &|s: &Step| s.name == "charts",
            _ => &|s: &Step| s.name == "size",
        };
        if !check_chosen(c, o, steps_of) {
            continue;
        }
        eprintln!("reproduce --check {}: {}", c.name, c.what);
        let found = match c.name {
            "int8-blobs" => check_blobs(&ctx)?,
            "eval-prefixes" => check_eval_prefixes(&ctx)?,
            "size" => check_size(&ctx)?,
            "curves" => check_curves(&ctx)?,
            "charts" => check_charts(&ctx)?,
            _ => unreachable!("every check has a body"),
        };
        stale.extend(found);
    }
    if !stale.is_empty() {
        bail!(
            "committed artifacts no longer come out of the code:\n  {}\nregenerate them with `cargo xtask reproduce --only STEP` (see --list)",
            stale.join("\n  ")
        );
    }
    eprintln!("reproduce --check: every checked artifact is current");
    Ok(())
}

fn check_blobs(ctx: &Ctx) -> Result<Vec<String>> {
    let (bin, dir) = (&ctx.bin, &ctx.dir);
    let mut stale = Vec::new();
    for s in STEPS
        .iter()
        .filter(|s| s.name.starts_with("int8-") && ctx.step(s))
    {
        let committed = s.args[s.args.len() - 1];
        let fresh = dir.join(format!("{}.q8", s.name));
        let mut args: Vec<&str> = s.args.to_vec();
        let n = args.len();
        let fresh_str = fresh.to_string_lossy().into_owned();
        args[n - 1] = &fresh_str;
        super::run(Command::new(bin).args(&args).current_dir(root()))?;
        let old = std::fs::read(ctx.committed.join(committed))
            .with_context(|| format!("committed {committed}"))?;
        if old != std::fs::read(&fresh)? {
            stale.push(format!("{committed} (step {})", s.name));
        }
    }
    Ok(stale)
}

/// `args` with the values of the given flags replaced (`--plans 1000` → `--plans 10`).
fn overridden(args: &[&str], with: &[(&str, &str)]) -> Vec<String> {
    let mut out = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        out.push(a.to_string());
        if let Some((_, v)) = with.iter().find(|(f, _)| f == a) {
            it.next();
            out.push(v.to_string());
        }
    }
    out
}

/// Plans per committed evaluation that `--check` replays.
pub const CHECK_PLANS: usize = 10;

fn check_eval_prefixes(ctx: &Ctx) -> Result<Vec<String>> {
    let (bin, dir) = (&ctx.bin, &ctx.dir);
    let mut stale = Vec::new();
    for s in STEPS
        .iter()
        .filter(|s| s.args.first() == Some(&"eval") && ctx.step(s))
    {
        if s.args.contains(&"--extra-measurements") || s.args.contains(&"--stop-risks") {
            // results/extra and the frontier keep only aggregates, no per-episode records.
            continue;
        }
        // `--with-no-oracle` writes a second run into no-oracle/ and, for the paper's sensor,
        // the EDM-only instrument's into no-oracle-edm/, furnished and on sites into
        // no-oracle-edm-{furnished,site}/: all are compared.
        let mut files = vec!["results.json".to_string()];
        if s.args.contains(&"--with-no-oracle") {
            files.push("no-oracle/results.json".into());
            if !s.args.contains(&"edm") {
                files.push("no-oracle-edm/results.json".into());
                files.push("no-oracle-edm-furnished/results.json".into());
                files.push("no-oracle-edm-site/results.json".into());
            }
        }
        let mut committed_texts = Vec::new();
        for f in &files {
            match std::fs::read_to_string(ctx.committed.join(s.dir).join(f)) {
                Ok(t) => committed_texts.push((f.clone(), t)),
                Err(_) => stale.push(format!("{}/{f} is missing (step {})", s.dir, s.name)),
            }
        }
        if committed_texts.len() < files.len() {
            continue;
        }
        let out = dir.join(s.name);
        let out_str = out.to_string_lossy().into_owned();
        let plans = CHECK_PLANS.to_string();
        let mut args = overridden(s.args, &[("--plans", &plans), ("--out", &out_str)]);
        if !args.iter().any(|a| a == "--no-progress") {
            args.push("--no-progress".into());
        }
        super::run(
            Command::new(bin)
                .args(&args)
                .current_dir(root())
                .stdout(Stdio::null()),
        )?;
        for (f, text) in &committed_texts {
            let fresh = std::fs::read_to_string(out.join(f))?;
            if let Some(d) = first_difference(text, &fresh)? {
                stale.push(format!("{}/{f} (step {}): {d}", s.dir, s.name));
            }
        }
    }
    Ok(stale)
}

/// The first episode of `fresh` (a `--plans N` rerun's `results.json`) that differs from the
/// same episode in the committed run: rows are matched by agent and K, episodes by position
/// (a run's episodes are its plans in order, each independent of the others).
pub fn first_difference(committed: &str, fresh: &str) -> Result<Option<String>> {
    use serde_json::Value;
    let committed: Value = serde_json::from_str(committed).context("committed results.json")?;
    let fresh: Value = serde_json::from_str(fresh).context("fresh results.json")?;
    let rows = |v: &Value| {
        v.get("results")
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default()
    };
    let key = |r: &Value| (r.get("agent").cloned(), r.get("rot_bins").cloned());
    let episodes = |r: &Value| {
        r.get("episodes")
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default()
    };
    let (old_rows, new_rows) = (rows(&committed), rows(&fresh));
    if new_rows.is_empty() {
        return Ok(Some("the rerun produced no rows".into()));
    }
    for new in &new_rows {
        let Some(old) = old_rows.iter().find(|o| key(o) == key(new)) else {
            return Ok(Some(format!("no committed row for {:?}", key(new))));
        };
        let (old_eps, new_eps) = (episodes(old), episodes(new));
        if new_eps.is_empty() {
            return Ok(Some(format!("{:?}: the rerun has no episodes", key(new))));
        }
        for (i, e) in new_eps.iter().enumerate() {
            match old_eps.get(i) {
                Some(o) if o == e => {}
                Some(o) => {
                    return Ok(Some(format!(
                        "{:?}, episode {i}: committed {o}, today {e}",
                        key(new)
                    )))
                }
                None => {
                    return Ok(Some(format!(
                        "{:?}: the committed run has only {i} episodes",
                        key(new)
                    )))
                }
            }
        }
    }
    Ok(None)
}

/// Updates of each committed training run that `--check` replays.
pub const CHECK_UPDATES: u64 = 300;

fn check_curves(ctx: &Ctx) -> Result<Vec<String>> {
    let (bin, dir) = (&ctx.bin, &ctx.dir);
    let mut stale = Vec::new();
    for s in STEPS
        .iter()
        .filter(|s| s.args.first() == Some(&"train") && ctx.step(s))
    {
        let committed = ctx.committed.join(s.dir).join("log.csv");
        let Ok(text) = std::fs::read_to_string(&committed) else {
            stale.push(format!("{}/log.csv is missing (step {})", s.dir, s.name));
            continue;
        };
        let out = dir.join(s.name);
        let out_str = out.to_string_lossy().into_owned();
        let updates = CHECK_UPDATES.to_string();
        let args = overridden(s.args, &[("--updates", &updates), ("--out", &out_str)]);
        super::run(
            Command::new(bin)
                .args(&args)
                .current_dir(root())
                .stdout(Stdio::null()),
        )?;
        let fresh = std::fs::read_to_string(out.join("log.csv"))?;
        if let Some(d) = first_curve_difference(&text, &fresh) {
            stale.push(format!("{}/log.csv (step {}): {d}", s.dir, s.name));
        }
    }
    Ok(stale)
}

/// Columns of a learning curve that measure the machine, not the learning.
const WALL_COLUMNS: &[&str] = &["wall_s", "steps_per_s"];

/// The first row of the replayed curve `fresh` that differs from the committed one, every
/// column but [`WALL_COLUMNS`] compared as text.
pub fn first_curve_difference(committed: &str, fresh: &str) -> Option<String> {
    let mut c = committed.lines();
    let mut f = fresh.lines();
    let (ch, fh) = (c.next()?, f.next()?);
    if ch != fh {
        return Some(format!("header differs: committed `{ch}`, today `{fh}`"));
    }
    let keep: Vec<bool> = ch.split(',').map(|h| !WALL_COLUMNS.contains(&h)).collect();
    let strip = |l: &str| -> Vec<String> {
        l.split(',')
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(v, _)| v.to_string())
            .collect()
    };
    let mut rows = 0;
    for (new, old) in f.zip(c.by_ref()) {
        rows += 1;
        if strip(new) != strip(old) {
            return Some(format!("committed `{old}`, today `{new}`"));
        }
    }
    (rows == 0).then(|| "the replay logged no row".to_string())
}

/// The charts, drawn again from their committed JSON by the `redraw` example, against the
/// committed SVGs.
fn check_charts(ctx: &Ctx) -> Result<Vec<String>> {
    let mut c = super::cargo();
    c.args([
        "run",
        "--quiet",
        "--release",
        "-p",
        "activesense-lab",
        "--example",
        "redraw",
        "--",
        "--check",
    ]);
    c.arg(ctx.committed.join("results"));
    c.arg(ctx.committed.join("policies"));
    c.current_dir(root());
    let status = c.status().context("running the redraw example")?;
    Ok(if status.success() {
        vec![]
    } else {
        vec!["the charts listed above (step charts)".into()]
    })
}

fn check_size(ctx: &Ctx) -> Result<Vec<String>> {
    let dir = &ctx.dir;
    let committed = ctx.committed.join("results/size.md");
    let fresh = dir.join("size.md");
    // In process (the table `cargo xtask size` prints), not through `current_exe`: a
    // `cargo test` earlier in the same CI run may have replaced this binary on disk.
    let (text, _) = super::size::table(&super::build_firmware()?)?;
    std::fs::write(&fresh, &text)?;
    let same = std::fs::read(&committed).ok() == Some(text.into_bytes());
    Ok(if same {
        vec![]
    } else {
        vec!["results/size.md (step size)".into()]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_changed_episode_is_found_and_a_prefix_is_not_a_difference() {
        let committed = r#"{"results":[{"agent":"learnt","rot_bins":1,"episodes":[{"plan_seed":1,"cost":0.1},{"plan_seed":2,"cost":0.2},{"plan_seed":3,"cost":0.3}]}]}"#;
        let prefix = r#"{"results":[{"agent":"learnt","rot_bins":1,"episodes":[{"plan_seed":1,"cost":0.1},{"plan_seed":2,"cost":0.2}]}]}"#;
        assert_eq!(first_difference(committed, prefix).unwrap(), None);
        let moved = r#"{"results":[{"agent":"learnt","rot_bins":1,"episodes":[{"plan_seed":1,"cost":0.1},{"plan_seed":2,"cost":0.25}]}]}"#;
        let d = first_difference(committed, moved).unwrap().unwrap();
        assert!(d.contains("episode 1"), "{d}");
        let other_k =
            r#"{"results":[{"agent":"learnt","rot_bins":10,"episodes":[{"plan_seed":1}]}]}"#;
        assert!(first_difference(committed, other_k)
            .unwrap()
            .unwrap()
            .starts_with("no committed row"));
        assert!(first_difference(committed, r#"{"results":[]}"#)
            .unwrap()
            .is_some());
    }

    #[test]
    fn a_curve_that_moves_is_found_and_wall_time_is_not_a_difference() {
        let committed = "update,wall_s,mean_return,steps_per_s\n50,0.6,1.5565,19771.3\n100,1.2,1.5131,20011.0\n150,1.9,1.6,19000.0\n";
        let replay = "update,wall_s,mean_return,steps_per_s\n50,0.9,1.5565,12000.0\n100,1.8,1.5131,12500.0\n";
        assert_eq!(first_curve_difference(committed, replay), None);
        let moved = "update,wall_s,mean_return,steps_per_s\n50,0.9,1.5565,12000.0\n100,1.8,1.5130,12500.0\n";
        assert!(first_curve_difference(committed, moved)
            .unwrap()
            .contains("1.5130"));
        assert!(
            first_curve_difference(committed, "update,wall_s,mean_return,steps_per_s\n").is_some()
        );
    }

    #[test]
    fn every_step_writes_into_its_manifest_dir_and_names_are_unique() {
        let mut names = std::collections::BTreeSet::new();
        for s in STEPS {
            assert!(names.insert(s.name), "step {} twice", s.name);
            if let Some(out) = s.stdout_to {
                assert!(
                    out.starts_with(s.dir),
                    "{}: {out} outside {}",
                    s.name,
                    s.dir
                );
            }
            if let Some(i) = s.args.iter().position(|a| *a == "--out") {
                assert!(
                    s.args[i + 1].trim_end_matches('/').starts_with(s.dir),
                    "{}",
                    s.name
                );
            }
        }
    }
}
