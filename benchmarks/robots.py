"""Benchmark behind ``posekit bench robots``.

Times posekit's robot kinematics — tool pose ``T_base_tool`` and geometric Jacobian (base
frame, rows ``[v; w]``) of one compiled kernel pass — on the bundled UR10 (``base_link`` ->
``ee_link``) and ABB IRB 6640 (``base_link`` -> ``tool0``) URDFs, 6 joints each, one thread,
and in the same run the same quantities from Pinocchio, the library a user would otherwise
pick, called the way a user would write it (model built once from the same URDF, then per
configuration ``forwardKinematics`` + ``updateFramePlacement`` + ``computeFrameJacobian(...,
LOCAL_WORLD_ALIGNED)`` + ``data.oMf[fid].homogeneous``; the joint vector already in
Pinocchio's layout, its metres and its extra Jacobian columns left as they are).

1. One configuration per call from Python: ours ``chain.forward_kinematics_and_jacobian(q,
   check=False)`` — the unchecked path that the systems (seam filter, resolved-rate control,
   calibration) call in their inner loops, so the one that matters — against the Pinocchio
   sequence; also ours as two calls (``forward_kinematics`` + ``geometric_jacobian``) and the
   validating call (``check=True``, what a user gets by default). Target: ours within 2x of
   Pinocchio (ratio ours / Pinocchio <= 2).
2. A batch: ours on ``q`` of shape (10000, 6) in one call, per configuration (target <= 2 µs),
   against a Python loop of the Pinocchio sequence over the same configurations (Pinocchio
   has no batched call).

Before any timing both sides must agree on every timed configuration (FK translation to
1e-6 mm, rotation and Jacobian to 1e-9 relative); otherwise the run stops with an error.
Each time is the median over passes of the mean per call of a loop of ``count`` calls
(default 2,000); the machines are shared and noisy, so compare ratios. ``realtime_factor`` is
a 1 kHz control period over our median time per configuration.
"""

import os
import sys
import time
from pathlib import Path

import numpy as np

from posekit.errors import EstimationError

HERE = Path(__file__).resolve().parent
MODELS = ("ur10", "abb_irb6640")
CONTROL_PERIOD_MS = 1.0          # a 1 kHz robot control loop
DEFAULT_CALLS = 2_000            # calls per timed loop (one configuration per call)
BATCH = 10_000                   # configurations of the batched call
PASSES = 7                       # single-configuration passes (median over them)
BATCH_PASSES = 5
WARMUP_S = 0.5                   # busy warm-up per model (the VM's vCPU ramps up after idling)
TARGET_RATIO = 2.0               # ours / Pinocchio, one configuration
TARGET_BATCH_US = 2.0            # ours per configuration in a batch
TOL_T_MM = 1e-6                  # FK translation, mm
TOL_REL = 1e-9                   # rotation and Jacobian, relative
PEER = ("pinocchio forwardKinematics + updateFramePlacement + computeFrameJacobian(LOCAL_WORLD_ALIGNED) "
        "+ oMf.homogeneous")


def import_pinocchio():
    """``pinocchio``, or a one-line ConfigError saying how to install it (the CLI exits 1)."""
    try:
        import pinocchio
    except ImportError:
        from posekit.errors import ConfigError
        raise ConfigError('posekit bench robots needs Pinocchio (PyPI package "pin") as its peer: '
                          'pip install -e ".[bench]" (or ".[test]")') from None
    return pinocchio


