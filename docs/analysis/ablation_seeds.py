#!/usr/bin/env python3
"""The §4.4 ablations over their training seeds (README, "Ablations").

Reads the Table-4 evaluations (learnt agent, 1000 test plans, oracle stop) of every ablated policy:
seed 1 in `results/ablations/k{K}-{what}/`, seeds 2 and 3 in `results/ablations/k{K}-{what}/seeds/{S}/`
(the `eval-ablation-…` steps of `cargo xtask reproduce`), and the full policy's three seeds from the
mean ± sd row of a `seeds.md` (the same plans). Prints one markdown table: mean ± sample standard
deviation over the seeds of recognition, pose error, measurements, rotations and cost.

Every ablation is the A2C command plus one switch, so its "full" row is the A2C command's seeds:
`policies/k1/seeds.md` at K = 1 (the committed K = 1 policy is A2C), and at K = 10, where the
committed policy is now trained with PPO's clipped update (`--update-epochs 4`),
`policies/ablations/k10-full-a2c/seeds.md`: the A2C command's seeds, kept to compare like with like.

    python3 docs/analysis/ablation_seeds.py 1 > results/ablations/seeds-k1.md
"""

import json
import statistics
import sys
from pathlib import Path

WHAT = [
    ("no-registration-reward", "without the registration-error reward"),
    ("no-scans", "without topological scans"),
    ("no-belief", "without the belief map (scans + history)"),
]
# Where the A2C command's three full-policy seeds live, per K.
FULL_A2C = {1: "policies/k1", 10: "policies/ablations/k10-full-a2c"}
COLUMNS = [("recognition_rate", 3), ("pose_error", 4), ("measurements", 2), ("rotations", 2), ("cost", 3)]


def learnt_row(path, k):
    for r in json.loads(path.read_text())["results"]:
        if r["agent"] == "learnt" and r["rot_bins"] == k:
            return r
    raise SystemExit(f"{path}: no learnt row for K = {k}")


def main():
    k = int(sys.argv[1])
    root = Path(__file__).resolve().parents[2] / "results" / "ablations"
    print(f"# The §4.4 ablations at K = {k} over their training seeds\n")
    print(f"`python3 docs/analysis/ablation_seeds.py {k}`: the learnt agent on the 1000 test plans (oracle stop), "
          "each seed's `results.json`; mean ± sample standard deviation over the seeds.\n")
    print("| policy | seeds | recognition | pose error (m) | measurements | rotations | cost |")
    print("|---|---|---|---|---|---|---|")
    full_dir = FULL_A2C[k]
    seeds_md = Path(__file__).resolve().parents[2] / full_dir / "seeds.md"
    full = next(l for l in seeds_md.read_text().splitlines() if l.startswith("| mean ± sd"))
    c = [x.strip() for x in full.strip("|").split("|")]
    # seed | val. recognition | val. cost | recognition | cost | measurements | rotations | pose error | …
    print(f"| full, A2C (`{full_dir}/seeds.md`) | 3 | {c[3]} | {c[7]} | {c[5]} | {c[6]} | {c[4]} |")
    for d, label in WHAT:
        base = root / f"k{k}-{d}"
        files = [base / "results.json"] + sorted((base / "seeds").glob("*/results.json"))
        rows = [learnt_row(f, k) for f in files]
        cells = []
        for key, digits in COLUMNS:
            xs = [r[key] for r in rows]
            sd = statistics.stdev(xs) if len(xs) > 1 else 0.0
            cells.append(f"{statistics.mean(xs):.{digits}f} ± {sd:.{digits}f}")
        print(f"| {label} | {len(rows)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
