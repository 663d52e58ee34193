#!/usr/bin/env python3
"""The site-level table's rows (README, docs/results.md): the EDM-only instrument's agents in the room
as its plan, furnished and on a building site, one column group (right, wrong of answered,
unanswered, cost) per level, in the layout tests/tests/readme_figures.rs checks.
Usage: python3 lab/scripts/site_table.py [results/]"""
import json, os, sys

out = sys.argv[1] if len(sys.argv) > 1 else "results"
levels = [("plan", "no-oracle-edm"), ("furnished", "no-oracle-edm-furnished"), ("site", "no-oracle-edm-site")]
runs = [json.load(open(os.path.join(out, d, "results.json")))["results"] for _, d in levels]
head = " | ".join(f"{l}: right | {l}: wrong (of answered) | {l}: unanswered | {l}: cost" for l, _ in levels)
print(f"| agent | K | {head} |")
print("|---|---|" + "---|" * (4 * len(levels)))
for r in runs[1]:
    cells = []
    for run in runs:
        x = next(q for q in run if q["agent"] == r["agent"] and q["rot_bins"] == r["rot_bins"])
        cells += [f"{x['right']:.3f}", f"{x['wrong']} ({100 * x['wrong_of_answered']:.1f} %)",
                  f"{x['unanswered']:.3f}", f"{x['cost']:.3f}"]
    print(f"| {r['agent']} | {r['rot_bins']} | " + " | ".join(cells) + " |")
