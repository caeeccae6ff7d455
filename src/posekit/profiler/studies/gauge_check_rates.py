"""Both error rates of the batch test of the gauge file (:mod:`~posekit.profiler.gauge.check`).

``python -m posekit.profiler.studies.gauge_check_rates faces NB K TOLS [--scale-sigma-ppm S] [--gen sim|simcal|ind]``
    one face of demo-5 20 µm off its file, NB batches of K profiles per face and declared
    ``tolerance_um`` in TOLS (comma-separated): batches the test lets pass, and for the poses
    left 'ok' the 95th percentile of |error| / std and the share within 2σ per component.
``python -m posekit.profiler.studies.gauge_check_rates good NB K GAUGES [--scale-sigma-ppm S] [--gen ...]``
    the true file: batches failed, poses suspect, share of each component within 2σ.
``python -m posekit.profiler.studies.gauge_check_rates tilts NB K TOLS``
    the nominal demo-5 file with a declared tolerance on a realistically machined gauge.

Generators: ``sim`` posekit's realistic simulator (:class:`~posekit.profiler.sim.realism.RealismModel`,
its defaults but machining, at :func:`~posekit.profiler.sim.poses.sample_poses`), ``simcal``
the same with the sensor's scale error 15 ppm instead of 100, ``ind`` the tests' independent
generator (tests/profiler/test_gauge_check.py; run from the repository root). Seeded: the
numbers in the README come from these commands.
"""

import argparse
from dataclasses import replace

import numpy as np

from ..estimate.pipeline import estimate_profiles
from ..gauge.model import bundled_gauge
from ..sensor import NoiseModel
from ..sim.poses import sample_poses
from ..sim.realism import RealismModel, build_as_built
from ..sim.render import render_profiles
from .evaluate import pose_errors

__all__ = ["face_off", "batch", "face_rates", "good_rates", "tilt_rates"]


def face_off(gauge, face: int, um: float):
    """``gauge`` with face ``face`` moved by ``um`` µm along its normal."""
    offsets = gauge.offsets.copy()
    offsets[face] += um * 1e-3
    return replace(gauge, offsets=offsets)


def batch(built, nominal, count: int, seed: int, gen: str, noise: NoiseModel, machining: bool = False):
    """Profiles (count, N, 2) of the gauge ``built`` and their true poses (count, 4, 4)."""
    if gen == "ind":
        from tests.profiler.test_gauge_check import batch as independent

        return independent(built, nominal, count, seed)
    real = RealismModel.realistic()
    if not machining:
        real = replace(real, face_offset_um=0.0, face_tilt_deg=0.0)
    if gen == "simcal":
        real = replace(real, scale_x_ppm=15.0, scale_z_ppm=-15.0)
    scene = build_as_built(built, real, seed)
    rng = np.random.default_rng(seed + 10000)
    Ts = sample_poses(built, count, rng)
    return render_profiles(built, Ts, noise, rng, realism=scene), Ts


def _z(res, Ts, only_ok: bool):
    z = [np.abs(pose_errors(e.T_G_F, T)) / np.sqrt(np.diag(e.cov)) for e, T in zip(res.estimates, Ts)
         if e is not None and (e.status == "ok" or not only_ok)]
    return np.array(z).reshape(-1, 6)


def _coverage(z) -> str:
    if not len(z):
        return ""
    return (" p95 |err|/std " + " ".join(f"{np.percentile(z[:, i], 95):.1f}" for i in range(6))
            + "; within 2σ % " + " ".join(f"{100 * np.mean(z[:, i] <= 2):.0f}" for i in range(6)))


def face_rates(nb: int, K: int, tols, noise: NoiseModel, gen: str = "sim", faces=range(6)) -> list:
    """One line per (tolerance, face): batches that pass with the face 20 µm off, and the 'ok' poses' errors."""
    d5 = bundled_gauge("demo-5")
    lines = []
    for tol in tols:
        for face in faces:
            passed, z, chis = 0, [], []
            for b in range(nb):
                prof, Ts = batch(face_off(d5, face, 20.0), d5, K, 10000 + b, gen, noise)
                res = estimate_profiles(prof, replace(d5, tolerance_um=tol), noise=noise)
                passed += res.gauge_check.passed is not False
                chis.append(res.gauge_check.chi2)
                z.append(_z(res, Ts, True))
            z = np.concatenate(z)
            lines.append(f"[{gen} scale_sigma {noise.scale_sigma_ppm:g}] tol {tol:g} um, face {face} +20 um: batches "
                         f"ok {passed}/{nb}, ok poses {len(z)}, chi2 median {np.median(chis):.1f}{_coverage(z)}")
            print(lines[-1], flush=True)
    return lines


