#!/usr/bin/env python3
"""Cross-check evalharness's Lift and Can against robosuite's own Lift and PickPlaceCan.

Evidence, not a CI test: it needs the package index. It
1. installs robosuite==1.5.2 and mujoco==3.17.0 into a throw-away virtual
   environment (``--venv``, default ``.robosuite/venv``, git-ignored);
2. runs ``evalharness simulate --scenario scenarios/{lift,can}_robosuite.toml``
   (robosuite's rendering) for one expert and one
   random-action episode, stepping past success (``--no-early-stop``);
3. starts robosuite's ``Lift`` / ``PickPlaceCan`` from the same initial state
   (the object's size, position and yaw, the arm's joints), feeds it the same
   7-D actions and prints, for 25, 50, 100 and 200 steps, the largest
   end-effector and object position differences so far and whether success
   agrees;
4. with ``--picture PATH``, saves robosuite's agentview renders over
   evalharness's at steps 0 and 40 of the expert episode, and prints their mean
   absolute pixel difference.

Usage: scripts/crosscheck_robosuite.py [--task lift|can|both] [--seed 0] [--binary target/release/evalharness]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STEPS = (25, 50, 100, 200)


def ensure_venv(venv: Path) -> Path:
    py = venv / "bin" / "python"
    if not py.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    stamp = venv / ".installed-robosuite-1.5.2-mujoco-3.17.0"
    if not stamp.exists():
        subprocess.run(
            [str(py), "-m", "pip", "install", "--quiet", "robosuite==1.5.2", "mujoco==3.17.0", "Pillow"],
            check=True,
        )
        stamp.touch()
    return py


def run_evalharness(binary: str, task: str, policy: str, seed: int, out: Path) -> None:
    # robosuite's rendering (multisampling, reflections), not evalharness's cheaper default,
    # so that the pictures compare like with like.
    scenario = ROOT / "scenarios" / f"{task}_robosuite.toml"
    subprocess.run(
        [binary, "--quiet", "simulate", "--scenario", str(scenario), "--policy", policy, "--episodes", "1",
         "--seed-start", str(seed), "--max-steps", str(max(STEPS) + 1), "--no-early-stop",
         "--jobs", "1", "--force", "--out", str(out)],
        check=True,
    )


# The part that runs inside the virtual environment: robosuite 1.5.2 on MuJoCo 3.17.0.
INNER = r'''
import json, os, sys, types
os.environ.setdefault("MUJOCO_GL", "egl")
import numpy as np
import mujoco
import robosuite as suite
import robosuite.utils.binding_utils as bu
import robosuite.controllers.parts.controller as ctl
import robosuite.environments.manipulation.lift as lift_mod

# robosuite 1.5.2 predates two MuJoCo 3.17 API changes; adapt to them without
# changing any physics: joint types compare as plain ints, and mj_fullM takes
# (model, data, dst) instead of (model, dst, qM).
joint_types = {n: int(getattr(mujoco.mjtJoint, n)) for n in ("mjJNT_FREE", "mjJNT_BALL", "mjJNT_SLIDE", "mjJNT_HINGE")}
proxy = types.SimpleNamespace(**{k: getattr(mujoco, k) for k in dir(mujoco) if not k.startswith("__")})
proxy.mjtJoint = types.SimpleNamespace(**joint_types)
bu.mujoco = proxy
full_m = mujoco.mj_fullM
cproxy = types.SimpleNamespace(**{k: getattr(mujoco, k) for k in dir(mujoco) if not k.startswith("__")})
cproxy.mj_fullM = lambda model, dst, data: full_m(model, data, dst)
ctl.mujoco = cproxy
bu.MjData.qM = property(lambda self: self._data)

case = json.load(open(sys.argv[1]))
PICTURE_STEPS = (0, 40)
init = case["init"]
if case["task"] == "lift":
    half = init["cube_half"]
    orig_box = lift_mod.BoxObject
    lift_mod.BoxObject = lambda **kw: orig_box(**{**kw, "size_min": half, "size_max": half})
    env_name, joint, body, pose = "Lift", "cube_joint0", "cube_main", init["cube_pos"] + init["cube_quat"]
else:
    env_name, joint, body, pose = "PickPlaceCan", "Can_joint0", "Can_main", init["can_pos"] + init["can_quat"]

# No hard reset: a hard reset rebuilds the robots and forgets init_qpos.
env = suite.make(env_name, robots="Panda", initialization_noise=None, has_renderer=False,
                 has_offscreen_renderer=True, use_camera_obs=False, ignore_done=True, hard_reset=False, seed=0)
env.robots[0].init_qpos = np.array(init["arm_q"])
env.reset()
sim = env.sim
sim.data.set_joint_qpos(joint, np.array(pose))
sim.data.set_joint_qvel(joint, np.zeros(6))
sim.forward()
site = "gripper0_right_grip_site"
cube = sim.model.body_name2id(body)
out = {"eef": [], "cube": [], "success": []}
def record():
    out["eef"].append(np.array(sim.data.get_site_xpos(site)).tolist())
    out["cube"].append(np.array(sim.data.body_xpos[cube]).tolist())
    out["success"].append(bool(env._check_success()))
def picture(k):
    if case.get("picture") and k in PICTURE_STEPS:
        img = sim.render(camera_name="agentview", width=256, height=256)[::-1]
        from PIL import Image
        Image.fromarray(np.ascontiguousarray(img)).save(case["picture"].format(k))
record()
picture(0)
for k, a in enumerate(case["actions"]):
    env.step(np.array(a))
    record()
    picture(k + 1)
json.dump(out, open(sys.argv[2], "w"))
'''


def load_episode(out: Path):
    rows = [json.loads(l) for l in (out / "episodes.jsonl").read_text().splitlines()]
    init = json.loads((out / "initial_states.jsonl").read_text().splitlines()[0])
    return rows, init


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--task", choices=("lift", "can", "both"), default="both")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--binary", default=str(ROOT / "target" / "release" / "evalharness"))
    ap.add_argument("--venv", default=str(ROOT / ".robosuite" / "venv"))
    ap.add_argument("--picture", help="save robosuite's and evalharness's agentview renders (PNG; with "
                    "--task both, TASK in the path is replaced by the task's name)")
    args = ap.parse_args()
    py = ensure_venv(Path(args.venv))
    print("| task | behaviour | steps | max end-effector diff (mm) | max object diff (mm) | success (evalharness / robosuite) |")
    print("|---|---|---|---|---|---|")
    tasks = ("lift", "can") if args.task == "both" else (args.task,)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for task, policy in ((t, p) for t in tasks for p in ("expert", "random")):
            out = tmp / f"{task}-{policy}"
            run_evalharness(args.binary, task, policy, args.seed, out)
            rows, init = load_episode(out)
            case = {"task": task, "init": init, "actions": [r["action"] for r in rows[: max(STEPS)]]}
            picture = Path(args.picture.replace("TASK", task)) if args.picture else None
            if picture and policy == "expert":
                case["picture"] = str(tmp / "robosuite_{}.png")
            (tmp / "case.json").write_text(json.dumps(case))
            subprocess.run([str(py), "-c", INNER, str(tmp / "case.json"), str(tmp / "rs.json")], check=True,
                           stderr=subprocess.DEVNULL)
            rs = json.loads((tmp / "rs.json").read_text())
            # Row k holds the state before action k: the state after k actions.
            eh_eef = [r["state"][7:10] for r in rows]
            eh_cube = [r["state"][0:3] for r in rows]
            eh_success = [False] + [r["success"] for r in rows]
            diff = lambda a, b: max(abs(x - y) for x, y in zip(a, b)) * 1000.0
            for n in STEPS:
                de = max(diff(eh_eef[k], rs["eef"][k]) for k in range(n + 1))
                dc = max(diff(eh_cube[k], rs["cube"][k]) for k in range(n + 1))
                print(f"| {task} | {policy} | {n} | {de:.3f} | {dc:.3f} | {eh_success[n]} / {rs['success'][n]} |")
            if picture and policy == "expert":
                side_by_side(out, tmp, picture, py)
    return 0


def side_by_side(out: Path, tmp: Path, picture: Path, py: Path) -> None:
    """Robosuite's agentview (top) over evalharness's (bottom) at steps 0 and 40."""
    gif = next(out.glob("episode_*.gif"))
    code = (
        "import sys\nfrom PIL import Image\n"
        "tmp, gif, dest = sys.argv[1], sys.argv[2], sys.argv[3]\n"
        "g = Image.open(gif)\n"
        "o = Image.new('RGB', (2 * 256 + 8, 2 * 256 + 8), 'white')\n"
        "for col, k in enumerate((0, 40)):\n"
        "    a = Image.open(f'{tmp}/robosuite_{k}.png').convert('RGB')\n"
        "    g.seek(k); b = g.convert('RGB').resize(a.size)\n"
        "    o.paste(a, (col * 264, 0)); o.paste(b, (col * 264, 264))\n"
        "    pa, pb = a.tobytes(), b.tobytes()\n"
        "    print(k, sum(abs(x - y) for x, y in zip(pa, pb)) / len(pa))\n"
        "o.save(dest)\n"
    )
    picture.parent.mkdir(parents=True, exist_ok=True)
    res = subprocess.run([str(py), "-c", code, str(tmp), str(gif), str(picture)], check=True,
                         capture_output=True, text=True).stdout
    print(f"\nagentview at steps 0 and 40: robosuite (top), evalharness (bottom; its GIF, 256 colours) -> {picture}")
    for line in res.splitlines():
        k, mad = line.split()
        print(f"step {k}: mean absolute difference per channel (0-255) {float(mad):.2f}")
    print()


if __name__ == "__main__":
    sys.exit(main())
