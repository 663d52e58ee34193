#!/usr/bin/env python3
"""The no-oracle table's rows (README, docs/results.md) from an evaluation's results.json, in the
layout tests/tests/readme_figures.rs checks: agent, K, right, wrong (of answered), unanswered,
measurements, rotations, cost, position error of right answers (mean / median / p95, mm),
recognition. Usage: python3 lab/scripts/no_oracle_table.py results/no-oracle-edm/results.json"""
import json, sys

def mm(r, key):
    v = r.get(key)
    return "–" if v is None else f"{1000 * v:.1f}"

res = json.load(open(sys.argv[1]))
print("| agent | K | right | wrong (of answered) | unanswered | measurements | rotations | cost "
      "| position error of right answers, mean / median / p95 (mm) | recognition (cell) |")
print("|---|---|---|---|---|---|---|---|---|---|")
for r in res["results"]:
    print(f"| {r['agent']} | {r['rot_bins']} | {r['right']:.3f} | {r['wrong']} ({100 * r['wrong_of_answered']:.1f} %) "
          f"| {r['unanswered']:.3f} | {r['measurements']:.2f} | {r['rotations']:.2f} | {r['cost']:.3f} "
          f"| {mm(r, 'right_position_error')} / {mm(r, 'right_position_error_median')} / {mm(r, 'right_position_error_p95')} "
          f"| {r['recognition_rate']:.3f} |")
