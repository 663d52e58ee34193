#!/usr/bin/env python3
"""How noisy is a threshold placed on 2000 episodes? (docs/EVALUATION.md, "A table placed on all
its episodes").

Reads the decision points that `activesense calibrate --samples-out S` writes, scores them with the
committed model of `core-nostd/src/stop/calibration.rs` (the stop score: the estimate x 8 / distinct
bearings), and places the threshold for a stated risk P on one half of the plans (even or odd
index), checking it on the other, by three rules: `envelope` (the calibration's own, the largest
threshold whose first crossings, and every smaller one's, were wrong at most P of the time),
`last` (the largest whose own rate is at most P) and `isotonic` (the largest where an increasing
fit of the rate, weighted by the stops, is at most P). Then the threshold placed on all episodes.
"Ranges" counts the action limit (100) for an episode that never stops.

    activesense calibrate --agents learnt --rot-bins 10 --plans 4000 --agent-tables none \\
        --samples-out S --rust-out /tmp/cal.rs --out /tmp/cal
    python3 lab/scripts/threshold_placement.py S

Needs numpy.
"""

import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from stop_features import features, load  # noqa: E402
from waiting_points import committed_model  # noqa: E402

# The calibration's candidate thresholds (`calibrate::candidate_thresholds`).
CANDIDATES = np.array([1e-5 * (0.9 / 1e-5) ** (i / 399) for i in range(400)])
ACTION_LIMIT = 100


def episodes_scored(path):
    eps = load(path)
    first = next(iter(eps.values()))[0]
    rot_bins = first.get("rot_bins") or (1 if first["features"]["unknowns"] == 2 else 10)
    w, b, _ = committed_model(rot_bins)
    out = {}
    for plan, pts in eps.items():
        score, wrong, readings = [], [], []
        for d in pts:
            z = float(w @ np.array(features(d["features"])) + b)
            risk = 1 / (1 + math.exp(-z)) if z > -60 else 0.0
            score.append(risk * 8 / max(d["features"]["readings"], 1))
            wrong.append(bool(d["wrong"]))
            readings.append(d["features"]["readings"])
        out[plan] = (np.array(score), np.array(wrong), np.array(readings))
    return rot_bins, out


def first_crossings(eps, plans):
    """Per candidate threshold: episodes stopped, of them wrong, and the summed ranges."""
    stops = np.zeros(len(CANDIDATES))
    wrong = np.zeros(len(CANDIDATES))
    ranges = np.zeros(len(CANDIDATES))
    for p in plans:
        score, wr, rd = eps[p]
        running_min = np.minimum.accumulate(score)
        # The first crossing of t is the first point whose running minimum is below t.
        idx = np.searchsorted(-running_min, -CANDIDATES, side="right")
        stopped = idx < len(score)
        at = np.minimum(idx, len(score) - 1)
        stops += stopped
        wrong += np.where(stopped, wr[at], 0)
        ranges += np.where(stopped, rd[at], ACTION_LIMIT)
    return stops, wrong, ranges


def increasing_fit(y, weight):
    """Pool-adjacent-violators: the weighted increasing fit of `y`."""
    blocks = []  # [value, weight, count]
    for yi, wi in zip(y, weight):
        blocks.append([yi, wi, 1])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            v2, w2, n2 = blocks.pop()
            v1, w1, n1 = blocks[-1]
            blocks[-1] = [(v1 * w1 + v2 * w2) / (w1 + w2) if w1 + w2 > 0 else 0.0, w1 + w2, n1 + n2]
    return np.concatenate([[v] * n for v, _, n in blocks])


def place(stops, wrong, p, rule):
    rate = np.where(stops > 0, wrong / np.maximum(stops, 1), 0.0)
    curve = {"envelope": np.maximum.accumulate(rate), "last": rate,
             "isotonic": increasing_fit(rate, stops)}[rule]
    ok = np.where(curve <= p)[0]
    return ok[-1] if len(ok) else 0


def main():
    rot_bins, eps = episodes_scored(sys.argv[1])
    plans = sorted(eps)
    halves = {"even": [p for p in plans if p % 2 == 0], "odd": [p for p in plans if p % 2 == 1]}
    print(f"K = {rot_bins}, {len(plans)} episodes")
    print("| placed on | checked on | P | rule | threshold | checked: wrong of stopped | ranges |")
    print("|---|---|---|---|---|---|---|")
    for fit, check in [("even", "odd"), ("odd", "even")]:
        fs, fw, _ = first_crossings(eps, halves[fit])
        cs, cw, cr = first_crossings(eps, halves[check])
        for p in [0.003, 0.01, 0.03]:
            for rule in ["envelope", "last", "isotonic"]:
                i = place(fs, fw, p, rule)
                print(f"| {fit} | {check} | {100 * p:g} % | {rule} | {CANDIDATES[i]:.4f} | "
                      f"{int(cw[i])} of {int(cs[i])} ({100 * cw[i] / max(cs[i], 1):.2f} %) | "
                      f"{cr[i] / len(halves[check]):.2f} |")
    s, w, _ = first_crossings(eps, plans)
    for p in [0.003, 0.01, 0.03]:
        i = place(s, w, p, "envelope")
        print(f"all {len(plans)} episodes, {100 * p:g} %: threshold {CANDIDATES[i]:.4f} "
              f"({int(w[i])} wrong of {int(s[i])} stopped, in-sample)")


if __name__ == "__main__":
    main()
