"""KITTI and EuRoC texts (valid and corrupted) through read_trajectory: hash or message per case."""
import hashlib
import tempfile
from pathlib import Path

import numpy as np

from posekit.errors import PosekitError
from posekit.localcal.registration.formats import read_trajectory

rng = np.random.default_rng(1)
from scipy.spatial.transform import Rotation
R = Rotation.random(20, random_state=1)
kit = "".join(" ".join(f"{v:.9e}" for v in np.c_[m, rng.normal(size=3)].ravel()) + "\n" for m in R.as_matrix())
q = R.as_quat()[:, [3, 0, 1, 2]]
eur = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n" + "".join(
    f"{1403636579758555392 + k * 5000000}," + ",".join(f"{v:.9f}" for v in (*rng.normal(size=3), *q[k])) + "\n"
    for k in range(20))
out = []
with tempfile.TemporaryDirectory() as d:
    for fmt, base, suffix, sep in (("kitti", kit, ".kitti", " "), ("euroc", eur, ".csv", ",")):
        lines = base.splitlines(keepends=True)
        cases = {"good": base, "empty": "", "inline#": base.replace("\n", " # c\n", 2), "long": base + sep.join(["x" * 60] * 12) + "\n"}
        for k in range(200):
            ls = list(lines)
            i = int(rng.integers(1 if fmt == "euroc" else 0, len(ls)))
            f = ls[i].rstrip("\n").split(sep)
            op = k % 4
            if op == 0:
                f[int(rng.integers(len(f)))] = rng.choice(["nan", "abc", "#", "", "1e999", "1_0", "5"])
            elif op == 1:
                del f[int(rng.integers(len(f)))]
            elif op == 2:
                f.append("1")
            else:
                f[int(rng.integers(len(f)))] = f"{rng.normal() * 10 ** rng.integers(0, 12):.6g}"
            ls[i] = sep.join(f) + "\n"
            cases[f"rand{k}"] = "".join(ls)
        for name, text in cases.items():
            p = Path(d) / f"t{suffix}"
            p.write_text(text)
            try:
                tr = read_trajectory(p, fmt=fmt, rate_hz=10.0)
                res = "ok " + hashlib.sha256(tr.t_s.tobytes() + np.ascontiguousarray(tr.T).tobytes()).hexdigest()[:16]
            except PosekitError as exc:
                res = f"{type(exc).__name__}: {str(exc).replace(d, 'DIR')}"
            out.append(f"{fmt} {name}: {res}")
print("\n".join(out))
