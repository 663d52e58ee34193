#!/usr/bin/env python3
"""Is the calibrated stop limited by its logistic model or by its features? (docs/EVALUATION.md,
"What the estimate cannot learn from its features").

Reads the decision points that `activesense calibrate --samples-out S` writes (one JSON line per
decision point: the stop features and whether the answer there was wrong) and compares stop
rules by the ranges an episode takes before its first stop, at a given share of wrong stops.
Episodes are split by plan index: a quarter fits the model, a quarter places the threshold, the
odd half checks. An episode that never stops counts the action limit (100) as its ranges.

    activesense calibrate --agents learnt --rot-bins 10 --plans 4000 --agent-tables none \
        --samples-out S --rust-out /tmp/cal.rs --out /tmp/cal
    python3 lab/scripts/stop_features.py S            # logistic against boosted trees
    python3 lab/scripts/stop_features.py S --history  # with the answer's history features
    python3 lab/scripts/stop_features.py S --quarters # the logistic model over four splits, with and
                                                        # without the previous decision point's margin

`--history` needs samples written by a build with `lab/scripts/answer-history.patch` or
`lab/scripts/argmax-history.patch` applied (each adds `settled_readings` and `answer_step` to the
features: of the answer, or of the belief argmax). Needs numpy and scikit-learn.
"""

import json
import sys
from collections import defaultdict

import numpy as np
from sklearn.ensemble import HistGradientBoostingClassifier
from sklearn.linear_model import LogisticRegression

ACTION_LIMIT = 100


def load(path):
    episodes = defaultdict(list)
    with open(path) as f:
        for line in f:
            d = json.loads(line)["sample"]
            episodes[d["plan"]].append(d)
    return episodes


def margin(f):
    return max(-30.0, min(30.0, f["rival_margin"]))


def features(f):
    """`StopFeatures::to_vector` (core-nostd/src/stop/mod.rs), in float64."""
    m = margin(f)
    p = min(max(f["peak_mass"], 1e-4), 1 - 1e-4)
    r = max(f["readings"], 1)
    unexplained = max(f["readings"] - f["explained"], 0)
    checks = max(-3, min(10, f["explained"] - f["unknowns"]))
    return [np.log(p / (1 - p)), f["entropy"], np.log(r), unexplained, checks, f["observability"],
            f["offset_cells"], f["offset_bins"], np.exp(-max(f["edge_margin"], 0) / 0.02),
            unexplained / r, f["repeats"] / r, 0 if f["agrees"] else 1, min(m, 10) / 10,
            max(m - 10, 0) / 10] + precision(f)


def precision(f):
    """The answer's precision: none, and ln(sigma / tolerance) of position and heading."""
    p = f.get("precision")
    if p is None:
        return [1.0, 0.0, 0.0]
    ratio = lambda s, t: np.log(min(max(s / t, 1e-3), 10.0))
    return [0.0, ratio(p["position"], 0.05), ratio(p["heading"], np.radians(0.5))]


def with_history(f):
    """The four features of answer-history.patch (heading unknown only)."""
    if f["unknowns"] < 3:
        return features(f) + [0.0, 0.0, 0.0, 0.0]
    s = min(f["settled_readings"], 5) / 5
    return features(f) + [s, 1.0 if f["settled_readings"] == 0 else 0.0,
                          min(max(f["answer_step"], 0.0), 1.0), s * min(margin(f), 10) / 10]


def ranges(d):
    return d["features"]["readings"] + d["features"]["repeats"]


def first_stops(episodes, plans, scores, t):
    answered = wrong = 0
    taken = []
    for p in plans:
        hit = np.nonzero(scores[p] < t)[0]
        if len(hit):
            d = episodes[p][hit[0]]
            answered += 1
            wrong += d["wrong"]
            taken.append(ranges(d))
        else:
            taken.append(ACTION_LIMIT)
    return answered, wrong, float(np.mean(taken))


def threshold_for(episodes, plans, scores, risk):
    """The largest threshold whose first stops (and every smaller one's) were wrong at most `risk`."""
    best = None
    for t in np.geomspace(1e-4, 2.0, 240):
        a, w, _ = first_stops(episodes, plans, scores, t)
        if a and w / a > risk:
            break
        best = t
    return best


def scores_of(episodes, plans, predict, vec):
    out = {}
    for p in plans:
        x = np.array([vec(d["features"]) for d in episodes[p]])
        risk = predict(x)
        out[p] = np.array([r * 8 / max(d["features"]["readings"], 1)
                           for r, d in zip(risk, episodes[p])])
    return out


def xy(episodes, plans, vec):
    x = [vec(d["features"]) for p in plans for d in episodes[p]]
    y = [d["wrong"] for p in plans for d in episodes[p]]
    return np.array(x), np.array(y)