class PinocchioPeer:
    """The same robot in Pinocchio, built from the same URDF file.

    Pinocchio's configuration can be longer than the chain's (the ABB arm's two side-branch
    joints, ``joint_piston`` and ``joint_cylinder``, are in the model): :meth:`q` puts the
    chain's joint values at their joints' ``idx_q`` (by name) into ``pin.neutral`` (the other
    joints at 0). :meth:`step` is the timed call; :meth:`in_posekit_units` converts its output
    (metres, one Jacobian column per Pinocchio velocity) to posekit's (mm, the chain's joints).
    """

    def __init__(self, chain, path):
        pin = import_pinocchio()
        self.pin = pin
        self.model = pin.buildModelFromUrdf(str(path))
        self.data = self.model.createData()
        self.fid = self.model.getFrameId(chain.tip_link)
        self.base = self.model.getFrameId(chain.base_link)
        if self.fid >= len(self.model.frames) or self.base >= len(self.model.frames):
            raise EstimationError(f"{chain.name}: pinocchio has no frame {chain.tip_link!r} or {chain.base_link!r}")
        names = list(self.model.names)
        missing = [n for n in chain.joint_names if n not in names]
        if missing:
            raise EstimationError(f"{chain.name}: pinocchio model has no joint(s) {missing}")
        joints = [self.model.joints[names.index(n)] for n in chain.joint_names]
        if any(j.nq != 1 for j in joints):
            raise EstimationError(f"{chain.name}: expected one-variable joints on the chain in pinocchio")
        self.idx_q = np.array([j.idx_q for j in joints])
        self.idx_v = np.array([j.idx_v for j in joints])
        self.frame = pin.LOCAL_WORLD_ALIGNED

    def q(self, Q):
        """Pinocchio configurations (N, nq) for the chain's joint values ``Q`` (N, n), rad."""
        Q = np.atleast_2d(Q)
        out = np.tile(self.pin.neutral(self.model), (Q.shape[0], 1))
        out[:, self.idx_q] = Q
        return out

    def step(self, q):
        """The timed call: tool pose (4, 4) in metres and frame Jacobian (6, nv), as a user writes it."""
        pin, model, data, fid = self.pin, self.model, self.data, self.fid
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacement(model, data, fid)
        J = pin.computeFrameJacobian(model, data, q, fid, self.frame)
        return data.oMf[fid].homogeneous, J

    def in_posekit_units(self, q):
        """``(T_base_tool (4, 4) mm, J (6, n) [v mm/rad; w] base frame)`` at Pinocchio's ``q``."""
        T, J = self.step(q)
        self.pin.updateFramePlacement(self.model, self.data, self.base)
        T_world_base = self.data.oMf[self.base].homogeneous
        T = np.linalg.inv(T_world_base) @ T
        T[:3, 3] *= 1000.0
        R = T_world_base[:3, :3].T
        J = J[:, self.idx_v]
        return T, np.vstack([1000.0 * (R @ J[:3]), R @ J[3:]])


def sample_q(chain, n: int, rng) -> np.ndarray:
    """``n`` configurations (n, joints) uniform within the joint limits clipped to ±π."""
    lo = np.clip(chain.q_min, -np.pi, np.pi)
    hi = np.clip(chain.q_max, -np.pi, np.pi)
    return rng.uniform(lo, hi, (n, chain.n_joints))


def _errors(T, J, T_ref, J_ref) -> dict:
    """Largest disagreements of stacks (N, 4, 4) / (N, 6, n) against the reference."""
    scale_v = np.maximum(1.0, np.abs(J_ref[:, :3]).max(axis=(1, 2)))        # mm/rad: relative per configuration
    return {"max_err_t_mm": float(np.abs(T[:, :3, 3] - T_ref[:, :3, 3]).max()),
            "max_err_R": float(np.abs(T[:, :3, :3] - T_ref[:, :3, :3]).max()),
            "max_rel_err_Jv": float((np.abs(J[:, :3] - J_ref[:, :3]).max(axis=(1, 2)) / scale_v).max()),
            "max_err_Jw": float(np.abs(J[:, 3:] - J_ref[:, 3:]).max())}


def check_agreement(chain, peer, Q, *, batch=None) -> dict:
    """Raise ``EstimationError`` unless posekit and Pinocchio agree on every configuration of ``Q``.

    Checked: ours one call per configuration (joint and separate FK / Jacobian calls, with and
    without ``check``) and, for ``batch`` (a second (M, n) array, default none), ours in one
    batched call — each against Pinocchio at the same joint values. Tolerances: translation
    1e-6 mm; rotation entries and angular Jacobian rows 1e-9; linear Jacobian rows 1e-9
    relative to the largest entry of that configuration's linear rows (mm/rad, >= 1).
    Returns the largest errors (over all checked paths).
    """
    Q = np.ascontiguousarray(Q, dtype=np.float64)
    sets = [("single", Q)] if batch is None else [("single", Q), ("batch", np.ascontiguousarray(batch, float))]
    worst = {}
    for label, X in sets:
        ref = [peer.in_posekit_units(qp) for qp in peer.q(X)]
        T_ref = np.array([r[0] for r in ref])
        J_ref = np.array([r[1] for r in ref])
        if label == "single":
            rows = [chain.forward_kinematics_and_jacobian(q, check=False) for q in X]
            paths = {"forward_kinematics_and_jacobian(check=False)": rows,
                     "forward_kinematics + geometric_jacobian (check=False)":
                         [(chain.forward_kinematics(q, check=False), chain.geometric_jacobian(q, check=False))
                          for q in X],
                     "forward_kinematics_and_jacobian(check=True)":
                         [chain.forward_kinematics_and_jacobian(q, check=True) for q in X]}
            paths = {k: (np.array([r[0] for r in v]), np.array([r[1] for r in v])) for k, v in paths.items()}
        else:
            paths = {"forward_kinematics_and_jacobian(batch, check=False)":
                     chain.forward_kinematics_and_jacobian(X, check=False)}
        for what, (T, J) in paths.items():
            err = _errors(T, J, T_ref, J_ref)
            bad = [f"{k} = {v:.3g}" for k, v, tol in (("translation", err["max_err_t_mm"], TOL_T_MM),
                                                       ("rotation", err["max_err_R"], TOL_REL),
                                                       ("linear Jacobian (relative)", err["max_rel_err_Jv"], TOL_REL),
                                                       ("angular Jacobian", err["max_err_Jw"], TOL_REL))
                   if not v <= tol]
            if bad:
                raise EstimationError(f"posekit bench robots: {chain.name}: posekit {what} disagrees with pinocchio "
                                   f"on {len(X)} {label} configurations: {', '.join(bad)} "
                                   f"(tolerances {TOL_T_MM:g} mm, {TOL_REL:g} relative)")
            for k, v in err.items():
                worst[k] = max(worst.get(k, 0.0), v)
    return worst


