#!/usr/bin/env python3
"""What the episodes an oracle-terminated evaluation did not recognise look like (docs/EVALUATION.md,
"The window argmax with the heading known").

Under the oracle stop an episode fails when its belief argmax never sits on the truth's cell (or a
symmetric equivalent) within the action limit. This script splits an agent's failures at rotation
setting K by whether the refined pose was nonetheless within `TOL` metres of the truth at the end
(the argmax one cell off while the registration is right: a cell-edge case), and prints them with
their readings, final pose error and the peak mass of the belief.

    python3 lab/scripts/oracle_failures.py results/results.json learnt 1 [TOL=0.02]
"""

import json
import sys


def main():
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    path, agent, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
    tol = float(sys.argv[4]) if len(sys.argv) > 4 else 0.02
    rows = [
        r
        for r in json.loads(open(path).read())["results"]
        if r["agent"] == agent and r["rot_bins"] == k
    ]
    if not rows:
        raise SystemExit(f"{path}: no {agent} row for K = {k}")
    episodes = rows[0]["episodes"]
    failed = [e for e in episodes if not e["recognised"]]
    registered = [e for e in failed if e["pose_error"] is not None and e["pose_error"] <= tol]
    print(
        f"{agent}, K = {k}: {len(failed)} of {len(episodes)} episodes not recognised; "
        f"{len(registered)} of them end with the refined pose within {tol * 100:.0f} cm of the truth"
    )
    print("plan seed | readings | refined pose error (m) | argmax cell centre's error (m) | peak mass")
    for e in failed:
        pe = e["pose_error"]
        print(
            f"{e['plan_seed']} | {e['measurements']} | "
            f"{'—' if pe is None else f'{pe:.4f}'} | {e['coarse_error']:.3f} | {e['final_peak_mass']:.2f}"
        )


if __name__ == "__main__":
    main()
