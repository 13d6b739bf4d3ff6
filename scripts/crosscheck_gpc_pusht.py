#!/usr/bin/env python3
"""Cross-check evalharness's Push-T against GPC's own environment (the official DriftWorld code's
`gpc_rank/pusht_env.py`), imported from a checkout the caller gives. Evidence, not a CI test:
nothing of that repository enters the project, and it needs pygame, pymunk, shapely, opencv,
scikit-image, gymnasium, pyyaml, torch and torchvision from the package index.

1. Resets: for seeds 100000-100099, GPC's `PushTEnv(domain_filename="push_t")` after `seed(s)`
   and `reset()` against `scenarios/pusht/gpc_resets.tsv`, the table whose rows evalharness's
   `reset.rng = "gpc-numpy"` reproduces to 1e-9 (its unit test, `scenarios::pusht::numpy_rng`).
   It prints the largest difference of the agent's position, the block's pose and the goal pose.
2. With `--write-fixtures`, GPC's own frames and trajectories, into `scenarios/fixtures/gpc_pusht/`
   (data its environment produced; no code of it), which evalharness's tests compare against:
   - `frames.tsv` + `frames96.bin`: 24 states of pushing episodes (seeds 100000-100005, the agent
     driven at the block so that it touches it) and the 96 x 96 observation frame GPC's
     `_render_frame` hands a policy for each (uint8 RGB, row-major, frames one after another).
     Read by `scenarios::pusht::gpc_render::tests` (mean |difference| and the share of pixels
     within 8 levels).
   - `canvas512.rle`: the 512 x 512 canvases of the first 4 of those states before the resize,
     drawn with pymunk's contact marks switched off (runs of `u32 length, r, g, b`), which
     evalharness's canvas must equal pixel for pixel.
   - `trajectories.tsv`: 4 episodes (seeds 100010-100013) of 80 actions each, the actions drawn
     by numpy's `default_rng(7)` around the block, with GPC's agent position and block pose after
     every action; `scenarios::pusht::gpc_render::tests::drift_against_gpcs_pymunk` replays the
     actions in evalharness's MuJoCo scene from the same reset and prints how far they drift.

Usage: scripts/crosscheck_gpc_pusht.py --gpc PATH_TO_DRIFTWORLD_CHECKOUT [--write-fixtures]
"""

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gpc", required=True, help="a checkout of the official DriftWorld repository")
    ap.add_argument("--write-fixtures", action="store_true", help="write scenarios/fixtures/gpc_pusht/")
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
    if a.write_fixtures:
        write_fixtures(PushTEnv)


def state_of(env):
    return list(env.agent.position) + list(env.block.position) + [env.block.angle] + list(env.goal_pose)


def write_fixtures(PushTEnv):
    import numpy as np
    import pymunk
    import pusht_env

    out = ROOT / "scenarios/fixtures/gpc_pusht"
    out.mkdir(parents=True, exist_ok=True)
    env = PushTEnv(domain_filename="push_t", render_action=False)
    rng = np.random.default_rng(1)
    states, frames = [], []
    for seed in range(100000, 100006):
        env.seed(seed)
        env.reset()
        for _ in range(4):
            for _ in range(int(rng.integers(1, 6))):
                env.step(np.array(env.block.position) + rng.normal(0, 30, 2))
            states.append(state_of(env))
            frames.append(env._render_frame("rgb_array"))
    head = "agent_x\tagent_y\tblock_x\tblock_y\tblock_theta\tgoal_x\tgoal_y\tgoal_theta\n"
    (out / "frames.tsv").write_text(head + "".join("\t".join(repr(float(v)) for v in s) + "\n" for s in states))
    np.stack(frames).astype(np.uint8).tofile(out / "frames96.bin")

    # The canvases without pymunk's contact marks: put the states back and draw shapes only.
    draw = pusht_env.DrawOptions.__init__

    def shapes_only(self, surface):
        draw(self, surface)
        self.flags = pymunk.SpaceDebugDrawOptions.DRAW_SHAPES

    pusht_env.DrawOptions.__init__ = shapes_only
    rle = bytearray()
    for s in states[:4]:
        env.agent.position = s[0:2]
        env.block.angle = s[4]
        env.block.position = s[2:4]
        env.space.reindex_shapes_for_body(env.block)
        env.space.reindex_shapes_for_body(env.agent)
        env.goal_pose = np.array(s[5:8])
        flat = env._render_frame("rgb_array", out_size=512).reshape(-1, 3)
        change = np.flatnonzero((flat[1:] != flat[:-1]).any(1)) + 1
        starts = np.concatenate([[0], change, [len(flat)]])
        for i, j in zip(starts[:-1], starts[1:]):
            rle += int(j - i).to_bytes(4, "little") + bytes(flat[i].tolist())
    pusht_env.DrawOptions.__init__ = draw
    (out / "canvas512.rle").write_bytes(bytes(rle))

    act = np.random.default_rng(7)
    lines = ["seed\tstep\taction_x\taction_y\tagent_x\tagent_y\tblock_x\tblock_y\tblock_theta\n"]
    for seed in range(100010, 100014):
        env.seed(seed)
        env.reset()
        for step in range(80):
            a_xy = np.clip(np.array(env.block.position) + act.normal(0, 40, 2), 20, 492)
            env.step(a_xy)
            s = state_of(env)
            lines.append("\t".join([str(seed), str(step)] + [repr(float(v)) for v in list(a_xy) + s[:5]]) + "\n")
    (out / "trajectories.tsv").write_text("".join(lines))
    print(f"wrote {len(states)} frames, 4 canvases and {len(lines) - 1} trajectory steps into {out}")


if __name__ == "__main__":
    main()