def _loop_ours(f, qs) -> float:
    t0 = time.perf_counter()
    for q in qs:
        f(q, check=False)
    return time.perf_counter() - t0


def _loop_ours_two(chain, qs) -> float:
    fk, jac = chain.forward_kinematics, chain.geometric_jacobian
    t0 = time.perf_counter()
    for q in qs:
        fk(q, check=False)
        jac(q, check=False)
    return time.perf_counter() - t0


def _loop_checked(f, qs) -> float:
    t0 = time.perf_counter()
    for q in qs:
        f(q, check=True)
    return time.perf_counter() - t0


def _loop_pin(peer, qps) -> float:
    pin, model, data, fid, frame = peer.pin, peer.model, peer.data, peer.fid, peer.frame
    fk, place, jac = pin.forwardKinematics, pin.updateFramePlacement, pin.computeFrameJacobian
    t0 = time.perf_counter()
    for q in qps:                                   # the sequence of PinocchioPeer.step, inlined
        fk(model, data, q)
        place(model, data, fid)
        jac(model, data, q, fid, frame)
        data.oMf[fid].homogeneous
    return time.perf_counter() - t0


def _bench_model(name, calls, batch, passes, batch_passes, rng):
    from posekit.robots import bundled_robot_path, robot_model

    chain = robot_model(name)
    peer = PinocchioPeer(chain, bundled_robot_path(name))
    Q = sample_q(chain, calls, rng)
    QB = sample_q(chain, batch, rng)
    errors = check_agreement(chain, peer, Q, batch=QB)

    qs = [np.ascontiguousarray(q) for q in Q]            # each call gets its own 1-D float64 array
    qps = [np.ascontiguousarray(q) for q in peer.q(Q)]
    qbs = [np.ascontiguousarray(q) for q in peer.q(QB)]
    f = chain.forward_kinematics_and_jacobian
    t_end = time.perf_counter() + WARMUP_S
    while time.perf_counter() < t_end:
        _loop_ours(f, qs[:200])
        _loop_pin(peer, qps[:200])
        f(QB[:1000], check=False)
    single = {"ours": [], "pin": [], "two": [], "checked": []}
    for _ in range(passes):                          # interleaved: each pass sees the same machine state
        single["ours"].append(_loop_ours(f, qs) / calls)
        single["pin"].append(_loop_pin(peer, qps) / calls)
        single["two"].append(_loop_ours_two(chain, qs) / calls)
        single["checked"].append(_loop_checked(f, qs) / calls)
    batched = {"ours": [], "pin": []}
    for _ in range(batch_passes):
        t0 = time.perf_counter()
        f(QB, check=False)
        batched["ours"].append((time.perf_counter() - t0) / batch)
        batched["pin"].append(_loop_pin(peer, qbs) / batch)
    med = {k: float(np.median(v)) * 1e3 for k, v in single.items()}          # ms per call
    medb = {k: float(np.median(v)) * 1e3 for k, v in batched.items()}         # ms per configuration
    common = {"robot": name, "joints": chain.n_joints, "pinocchio_nq": int(peer.model.nq),
              "pinocchio_nv": int(peer.model.nv), **errors}
    ratio = med["ours"] / med["pin"]
    single_row = {"name": f"robots.fk_jac.single.{name}", "ours_ms": med["ours"], "baseline": PEER,
                  "baseline_ms": med["pin"], "speedup": med["pin"] / med["ours"], "ratio": ratio,
                  "realtime_factor": CONTROL_PERIOD_MS / med["ours"],
                  "ours_two_calls_ms": med["two"], "ours_checked_ms": med["checked"],
                  "ours_us": med["ours"] * 1e3, "baseline_us": med["pin"] * 1e3,
                  "target_ratio": TARGET_RATIO, "target_met": bool(ratio <= TARGET_RATIO),
                  "calls": calls, "passes": passes, **common}
    batch_row = {"name": f"robots.fk_jac.batch.{name}", "ours_ms": medb["ours"],
                 "baseline": PEER + ", Python loop", "baseline_ms": medb["pin"],
                 "speedup": medb["pin"] / medb["ours"], "ratio": medb["ours"] / medb["pin"],
                 "realtime_factor": CONTROL_PERIOD_MS / medb["ours"],
                 "ours_us": medb["ours"] * 1e3, "baseline_us": medb["pin"] * 1e3,
                 "ours_call_ms": medb["ours"] * batch, "target_us": TARGET_BATCH_US,
                 "target_met": bool(medb["ours"] * 1e3 <= TARGET_BATCH_US),
                 "batch": batch, "passes": batch_passes, **common}
    return [single_row, batch_row]


