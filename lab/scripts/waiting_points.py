#!/usr/bin/env python3
"""What keeps a right answer waiting for the calibrated stop? (docs/EVALUATION.md, "What the
estimate cannot learn from its features").

Reads the decision points that `activesense calibrate --samples-out S` writes (one JSON line per
decision point: the stop features and whether the answer there was wrong; the episodes run to the
action limit) and replays the committed stop on them: the model of `core-nostd/src/stop/calibration.rs`
for the samples' K, and the threshold of the learnt policy's own table for a stated risk (default
1 %), compared with the stop score (the estimate x 8 / distinct bearings, `stop::stop_score`). For
every episode whose answer is right for good before the stop first fires, the decision points in
between are "waiting"; the table compares their mean features with those of the points where the
stop fires, and weighs the difference by the model's weight: how much of the gap in the estimate's
logit each feature makes. Last, the wrong first stops by how they are wrong (the samples'
`position_error` and `heading_error_deg`): the right pose off in heading only, a near miss, or
another pose (a twin).

    activesense calibrate --agents learnt --rot-bins 10 --plans 4000 --agent-tables none \
        --samples-out S --rust-out /tmp/cal.rs --out /tmp/cal
    python3 lab/scripts/waiting_points.py S [--risk 0.01]
    # the same samples under an earlier model (features it did not read count with weight 0):
    git show ef694db:core-nostd/src/stop/calibration.rs > /tmp/old.rs
    python3 lab/scripts/waiting_points.py S --calibration /tmp/old.rs

Needs numpy. Uses the feature vector of lab/scripts/stop_features.py.
"""

import argparse
import math
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from stop_features import features, load  # noqa: E402

NAMES = ["logit of peak mass", "entropy", "ln readings", "unexplained", "checks", "observability",
         "offset (cells)", "offset (bins)", "edge closeness", "unexplained share", "repeat share",
         "disagrees", "margin below knee", "margin above knee", "no precision",
         "ln position sd / 5 cm", "ln heading sd / 0.5 deg"]
STATED = [0.001, 0.003, 0.01, 0.03, 0.1]
CALIBRATION = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "core-nostd",
                           "src", "stop", "calibration.rs")


def committed_model(rot_bins, path=CALIBRATION):
    """Weights, bias and the learnt policy's thresholds of the model for `rot_bins` in `path`
    (weights padded with zeros to the current feature count)."""
    src = open(path).read()
    for block in src.split("StopModel {")[1:]:
        if int(re.search(r"rot_bins:\s*(\d+)", block).group(1)) != rot_bins:
            continue
        nums = lambda s: [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", s)]
        weights = nums(re.search(r"weights:\s*\[([^\]]*)\]", block).group(1))
        bias = float(re.search(r"bias:\s*(-?[\d.e-]+)", block).group(1))
        learnt = re.search(r"AgentKind::Learnt,\s*thresholds:\s*\[([^\]]*)\]", block)
        weights += [0.0] * (len(NAMES) - len(weights))
        return np.array(weights), bias, nums(learnt.group(1))
    raise SystemExit(f"no model for K = {rot_bins} in {path}")


def kind_of_wrong(d):
    """How a wrong answer is wrong: `heading` (within 5 cm, heading off by under 5 deg), `near`
    (5-50 cm, under 5 deg) or `twin` (anything further: another pose)."""
    pos, head = d.get("position_error", float("nan")), d.get("heading_error_deg", float("nan"))
    if head < 5 and pos < 0.05:
        return "heading"
    if head < 5 and pos < 0.5:
        return "near"
    return "twin"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("samples")
    ap.add_argument("--risk", type=float, default=0.01, choices=STATED)
    ap.add_argument("--calibration", default=CALIBRATION,
                    help="calibration.rs to replay (default: the committed one)")
    args = ap.parse_args()
    episodes = load(args.samples)
    rot_bins = next(iter(episodes.values()))[0].get("rot_bins")
    if rot_bins is None:
        rot_bins = 1 if next(iter(episodes.values()))[0]["features"]["unknowns"] == 2 else 10
    w, b, table = committed_model(rot_bins, args.calibration)
    threshold = table[STATED.index(args.risk)]
    waiting, stopping, waited, wrong, stops, ranges = [], [], [], [], 0, []
    for pts in episodes.values():
        right_from = None
        for i in range(len(pts) - 1, -1, -1):
            if pts[i]["wrong"]:
                break
            right_from = i
        first = None
        for i, d in enumerate(pts):
            z = float(w @ np.array(features(d["features"])) + b)
            risk = 1 / (1 + math.exp(-z)) if z > -60 else 0.0
            if risk * 8 / max(d["features"]["readings"], 1) < threshold:
                first = i
                break
        if first is not None:
            stops += 1
            ranges.append(pts[first]["features"]["readings"])
            if pts[first]["wrong"]:
                wrong.append(kind_of_wrong(pts[first]))
        if first is None or right_from is None or right_from > first:
            continue
        stopping.append(features(pts[first]["features"]))
        waiting += [features(pts[i]["features"]) for i in range(right_from, first)]
        waited.append(first - right_from)
    wa, st = np.array(waiting), np.array(stopping)
    print(f"K = {rot_bins}, stated {100 * args.risk:g} %: {len(episodes)} episodes, {len(st)} right "
          f"for good before the stop fires, {np.mean(waited):.2f} decision points waited on average "
          f"({len(wa)} in all)")
    print("| feature | weight | waiting (mean) | at the stop (mean) | logit gap |")
    print("|---|---|---|---|---|")
    gaps = w * (wa.mean(axis=0) - st.mean(axis=0))
    for k in np.argsort(-gaps):
        print(f"| {NAMES[k]} | {w[k]:.3f} | {wa[:, k].mean():.3f} | {st[:, k].mean():.3f} "
              f"| {gaps[k]:+.3f} |")
    print(f"| sum | | | | {gaps.sum():+.3f} |")
    kinds = {k: wrong.count(k) for k in ("heading", "near", "twin")}
    print(f"\nfirst stops: {stops} of {len(episodes)} episodes, after {np.mean(ranges):.2f} distinct "
          f"bearings on average; wrong: {len(wrong)} ({100 * len(wrong) / max(stops, 1):.2f} %): "
          f"{kinds['heading']} heading only (< 5 cm), {kinds['near']} near misses (5-50 cm), "
          f"{kinds['twin']} other poses")


if __name__ == "__main__":
    main()