def with_previous(f, prev):
    """`features` and the previous decision point's rival margin (in the margin's two pieces) and a
    flag where there is none (lab/scripts/previous-margin.patch)."""
    if prev is None:
        return features(f) + [0.0, 0.0, 1.0]
    m = margin(prev)
    return features(f) + [min(m, 10) / 10, max(m - 10, 0) / 10, 0.0]


def quarters(episodes):
    """The logistic model on four splits of the plans (docs/EVALUATION.md, "A rival fitted from every
    heading start"): for k = 0..3 it is fitted on the plans with index = k (mod 4), and the ranges at
    its best threshold for at most 1 % wrong first stops are taken on the other three quarters; the
    mean over the four splits, with and without the previous decision point's margin."""
    plans = sorted(episodes)
    rows = {
        "features": {p: np.array([features(d["features"]) for d in episodes[p]]) for p in plans},
        "+ previous margin": {
            p: np.array([with_previous(d["features"], episodes[p][i - 1]["features"] if i else None)
                         for i, d in enumerate(episodes[p])]) for p in plans},
    }
    for name, x in rows.items():
        best = []
        for k in range(4):
            fit = [p for p in plans if p % 4 == k]
            rest = [p for p in plans if p % 4 != k]
            y = np.array([d["wrong"] for p in fit for d in episodes[p]])
            model = LogisticRegression(C=1e3, max_iter=5000).fit(np.concatenate([x[p] for p in fit]), y)
            s = {p: model.predict_proba(x[p])[:, 1] * 8
                 / np.maximum([d["features"]["readings"] for d in episodes[p]], 1) for p in plans}
            ok = [m for t in np.geomspace(1e-4, 2.0, 160)
                  for a, w, m in [first_stops(episodes, rest, s, t)] if a and w / a <= 0.01]
            best.append(min(ok) if ok else float("nan"))
        print(f"{name:20s} ranges at <= 1 % wrong first stops, best threshold, per split: "
              + " ".join(f"{b:.2f}" for b in best) + f"; mean {np.mean(best):.2f}", flush=True)


def main():
    episodes = load(sys.argv[1])
    if "--quarters" in sys.argv:
        quarters(episodes)
        return
    history = "--history" in sys.argv
    plans = sorted(episodes)
    fit = [p for p in plans if p % 4 == 0]
    place = [p for p in plans if p % 4 == 2]
    check = [p for p in plans if p % 2 == 1]
    rest = place + check

    def report(name, predict, vec):
        s = scores_of(episodes, plans, predict, vec)
        t = threshold_for(episodes, place, s, 0.01)
        a, w, r = first_stops(episodes, check, s, t)
        # Each rule at its best threshold for a wrong share (placed and checked on the same plans):
        # compares rules, does not predict a rate.
        best = []
        for risk in (0.003, 0.005, 0.01, 0.02, 0.03):
            ok = [m for t2 in np.geomspace(1e-4, 2.0, 160)
                  for a2, w2, m in [first_stops(episodes, rest, s, t2)] if a2 and w2 / a2 <= risk]
            best.append(f"{100 * risk:.1f} %: {min(ok) if ok else float('nan'):.2f}")
        print(f"{name:26s} 1 % placed, checked: {r:.2f} ranges, {100 * w / max(a, 1):.2f} % wrong"
              f" | best threshold, ranges at wrong <= " + ", ".join(best), flush=True)

    logistic = LogisticRegression(C=1e3, max_iter=5000).fit(*xy(episodes, fit, features))
    report("logistic", lambda x: logistic.predict_proba(x)[:, 1], features)
    if history:
        lh = LogisticRegression(C=1e3, max_iter=5000).fit(*xy(episodes, fit, with_history))
        report("logistic + history", lambda x: lh.predict_proba(x)[:, 1], with_history)
    else:
        for trees, leaves in ((100, 7), (200, 15), (400, 15)):
            gb = HistGradientBoostingClassifier(max_iter=trees, learning_rate=0.05,
                                                max_leaf_nodes=leaves, random_state=0)
            gb.fit(*xy(episodes, fit, features))
            report(f"boosted trees {trees}/{leaves}", lambda x, g=gb: g.predict_proba(x)[:, 1], features)
    # Where the answer is right from some reading on, and where it is first right.
    settled, first = [], []
    for p in check:
        seq = episodes[p]
        wrong = [d["wrong"] for d in seq]
        k = next((k for k in range(len(seq)) if not any(wrong[k:])), None)
        settled.append(ranges(seq[k]) if k is not None else ACTION_LIMIT)
        k = next((k for k, w in enumerate(wrong) if not w), None)
        first.append(ranges(seq[k]) if k is not None else ACTION_LIMIT)
    print(f"ranges until the answer is right from then on: {np.mean(settled):.2f};"
          f" until it is first right: {np.mean(first):.2f}")


if __name__ == "__main__":
    main()