def good_rates(nb: int, K: int, names, noise: NoiseModel, gen: str = "sim") -> list:
    """One line per gauge: good batches (the true file) failed, poses suspect, coverage of the std."""
    lines = []
    for name in names:
        g = bundled_gauge(name)
        failed, unchecked, chis, z, suspect, n = 0, 0, [], [], 0, 0
        for b in range(nb):
            if gen == "ind":
                prof, Ts = batch(g, g, K, 60000 + b, gen, noise)
                filed = g
            else:
                real = RealismModel.realistic()
                if gen == "simcal":
                    real = replace(real, scale_x_ppm=15.0, scale_z_ppm=-15.0)
                scene = build_as_built(g, real, 30000 + b)
                rng = np.random.default_rng(40000 + b)
                Ts = sample_poses(g, K, rng)
                prof, filed = render_profiles(g, Ts, noise, rng, realism=scene), scene.gauge
            res = estimate_profiles(prof, filed, noise=noise)
            c = res.gauge_check
            failed += c.passed is False
            unchecked += not c.checked
            if c.checked:
                chis.append(c.chi2)
            suspect += sum(e is not None and e.status != "ok" for e in res.estimates)
            n += sum(e is not None for e in res.estimates)
            z.append(_z(res, Ts, False))
        z = np.concatenate(z)
        lines.append(f"[{gen} scale_sigma {noise.scale_sigma_ppm:g}] {name}: good batches {nb}x{K}: gauge test failed "
                     f"{failed}/{nb}, not checked {unchecked}, chi2 mean {np.mean(chis) if chis else np.nan:.1f}; "
                     f"poses suspect {suspect}/{n};{_coverage(z)}")
        print(lines[-1], flush=True)
    return lines


def tilt_rates(nb: int, K: int, tols, noise: NoiseModel) -> list:
    """The nominal demo-5 file, declared ``tolerance_um`` in ``tols``, on gauges machined as the realistic
    simulator does (offsets 1σ 10 µm and tilts 1σ 0.01°): batches failed, and the poses' errors."""
    d5 = bundled_gauge("demo-5")
    lines = []
    for tol in tols:
        failed, z = 0, []
        for b in range(nb):
            prof, Ts = batch(d5, d5, K, 70000 + b, "sim", noise, machining=True)
            res = estimate_profiles(prof, replace(d5, tolerance_um=tol), noise=noise)
            failed += res.gauge_check.passed is False
            alone = estimate_profiles(prof, replace(d5, tolerance_um=tol), noise=noise, check_gauge=False)
            z.append(_z(alone, Ts, True))
        z = np.concatenate(z)
        lines.append(f"nominal file, tolerance_um {tol:g}, realistic machining: gauge test failed {failed}/{nb}; "
                     f"the poses 'ok' without the batch test:{_coverage(z)}")
        print(lines[-1], flush=True)
    return lines


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m posekit.profiler.studies.gauge_check_rates")
    p.add_argument("what", choices=["faces", "good", "tilts"])
    p.add_argument("nb", type=int)
    p.add_argument("K", type=int)
    p.add_argument("items", help="tolerances (faces, tilts) or gauge names (good), comma-separated")
    p.add_argument("--scale-sigma-ppm", type=float, default=NoiseModel().scale_sigma_ppm)
    p.add_argument("--gen", choices=["sim", "simcal", "ind"], default="sim")
    a = p.parse_args(argv)
    noise = NoiseModel(scale_sigma_ppm=a.scale_sigma_ppm)
    items = a.items.split(",")
    if a.what == "faces":
        face_rates(a.nb, a.K, [float(t) for t in items], noise, a.gen)
    elif a.what == "good":
        good_rates(a.nb, a.K, items, noise, a.gen)
    else:
        tilt_rates(a.nb, a.K, [float(t) for t in items], noise)


if __name__ == "__main__":
    main()
