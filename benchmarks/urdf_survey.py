"""URDF corpus survey (not a timing benchmark): every ``*.urdf`` (and ``robot.xml``) under the folders
given — does Pinocchio read it, does posekit, which default chain, and do the chains agree.

For each file Pinocchio reads: ``load_urdf(path)`` (the default chain); when the default is
ambiguous, every candidate tip the message names; each chain's forward kinematics and geometric
Jacobian against Pinocchio's at 20 random joint vectors (within the limits, clipped to ±π).

Usage::

    python benchmarks/urdf_survey.py FOLDER [FOLDER ...] [--list]

The numbers in docs/notes/issue-27.md come from the public collections named there.
"""

import argparse
import contextlib
import io
import math
import re
from pathlib import Path

import numpy as np


def _pin_reference(pin, path, chain):
    from posekit.robots import PRISMATIC

    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    fid, bid = model.getFrameId(chain.tip_link, pin.BODY), model.getFrameId(chain.base_link, pin.BODY)
    joints = [model.joints[model.getJointId(n)] for n in chain.joint_names]
    pri = np.array([t == PRISMATIC for t in chain.joint_types])

    def f(q):
        qp = pin.neutral(model)
        for j, v in zip(joints, np.where(pri, q / 1000, q)):
            if j.nq == 2:
                qp[j.idx_q:j.idx_q + 2] = math.cos(v), math.sin(v)
            else:
                qp[j.idx_q] = v
        pin.forwardKinematics(model, data, qp)
        pin.updateFramePlacements(model, data)
        J = pin.computeFrameJacobian(model, data, qp, fid, pin.LOCAL_WORLD_ALIGNED)[:, [j.idx_v for j in joints]]
        Twb = data.oMf[bid].homogeneous
        T = np.linalg.inv(Twb) @ data.oMf[fid].homogeneous
        T[:3, 3] *= 1000
        R = Twb[:3, :3].T
        J = np.vstack([R @ J[:3], R @ J[3:]])
        J[:3, ~pri] *= 1000
        return T, J
    return f


def survey(folders, listing=False):
    import pinocchio as pin

    from posekit.errors import PosekitError
    from posekit.robots import load_urdf

    files = sorted(f for d in folders for f in Path(d).rglob("*")
                   if f.is_file() and (f.suffix.lower() == ".urdf" or f.name == "robot.xml"))
    rng = np.random.default_rng(0)
    n_pin = n_read = n_default = n_chains = n_agree = 0
    worst = np.zeros(3)
    refused = []
    for f in files:
        try:
            with contextlib.redirect_stderr(io.StringIO()):
                pin.buildModelFromUrdf(str(f))
        except Exception:                               # noqa: BLE001 - Pinocchio's many errors
            continue
        n_pin += 1
        try:
            chain = load_urdf(f)
            tips, what = [chain.tip_link], f"{chain.base_link} -> {chain.tip_link}, {chain.n_joints} joints"
            n_default += 1
        except PosekitError as exc:
            msg = str(exc)
            if "candidate tips" in msg:
                tips = re.findall(r"'([^']+)'", msg.split("candidate tips")[1].split(";")[0])
                what = "two or more equal arms: " + ", ".join(tips)
            elif "no arm joint" in msg:
                tips, what = [], "no arm (a gripper, a base)"
            else:
                refused.append((f, msg))
                continue
        n_read += 1
        for tip in tips:
            chain = load_urdf(f, tip_link=tip)
            ref = _pin_reference(pin, f, chain)
            lo, hi = np.clip(chain.q_min, -math.pi, math.pi), np.clip(chain.q_max, -math.pi, math.pi)
            e = np.zeros(3)
            for q in rng.uniform(lo, hi, (20, chain.n_joints)):
                T, J = chain.forward_kinematics_and_jacobian(q)
                Tp, Jp = ref(q)
                e = np.maximum(e, [np.abs(T[:3, 3] - Tp[:3, 3]).max(), np.abs(T[:3, :3] - Tp[:3, :3]).max(),
                                   np.abs(J - Jp).max() / max(1.0, np.abs(Jp).max())])
            n_chains += 1
            n_agree += bool(e[0] < 1e-6 and e[1] < 1e-9 and e[2] < 1e-9)
            worst = np.maximum(worst, e)
        if listing:
            print(f"{what:70s} {f}")
    for f, msg in refused:
        print(f"refused: {msg.replace(str(f), f.name)[:200]}")
    print(f"{len(files)} files; Pinocchio reads {n_pin}; posekit reads {n_read} of them ({n_default} with a default "
          f"chain); {n_agree}/{n_chains} chains agree with Pinocchio; worst |dp| {worst[0]:.2g} mm, |dR| "
          f"{worst[1]:.2g}, relative |dJ| {worst[2]:.2g}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+")
    ap.add_argument("--list", action="store_true", help="print every file's default chain")
    a = ap.parse_args()
    survey(a.folders, a.list)
