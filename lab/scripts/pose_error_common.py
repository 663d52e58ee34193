#!/usr/bin/env python3
"""Two policies' pose error on the episodes both recognise (README, "Ablations").

A mean pose error is over the episodes a policy recognises, so two policies that recognise different
episodes are compared on different samples. This script compares them on the same one: the plans both
evaluations recognise (learnt agent, rotation setting K, per-episode records of `results.json`), and
the episodes only the first recognises. On the common plans it also prints each policy's median, the
share of episodes beyond 5, 10 and 30 cm, and how much of the mean the episodes beyond 10 cm carry (the
registration-error reward is clipped there: it says nothing about errors beyond 10 cm).

    python3 lab/scripts/pose_error_common.py results/results.json \\
        results/ablations/k10-ppo-no-registration-reward/results.json 10
"""

import json
import sys


def episodes(path, k):
    for r in json.loads(open(path).read())["results"]:
        if r["agent"] == "learnt" and r["rot_bins"] == k:
            return {e["plan_seed"]: e for e in r["episodes"]}
    raise SystemExit(f"{path}: no learnt row for K = {k}")


def mean(xs):
    return sum(xs) / len(xs) if xs else float("nan")


def main():
    if len(sys.argv) != 4:
        raise SystemExit("usage: pose_error_common.py A/results.json B/results.json K")
    k = int(sys.argv[3])
    a, b = episodes(sys.argv[1], k), episodes(sys.argv[2], k)
    both = [p for p in a if p in b and a[p]["recognised"] and b[p]["recognised"]]
    only_a = [p for p in a if p in b and a[p]["recognised"] and not b[p]["recognised"]]
    only_b = [p for p in a if p in b and b[p]["recognised"] and not a[p]["recognised"]]
    print(f"recognised by both: {len(both)}; pose error A {mean([a[p]['pose_error'] for p in both]):.4f} m, "
          f"B {mean([b[p]['pose_error'] for p in both]):.4f} m")
    for name, e in (("A", a), ("B", b)):
        xs = sorted(e[p]["pose_error"] for p in both)
        n = len(xs)
        beyond = lambda t: 100 * sum(x > t for x in xs) / n
        tail = sum(x for x in xs if x > 0.1) / n
        print(f"  {name}: median {xs[n // 2]:.4f} m; beyond 5 / 10 / 30 cm: {beyond(0.05):.1f} / "
              f"{beyond(0.1):.1f} / {beyond(0.3):.1f} %; episodes beyond 10 cm carry {tail:.4f} m of the mean")
    print(f"only A: {len(only_a)} (A's pose error {mean([a[p]['pose_error'] for p in only_a]):.4f} m); "
          f"only B: {len(only_b)} (B's {mean([b[p]['pose_error'] for p in only_b]):.4f} m)")


if __name__ == "__main__":
    main()
