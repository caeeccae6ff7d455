"""Step- and impulse-response metrics of one axis of the flange (Table IV, Fig. 5 of the paper).

All functions take a uniformly or non-uniformly sampled record ``t_s`` (s), ``y_mm`` (mm,
one axis of the flange position in the gauge frame G) and work on the part after the
step (or impulse) instant. Conventions, chosen to match the paper's Table IV:

- **Maximum overshoot** Mp (%): the largest excursion beyond the final value in the
  direction of the step, in % of the step ``|y_final - y0|``; 0 when the response never
  passes the final value.
- **Damping ratio** ζ: by default from Mp with the second-order relation
  ``ζ = -ln(Mp) / sqrt(π² + ln²(Mp))`` (``Mp`` as a fraction) — every ζ of Table IV
  follows from its Mp this way (5.39 % → 0.68, 65.88 % → 0.13, 20.51 % → 0.45, ...);
  no overshoot (ζ ≥ 1) gives 1.0. ``method="logdec"`` uses the logarithmic decrement
  of the first two successive extrema of the deviation instead (see :func:`damping_ratio`).
- **Peak frequency magnitude** Mf (µm): see :func:`peak_frequency_magnitude`.
"""

import numpy as np

from ...errors import ConfigError

__all__ = ["overshoot_pct", "zeta_from_overshoot", "damping_ratio", "amplitude_spectrum",
           "peak_frequency_magnitude", "arrival_time", "settling_time", "step_metrics", "impulse_resonance"]

MODE_BAND_HZ = (8.0, 12.0)
"""Default search band of the Mf peak: the ~10 Hz structural mode ± 2 Hz."""


