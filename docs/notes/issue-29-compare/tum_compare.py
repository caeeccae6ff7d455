"""Read many TUM texts (valid, malformed, random corruptions) and print one line each: the
trajectory's hash or the error message. Run once per source tree and diff the outputs."""
import hashlib
import sys
import tempfile
from pathlib import Path

import numpy as np

from posekit.errors import PosekitError
from posekit.localcal.registration.formats import read_trajectory
from posekit.localcal.registration.formats.tum import read_tum

rng = np.random.default_rng(0)
good = ["# timestamp tx ty tz qx qy qz qw\n"]
for k in range(30):
    q = rng.normal(size=4); q /= np.linalg.norm(q)
    good.append(f"{k * 0.1:.6f} {rng.normal():.6f} {rng.normal():.6f} {rng.normal():.6f} "
                f"{q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n")
base = "".join(good)
cases = {
    "good": base, "empty": "", "comments": "# a\n\n  # b\n", "commas": base.replace(" ", ","),
    "inline#": base.replace("\n", " # c\n", 3), "7fields": base + "1 2 3 4 5 6 7\n",
    "12fields": "1 0 0 0 0 1 0 0 0 0 1 0\n", "zero": base + "9 0 zero 0 0 0 0 1\n",
    "long": base + "9 0 " + "x" * 60 + " 0 0 0 0 1\n", "nan": base + "9 0 nan 0 0 0 0 1\n",
    "inf": base + "9 0 0 inf 0 0 0 1\n", "norm": base + "9 0 0 0 0 0 0 2\n",
    "big": base + "9 2e9 0 0 0 0 0 1\n", "back": base + "0.05 0 0 0 0 0 0 1\n",
    "under": base + "9 1_0 0 0 0 0 0 1\n", "arabic": base + "9 ١ 0 0 0 0 0 1\n",
    "tabs": base.replace(" ", "\t"), "crlf": base.replace("\n", "\r\n"),
    "norm+comma": base.replace(" ", ",") + "9,0,0,0,0,0,0,2\n",
    "back+#": base + "0.05 0 0 0 0 0 0 1 # x\n", "9fields": base + "9 0 0 0 0 0 0 1 1\n",
    "hex": base + "9 0x10 0 0 0 0 0 1\n",
}
lines = base.splitlines(keepends=True)
for k in range(300):                      # random corruptions of one line
    ls = list(lines)
    i = int(rng.integers(len(ls)))
    f = ls[i].split()
    op = k % 6
    if op == 0 and f:
        f[int(rng.integers(len(f)))] = rng.choice(["nan", "-", "1e999", "abc", "#", "1,2", "", "0.5.1", "+1", "1e-3"])
    elif op == 1 and f:
        del f[int(rng.integers(len(f)))]
    elif op == 2:
        f.append(str(rng.normal()))
    elif op == 3:
        ls.insert(i, ls[int(rng.integers(len(ls)))])
    elif op == 4 and f:
        f[int(rng.integers(len(f)))] = f"{rng.normal() * 10 ** rng.integers(0, 12):.6g}"
    else:
        f = ["#"] + f
    if op not in (3,):
        ls[i] = " ".join(f) + "\n"
    cases[f"rand{k}"] = "".join(ls)

out = []
with tempfile.TemporaryDirectory() as d:
    for name, text in cases.items():
        p = Path(d) / "t.tum"
        p.write_text(text, encoding="utf-8")
        for reader in ("read_tum", "read_trajectory_tum"):
            try:
                tr = read_tum(p) if reader == "read_tum" else read_trajectory(p, fmt="tum")
                h = hashlib.sha256(np.ascontiguousarray(tr.t_s).tobytes() + np.ascontiguousarray(tr.T).tobytes())
                res = f"ok {len(tr)} {h.hexdigest()[:16]}"
            except PosekitError as exc:
                res = f"{type(exc).__name__}: {str(exc).replace(d, 'DIR')}"
            out.append(f"{name} {reader}: {res}")
print("\n".join(out))
print(len(cases), "cases", file=sys.stderr)
