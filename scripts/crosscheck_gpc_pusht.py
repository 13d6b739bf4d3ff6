#!/usr/bin/env python3
"""Cross-check evalharness's Push-T against GPC's own environment (the official DriftWorld code's
`gpc_rank/pusht_env.py`), imported from a checkout the caller gives. Evidence, not a CI test:
nothing of that repository enters the project, and it needs pygame, pymunk, shapely, opencv,
scikit-image, gymnasium, pyyaml, torch and torchvision from the package index.

Today it checks the resets: for seeds 100000-100099, GPC's `PushTEnv(domain_filename="push_t")`
after `seed(s)` and `reset()` against `scenarios/pusht/gpc_resets.tsv`, the table whose rows
evalharness's `reset.rng = "gpc-numpy"` reproduces to 1e-9 (its unit test,
`scenarios::pusht::numpy_rng`). It prints the largest difference of the agent's position, the
block's pose and the goal pose. (Rendering and trajectory drift are not compared yet: evalharness
has no GPC-faithful renderer.)

Usage: scripts/crosscheck_gpc_pusht.py --gpc PATH_TO_DRIFTWORLD_CHECKOUT
"""

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gpc", required=True, help="a checkout of the official DriftWorld repository")
    a = ap.parse_args()
    here = Path(a.gpc).resolve() / "pusht_driftworld"
    sys.path.insert(0, str(here / "gpc_rank"))
    os.chdir(here)  # the environment reads ./domains_yaml/<domain>.yml
    from pusht_env import PushTEnv  # noqa: E402 (the caller's checkout)

    rows = [l.split("\t") for l in (ROOT / "scenarios/pusht/gpc_resets.tsv").read_text().splitlines()[1:]]
    worst = {"agent": 0.0, "block": 0.0, "goal": 0.0}
    env = PushTEnv(domain_filename="push_t", render_action=False)
    for r in rows:
        seed, v = int(r[0]), [float(x) for x in r[1:]]
        env.seed(seed)
        env.reset()
        got = {
            "agent": list(env.agent.position),
            "block": list(env.block.position) + [env.block.angle],
            "goal": list(env.goal_pose),
        }
        want = {"agent": v[0:2], "block": v[2:5], "goal": v[5:8]}
        for k in worst:
            worst[k] = max(worst[k], max(abs(g - w) for g, w in zip(got[k], want[k])))
    print(f"{len(rows)} seeds ({rows[0][0]}-{rows[-1][0]}): largest |GPC - table| "
          + ", ".join(f"{k} {d:.3g}" for k, d in worst.items()))


if __name__ == "__main__":
    main()