def _record(t_s, y_mm, name: str):
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(y_mm, dtype=float)
    if t.ndim != 1 or y.shape != t.shape or t.size < 4:
        raise ConfigError(f"{name}: t_s and y_mm must be 1-D arrays of the same length >= 4, "
                          f"got shapes {t.shape} and {y.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise ConfigError(f"{name}: t_s and y_mm must be finite (drop missing samples first)")
    if np.any(np.diff(t) <= 0):
        raise ConfigError(f"{name}: t_s must be strictly increasing")
    return t, y


def overshoot_pct(t_s, y_mm, y0_mm: float, y_final_mm: float, *, t_step_s: float | None = None) -> float:
    """Maximum overshoot of a step response, % of the step.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s.
    y_mm : ndarray, shape (n,)
        Response (one axis of the flange position in G), mm.
    y0_mm, y_final_mm : float
        Value before the step and final value, mm (``y_final_mm != y0_mm``).
    t_step_s : float, optional
        Only samples at or after this time count (default: all).

    Returns
    -------
    float
        ``100 · max(sign · (y - y_final)) / |y_final - y0|``, clipped at 0, where ``sign`` is
        the direction of the step.
    """
    t, y = _record(t_s, y_mm, "overshoot_pct")
    step = float(y_final_mm) - float(y0_mm)
    if step == 0 or not np.isfinite(step):
        raise ConfigError(f"overshoot_pct: y_final_mm must differ from y0_mm, got {y0_mm} and {y_final_mm}")
    after = y if t_step_s is None else y[t >= t_step_s]
    if after.size == 0:
        raise ConfigError(f"overshoot_pct: no sample at or after t_step_s = {t_step_s} s")
    return float(max(0.0, 100.0 * np.max(np.sign(step) * (after - y_final_mm)) / abs(step)))


def zeta_from_overshoot(mp_pct: float) -> float:
    """Damping ratio of the second-order system whose step overshoots by ``mp_pct`` (%).

    ``ζ = -ln(Mp) / sqrt(π² + ln²(Mp))``; Mp ≤ 0 (no overshoot, ζ ≥ 1) gives 1.0, and
    Mp ≥ 100 % gives ζ ≤ 0 (a growing oscillation).

    Examples
    --------
    >>> round(zeta_from_overshoot(65.88), 2), zeta_from_overshoot(0.0)
    (0.13, 1.0)
    """
    mp = float(mp_pct) / 100.0
    if not np.isfinite(mp):
        raise ConfigError(f"zeta_from_overshoot: overshoot must be a finite percentage, got {mp_pct}")
    if mp <= 0.0:
        return 1.0
    ln = np.log(mp)
    return float(-ln / np.sqrt(np.pi ** 2 + ln ** 2))


def damping_ratio(t_s, y_mm, y0_mm: float, y_final_mm: float, *, t_step_s: float | None = None,
                  method: str = "overshoot", noise_mm: float = 0.0) -> float:
    """Damping ratio ζ of a step response.

    Parameters
    ----------
    t_s, y_mm : ndarray, shape (n,)
        Record (s, mm); ``y0_mm``, ``y_final_mm``, ``t_step_s`` as in :func:`overshoot_pct`.
    method : {"overshoot", "logdec"}
        ``"overshoot"`` (Table IV's convention): :func:`zeta_from_overshoot` of the Mp.
        ``"logdec"``: logarithmic decrement over the half period between the first overshoot
        peak ``e1`` and the following undershoot ``e2`` of ``e = y - y_final``,
        ``δ = ln(|e1| / |e2|)``, ``ζ = δ / sqrt(π² + δ²)``. Extrema are sampled values, so at
        83.3 Hz on a 10 Hz mode the decrement is biased; it falls back to the overshoot
        value when ``|e2| <= 3 noise_mm`` (no measurable undershoot).
    noise_mm : float
        Measurement noise standard deviation, mm (only for ``"logdec"``).

    Returns
    -------
    float
        ζ, 1.0 without overshoot (≤ 0 for a growing oscillation, Mp ≥ 100 %).
    """
    mp = overshoot_pct(t_s, y_mm, y0_mm, y_final_mm, t_step_s=t_step_s)
    zeta_mp = zeta_from_overshoot(mp)
    if method == "overshoot":
        return zeta_mp
    if method != "logdec":
        raise ConfigError(f"damping_ratio: method must be 'overshoot' or 'logdec', got {method!r}")
    if mp <= 0:
        return 1.0
    t, y = _record(t_s, y_mm, "damping_ratio")
    s = np.sign(y_final_mm - y0_mm)
    e = s * (y - y_final_mm)
    if t_step_s is not None:
        e = e[t >= t_step_s]
    i1 = int(np.argmax(e))                    # the first (largest) overshoot peak
    rest = e[i1:]
    down = np.flatnonzero(rest < 0)
    if down.size == 0:
        return zeta_mp
    after = rest[down[0]:]                    # the undershoot lobe that follows it
    up = np.flatnonzero(after >= 0)
    e2 = -float(np.min(after[: up[0]] if up.size else after))
    if e2 <= 3.0 * noise_mm or e2 <= 0:
        return zeta_mp
    delta = np.log(e[i1] / e2)
    return float(min(1.0, delta / np.sqrt(np.pi ** 2 + delta ** 2))) if delta > 0 else zeta_mp


def amplitude_spectrum(t_s, x_mm, *, df_hz: float = 0.02, n_norm: int | None = None):
    """Single-sided amplitude spectrum of a uniformly sampled record, mm.

    ``A(f) = (2/N) |Σ_n x_n exp(-i 2π f t_n)|`` (rectangular window, zero-padded to a
    frequency spacing of at most ``df_hz``), so a sinusoid of amplitude ``a`` spanning the
    record reads ``A ≈ a`` at its frequency (exactly with a whole number of periods).
    ``N`` is the number of samples, or ``n_norm`` (a nominal window of which the record
    is the non-zero part).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Uniform sample times, s.
    x_mm : ndarray, shape (n,)
        Signal, mm (not detrended here).
    df_hz : float
        Largest frequency spacing of the returned grid, Hz.
    n_norm : int, optional
        Normalising sample count ``N`` (default ``len(x_mm)``).

    Returns
    -------
    f_hz : ndarray, shape (m,)
        Frequencies from 0 to Nyquist, Hz.
    a_mm : ndarray, shape (m,)
        Amplitude, mm.
    """
    t, x = _record(t_s, x_mm, "amplitude_spectrum")
    dt = np.diff(t)
    if np.ptp(dt) > 1e-6 * dt.mean():
        raise ConfigError("amplitude_spectrum: t_s must be uniformly sampled")
    n = x.size if n_norm is None else int(n_norm)
    n_fft = max(x.size, int(2 ** np.ceil(np.log2(1.0 / (df_hz * dt.mean())))))
    a = 2.0 * np.abs(np.fft.rfft(x, n_fft)) / n
    return np.fft.rfftfreq(n_fft, dt.mean()), a


def peak_frequency_magnitude(t_s, y_mm, *, y_final_mm: float | None = None, t_start_s: float | None = None,
                             window_s: float | None = 1.0, band_hz=MODE_BAND_HZ):
    """Peak of the amplitude spectrum of a deviation near the mode: (f_peak, Mf).

    Mf is computed as follows (a spectrum like Fig. 5(b), read at its ~10 Hz peak):

    1. keep the samples in ``[t_start_s, t_start_s + window_s)``;
    2. subtract ``y_final_mm`` (the deviation from the final value), or the mean of the
       kept samples when ``y_final_mm`` is None (a detrended record, e.g. an oscillation);
    3. take :func:`amplitude_spectrum` (rectangular window, zero padding) normalised by
       the **nominal** window, ``N = round(window_s / Δt)`` — samples the record lacks
       count as zero deviation — or by the number of kept samples if ``window_s`` is None;
    4. Mf is the largest amplitude inside ``band_hz`` and f_peak its frequency.

    A sinusoid of amplitude ``a`` µm filling the window reads Mf ≈ a µm. A decaying
    transient reads less the longer the window (Mf ∝ 1/window_s), so only values with
    the same window compare. :func:`step_metrics` starts the window when the response
    arrives at its target, not at the step: a window opening on the step would see a
    jump of the whole step at its edge, whose 2·step/(2π f · window_s) leakage (32 µm at
    10 Hz for 1 mm in 1 s) would swamp the oscillation.

    Parameters
    ----------
    t_s, y_mm : ndarray, shape (n,)
        Uniformly sampled record, s and mm.
    y_final_mm : float, optional
        Final value, mm.
    t_start_s : float, optional
        Start of the analysis window, s; default ``t_s[0]``.
    window_s : float or None
        Nominal window length, s; None: to the end of the record.
    band_hz : (float, float)
        Search band, Hz (default the 10 Hz mode ± 2 Hz).

    Returns
    -------
    f_peak_hz : float
        Frequency of the peak, Hz.
    mf_um : float
        Amplitude at the peak, µm.

    Examples
    --------
    >>> t = np.arange(0, 2, 0.004)
    >>> f, mf = peak_frequency_magnitude(t, 0.02 * np.sin(2 * np.pi * 10 * t), window_s=None)
    >>> round(f, 1), round(mf, 1)
    (10.0, 20.0)
    """
    t, y = _record(t_s, y_mm, "peak_frequency_magnitude")
    lo, hi = float(band_hz[0]), float(band_hz[1])
    if not 0 <= lo < hi:
        raise ConfigError(f"peak_frequency_magnitude: band_hz must be (low, high) with 0 <= low < high, got {band_hz}")
    if window_s is not None and not (np.isfinite(window_s) and window_s > 0):
        raise ConfigError(f"peak_frequency_magnitude: window_s must be > 0 or None, got {window_s!r}")
    dt = float(np.mean(np.diff(t)))
    t0 = t[0] if t_start_s is None else float(t_start_s)
    keep = t >= t0 - 1e-9
    if window_s is not None:
        keep &= t < t0 + window_s - 1e-9
    if keep.sum() < 4:
        raise ConfigError(f"peak_frequency_magnitude: fewer than 4 samples in the window from {t0} s")
    t, y = t[keep], y[keep]
    x = y - (np.mean(y) if y_final_mm is None else float(y_final_mm))
    n_norm = None if window_s is None else max(round(window_s / dt), x.size)
    f, a = amplitude_spectrum(t, x, n_norm=n_norm)
    band = (f >= lo) & (f <= hi)
    if not np.any(band):
        raise ConfigError(f"peak_frequency_magnitude: band {band_hz} Hz is above the Nyquist "
                          f"frequency {f[-1]:.1f} Hz")
    i = np.flatnonzero(band)[np.argmax(a[band])]
    return float(f[i]), float(1e3 * a[i])


def arrival_time(t_s, y_mm, y0_mm: float, y_final_mm: float, *, t_step_s: float = 0.0,
                 tol: float = 0.02) -> float:
    """First sample time after the step at which the response has reached its target, s.

    The earlier of the first sample at or past ``y_final`` (in the step's direction) and
    the first sample within ``tol · |step|`` of it; robust to a coarse sampling that
    jumps over the narrow band of a fast, ringing response. nan if neither happens.
    """
    t, y = _record(t_s, y_mm, "arrival_time")
    step = float(y_final_mm) - float(y0_mm)
    e = np.sign(step) * (y - y_final_mm)
    hit = np.flatnonzero((t >= t_step_s) & ((e >= 0) | (np.abs(e) <= tol * abs(step))))
    return float(t[hit[0]]) if hit.size else float("nan")


def settling_time(t_s, y_mm, y0_mm: float, y_final_mm: float, *, t_step_s: float = 0.0,
                  tol: float = 0.02) -> float:
    """Time after the step from which ``|y - y_final|`` stays within ``tol · |step|``, s.

    Returns ``nan`` when the record ends outside the band.
    """
    t, y = _record(t_s, y_mm, "settling_time")
    band = tol * abs(float(y_final_mm) - float(y0_mm))
    after = t >= t_step_s
    outside = np.flatnonzero(after & (np.abs(y - y_final_mm) > band))
    if outside.size == 0:
        return 0.0
    if outside[-1] == t.size - 1:
        return float("nan")
    return float(t[outside[-1] + 1] - t_step_s)


def step_metrics(t_s, y_mm, step_mm: float, *, t_step_s: float = 0.0, y0_mm: float | None = None,
                 y_final_mm: float | None = None, tail_s: float = 0.2, window_s: float | None = 1.0,
                 band_hz=MODE_BAND_HZ, arrival_tol: float = 0.02, zeta_method: str = "overshoot",
                 noise_mm: float = 0.0) -> dict:
    """Table IV metrics of one axis of a step response.

    Parameters
    ----------
    t_s, y_mm : ndarray, shape (n,)
        Uniformly sampled record, s and mm (one axis, gauge frame G).
    step_mm : float
        Commanded step, mm (signed).
    t_step_s : float
        Step instant, s.
    y0_mm : float, optional
        Value before the step; default the mean of the samples before ``t_step_s`` (or
        ``y_mm[0]`` if there are none).
    y_final_mm : float, optional
        Final value; default the mean over the last ``tail_s`` seconds of the record.
    window_s, band_hz
        Mf settings, see :func:`peak_frequency_magnitude`. The Mf window opens when the
        response first comes within ``arrival_tol · |step|`` of its final value
        (:func:`arrival_time`; at the step if it never does), so Mf measures the
        oscillation about the target, the "post-target oscillations" of §IV-C.
    arrival_tol : float
        Relative band of the arrival, default 2 % of the step.
    zeta_method, noise_mm
        See :func:`damping_ratio`.

    Returns
    -------
    dict
        ``Mp_pct`` (%), ``zeta``, ``Mf_um`` (µm), ``f_peak_hz`` (Hz), ``settling_s`` (2 %
        band, s after the step; nan if not settled), ``arrival_s`` (s after the step),
        ``y0_mm``, ``y_final_mm`` (mm).
    """
    t, y = _record(t_s, y_mm, "step_metrics")
    if not np.isfinite(step_mm) or step_mm == 0:
        raise ConfigError(f"step_metrics: step_mm must be finite and non-zero, got {step_mm}")
    before = t < t_step_s
    y0 = float(y0_mm) if y0_mm is not None else float(np.mean(y[before]) if before.any() else y[0])
    y_final = float(y_final_mm) if y_final_mm is not None else float(np.mean(y[t >= t[-1] - tail_s]))
    if np.sign(y_final - y0) != np.sign(step_mm):
        y_final = y0 + float(step_mm)           # the response did not move: measure against the target
    mp = overshoot_pct(t, y, y0, y_final, t_step_s=t_step_s)
    zeta = damping_ratio(t, y, y0, y_final, t_step_s=t_step_s, method=zeta_method, noise_mm=noise_mm)
    t_arr = arrival_time(t, y, y0, y_final, t_step_s=t_step_s, tol=arrival_tol)
    t_mf = t_arr if np.isfinite(t_arr) and np.sum(t >= t_arr) >= 4 else t_step_s
    f_pk, mf = peak_frequency_magnitude(t, y, y_final_mm=y_final, t_start_s=t_mf,
                                        window_s=window_s, band_hz=band_hz)
    return {"Mp_pct": mp, "zeta": zeta, "Mf_um": mf, "f_peak_hz": f_pk,
            "settling_s": settling_time(t, y, y0, y_final, t_step_s=t_step_s),
            "arrival_s": t_arr - t_step_s, "y0_mm": y0, "y_final_mm": y_final}


def impulse_resonance(t_s, y_mm, *, t_free_s: float, y_rest_mm: float | None = None,
                      band_hz=(2.0, 40.0)) -> dict:
    """Resonance of a mode from its impulse response (Fig. 5(c)-(d) of the paper).

    Two estimates from the free response after the impulse ends (``t >= t_free_s``):

    - ``f_peak_hz``: the peak of :func:`amplitude_spectrum` of ``y - y_rest`` inside
      ``band_hz`` (what Fig. 5(d) shows; for a mode with damping ζ it lies at
      ``f_n √(1 - 2ζ²)``, so it is near f_n only when ζ is small);
    - ``f_natural_hz``, ``f_damped_hz``, ``zeta``: a least-squares fit of the homogeneous
      second-order solution ``e^{-σt} (c1 cos ω_d t + c2 sin ω_d t)`` (exact for a linear
      mode once the input is constant again), ``f_n = √(σ² + ω_d²) / 2π``, ``ζ = σ / ω_n``.

    Parameters
    ----------
    t_s, y_mm : ndarray, shape (n,)
        Uniformly sampled record, s and mm (one axis).
    t_free_s : float
        End of the impulse (the command is back at rest from here), s.
    y_rest_mm : float, optional
        Rest position, mm; default the record's last sample.
    band_hz : (float, float)
        Search band of ``f_peak_hz``.

    Returns
    -------
    dict
        ``f_peak_hz``, ``peak_um`` (spectrum amplitude at the peak, µm), ``f_natural_hz``,
        ``f_damped_hz``, ``zeta`` (nan if the fit finds no oscillation).
    """
    t, y = _record(t_s, y_mm, "impulse_resonance")
    free = t >= t_free_s - 1e-9
    if free.sum() < 8:
        raise ConfigError(f"impulse_resonance: fewer than 8 samples after t_free_s = {t_free_s} s")
    tf, e = t[free] - t[free][0], y[free] - (y[-1] if y_rest_mm is None else float(y_rest_mm))
    f_pk, a_pk = peak_frequency_magnitude(tf, e, y_final_mm=0.0, window_s=None, band_hz=band_hz)

    def residual(p):
        sigma, wd = p
        basis = np.exp(-sigma * tf)[:, None] * np.stack([np.cos(wd * tf), np.sin(wd * tf)], 1)
        c, *_ = np.linalg.lstsq(basis, e, rcond=None)
        return basis @ c - e

    from scipy.optimize import least_squares  # imported here: 0.5-1 s, and only this fit needs it

    wd_max = np.pi / np.mean(np.diff(tf))                                # Nyquist
    starts = [(2 * np.pi * f * z, min(2 * np.pi * f * np.sqrt(1 - z * z), 0.9 * wd_max))
              for f in (f_pk, 2.0 * f_pk, 10.0) for z in (0.05, 0.3, 0.6)]     # (σ, ω_d) from (f_n, ζ)
    best = min((least_squares(residual, s0, bounds=([0.0, 1e-3], [np.inf, wd_max])) for s0 in starts),
               key=lambda r: r.cost)
    sigma, wd = best.x
    wn = np.hypot(sigma, wd)
    ok = best.success and wd > 1e-2
    return {"f_peak_hz": f_pk, "peak_um": a_pk,
            "f_natural_hz": float(wn / (2 * np.pi)) if ok else float("nan"),
            "f_damped_hz": float(wd / (2 * np.pi)) if ok else float("nan"),
            "zeta": float(sigma / wn) if ok else float("nan")}
