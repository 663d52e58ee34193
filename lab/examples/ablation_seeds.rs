//! The §4.4 ablations over their training seeds (README, "Ablations"): one markdown table, the
//! mean ± sample standard deviation over the seeds of recognition, pose error, measurements,
//! rotations and cost.
//!
//! `cargo run --release -p activesense-lab --example ablation_seeds -- K [ppo]` reads the
//! Table-4 evaluations (learnt agent, 1000 test plans, oracle stop) of every ablated policy:
//! seed 1 in `results/ablations/k{K}-{what}/`, seeds 2 and 3 in its `seeds/{S}/` (the
//! `eval-ablation-…` steps of `cargo xtask reproduce`, which also runs this), and the full
//! policy's three seeds from the mean ± sd row of a `seeds.md` report (the same plans).
//!
//! Every ablation is a training command plus one switch, so its "full" row is that command's
//! own seeds:
//! * without `ppo`, the A2C command: `policies/k1/seeds.md` at K = 1 (the committed K = 1
//!   policy is A2C's) and `policies/ablations/k10-full-a2c/seeds.md` at K = 10, kept to compare
//!   like with like since the committed K = 10 policy is trained with PPO's update;
//! * with `ppo` (K = 10 only), the committed K = 10 command (`--update-epochs 4`): the
//!   ablations in `results/ablations/k10-ppo-{what}/`, the full row `policies/k10/seeds.md`.

use std::path::{Path, PathBuf};

/// The ablations: directory suffix and the table's label.
const WHAT: &[(&str, &str)] = &[
    (
        "no-registration-reward",
        "without the registration-error reward",
    ),
    ("no-scans", "without topological scans"),
    ("no-belief", "without the belief map (scans + history)"),
];
/// `results.json` keys of the columns, with their decimals.
const COLUMNS: &[(&str, usize)] = &[
    ("recognition_rate", 3),
    ("pose_error", 4),
    ("measurements", 2),
    ("rotations", 2),
    ("cost", 3),
];

fn fail(msg: String) -> ! {
    eprintln!("ablation_seeds: {msg}");
    std::process::exit(2);
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())))
}

/// The learnt agent's row at K of one evaluation.
fn learnt_row(path: &Path, k: u64) -> serde_json::Value {
    let json: serde_json::Value = serde_json::from_str(&read(path))
        .unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
    json["results"]
        .as_array()
        .into_iter()
        .flatten()
        .find(|r| r["agent"] == "learnt" && r["rot_bins"] == k)
        .cloned()
        .unwrap_or_else(|| fail(format!("{}: no learnt row for K = {k}", path.display())))
}

/// Mean and sample standard deviation (0 for one value).
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let k: u64 = args
        .first()
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| fail("usage: ablation_seeds K [ppo]".into()));
    let ppo = match args.get(1).map(String::as_str) {
        None => false,
        Some("ppo") => true,
        Some(other) => fail(format!(
            "unknown trainer '{other}' (usage: ablation_seeds K [ppo])"
        )),
    };
    let (name, full_dir, prefix) = match (k, ppo) {
        (1, false) => ("A2C", "policies/k1", ""),
        (10, false) => ("A2C", "policies/ablations/k10-full-a2c", ""),
        (10, true) => ("PPO", "policies/k10", "ppo-"),
        _ => fail(format!(
            "no ablations of K = {k} with {}",
            if ppo { "PPO" } else { "A2C" }
        )),
    };
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let command = if ppo {
        format!("{k} ppo")
    } else {
        k.to_string()
    };
    println!("# The §4.4 ablations at K = {k} over their training seeds ({name})\n");
    println!(
        "`cargo run --release -p activesense-lab --example ablation_seeds -- {command}`: the learnt \
         agent on the 1000 test plans (oracle stop), each seed's `results.json`; mean ± sample \
         standard deviation over the seeds.\n"
    );
    println!("| policy | seeds | recognition | pose error (m) | measurements | rotations | cost |");
    println!("|---|---|---|---|---|---|---|");
    let seeds_md = read(&root.join(full_dir).join("seeds.md"));
    let full = seeds_md
        .lines()
        .find(|l| l.starts_with("| mean ± sd"))
        .unwrap_or_else(|| fail(format!("{full_dir}/seeds.md has no mean ± sd row")));
    let c: Vec<&str> = full
        .trim()
        .trim_matches('|')
        .split('|')
        .map(str::trim)
        .collect();
    if c.len() < 8 {
        fail(format!("{full_dir}/seeds.md: a short mean ± sd row"));
    }
    // seed | val. recognition | val. cost | recognition | cost | measurements | rotations | pose error | …
    println!(
        "| full, {name} (`{full_dir}/seeds.md`) | 3 | {} | {} | {} | {} | {} |",
        c[3], c[7], c[5], c[6], c[4]
    );
    for (what, label) in WHAT {
        let base = root.join(format!("results/ablations/k{k}-{prefix}{what}"));
        let mut files = vec![base.join("results.json")];
        let mut seeds: Vec<PathBuf> = std::fs::read_dir(base.join("seeds"))
            .map(|d| d.flatten().map(|e| e.path().join("results.json")).collect())
            .unwrap_or_default();
        seeds.retain(|p| p.exists());
        seeds.sort();
        files.extend(seeds);
        let rows: Vec<serde_json::Value> = files.iter().map(|f| learnt_row(f, k)).collect();
        let cells: Vec<String> = COLUMNS
            .iter()
            .map(|&(key, digits)| {
                let xs: Vec<f64> = rows
                    .iter()
                    .map(|r| {
                        r[key]
                            .as_f64()
                            .unwrap_or_else(|| fail(format!("no number '{key}'")))
                    })
                    .collect();
                let (m, sd) = mean_sd(&xs);
                format!("{m:.digits$} ± {sd:.digits$}")
            })
            .collect();
        println!("| {label} | {} | {} |", rows.len(), cells.join(" | "));
    }
}