def run(count=None, verbose=True, models=MODELS, batch=BATCH, passes=PASSES, batch_passes=BATCH_PASSES):
    """Run the benchmark; returns the JSON rows (``posekit bench`` contract).

    ``count``: calls per timed single-configuration loop (default 2,000; also the number of
    distinct configurations). ``batch``: configurations of the batched call (default 10,000).
    ``passes`` / ``batch_passes``: repetitions whose median is reported.
    """
    import_pinocchio()                               # a missing peer fails before any work
    calls = DEFAULT_CALLS if count is None else max(int(count), 10)
    rng = np.random.default_rng(0)
    rows = []
    for name in models:
        rows += _bench_model(name, calls, int(batch), int(passes), int(batch_passes), rng)
    if verbose:
        import pinocchio
        print(f"posekit bench robots: FK + geometric Jacobian of the tool, 6 joints, one thread; posekit vs "
              f"pinocchio {pinocchio.__version__} (same URDF); medians of {passes} passes x {calls} calls "
              f"(single) and {batch_passes} passes x {batch} configurations (batch); agreement checked first")
        print(f"{'robot':<13}{'call':<36}{'posekit':>10}{'pinocchio':>12}{'ours/pin':>10}{'speedup':>9}")
        for r in rows:
            single = ".single." in r["name"]
            what = "one configuration, fk_and_jacobian" if single else f"batch of {r['batch']}, per configuration"
            print(f"{r['robot']:<13}{what:<36}{r['ours_us']:>8.2f}µs{r['baseline_us']:>10.2f}µs"
                  f"{r['ratio']:>10.2f}{r['speedup']:>8.1f}x")
            if single:
                print(f"{'':<13}{'  fk + jacobian, two calls':<36}{r['ours_two_calls_ms'] * 1e3:>8.2f}µs"
                      f"{'':>12}{r['ours_two_calls_ms'] / r['baseline_ms']:>10.2f}")
                print(f"{'':<13}{'  fk_and_jacobian, check=True':<36}{r['ours_checked_ms'] * 1e3:>8.2f}µs"
                      f"{'':>12}{r['ours_checked_ms'] / r['baseline_ms']:>10.2f}")
        worst = {k: max(r[k] for r in rows) for k in ("max_err_t_mm", "max_err_R", "max_rel_err_Jv", "max_err_Jw")}
        print(f"agreement with pinocchio (all timed configurations): translation {worst['max_err_t_mm']:.1e} mm, "
              f"rotation {worst['max_err_R']:.1e}, linear J {worst['max_rel_err_Jv']:.1e} rel., "
              f"angular J {worst['max_err_Jw']:.1e}")
        singles = [r for r in rows if ".single." in r["name"]]
        batches = [r for r in rows if ".batch." in r["name"]]
        print(f"target: one configuration ours/pinocchio <= {TARGET_RATIO:g} -> "
              + ", ".join(f"{r['robot']} {r['ratio']:.2f} ({'met' if r['target_met'] else 'NOT met'})" for r in singles)
              + f"; batch <= {TARGET_BATCH_US:g} µs per configuration -> "
              + ", ".join(f"{r['robot']} {r['ours_us']:.2f} µs ({'met' if r['target_met'] else 'NOT met'})"
                          for r in batches))
    return rows


if __name__ == "__main__":  # pragma: no cover
    sys.path.insert(0, str(HERE.parent / "src"))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from posekit.errors import PosekitError
    try:
        run()
    except PosekitError as exc:
        print(f"posekit: error: {exc}", file=sys.stderr)
        sys.exit(1)
