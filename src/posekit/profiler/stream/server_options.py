"""The options of :class:`~posekit.profiler.stream.server.PoseServer`, checked before anything starts.

Each argument's meaning and unit are documented on
:class:`~posekit.profiler.stream.server.PoseServer`; a wrong one is a one-line
:class:`~posekit.errors.ConfigError` that names it.
"""

from ...errors import ConfigError, PosekitError
from ..estimate.consistency import check_noise
from ..estimate.solve import METHODS
from ..gauge.model import MOUNTINGS, Gauge
from .protocol import encode_hello

__all__ = ["check_options"]

_SECONDS_RANGE = (0.05, 86_400.0)   # accepted timeouts, s


def check_options(gauge, *, method, mounting, significance, noise, queue_size, history, nan_storm_fraction,
                  controller, pose_filter, record_sink, idle_timeout_s, read_timeout_s, max_dt_s, hello_timeout_s,
                  max_connections, max_pending, rate_burst, max_rate_hz, max_accept_hz, allow_remote,
                  token) -> None:
    """Check the arguments of :class:`~posekit.profiler.stream.server.PoseServer` (same names).

    Raises
    ------
    ConfigError
        ``PoseServer: ...`` naming the first argument out of its type or range, or a combination
        that cannot work (``method='cf'`` with a pose filter or a gauge of fewer than 5 corners,
        ``allow_remote`` without a token, ``mounting='auto'`` on an ambiguous gauge).
    """
    if not isinstance(gauge, Gauge):
        raise ConfigError(f"PoseServer: gauge must be a posekit Gauge, got {type(gauge).__name__}")
    if method not in METHODS:
        raise ConfigError(f"PoseServer: unknown method '{method}'; expected one of {', '.join(METHODS)}")
    if mounting not in MOUNTINGS:
        raise ConfigError(f"PoseServer: unknown mounting '{mounting}'; expected one of {', '.join(MOUNTINGS)}")
    if mounting == "auto" and getattr(gauge, "ambiguity", None):
        raise ConfigError(f"PoseServer: gauge '{gauge.name}' is ambiguous ({gauge.ambiguity}); give the "
                          "mounting ('normal' or 'reversed')")
    if not (isinstance(significance, float | int) and 0 < significance < 1):
        raise ConfigError(f"PoseServer: significance must be a number in (0, 1), got {significance!r}")
    try:
        check_noise(noise)
    except PosekitError as exc:
        raise ConfigError(f"PoseServer: {exc}") from None
    if method == "cf" and gauge.n_corners < 5:
        raise ConfigError(f"PoseServer: method 'cf' needs a gauge with >= 5 corners; "
                          f"'{gauge.name}' has {gauge.n_corners} (use 'mle')")
    if not (isinstance(queue_size, int) and queue_size >= 1):
        raise ConfigError(f"PoseServer: queue_size must be an integer >= 1, got {queue_size!r}")
    if not (isinstance(history, int) and history >= 1):
        raise ConfigError(f"PoseServer: history must be an integer >= 1, got {history!r}")
    if not 0.0 <= nan_storm_fraction < 1.0:
        raise ConfigError(f"PoseServer: nan_storm_fraction must be in [0, 1), got {nan_storm_fraction}")
    if controller is not None and not callable(controller):
        raise ConfigError("PoseServer: controller must be callable(seq, t_s, T_G_F, cov) -> dict | None")
    if pose_filter is not None and not callable(getattr(pose_filter, "update", None)):
        raise ConfigError("PoseServer: pose_filter must have update(t_s, T_G_F, cov) -> FilteredPose")
    if pose_filter is not None and method == "cf":
        raise ConfigError("PoseServer: a pose filter needs method 'mle' (the closed form 'cf' gives no "
                          "covariance to filter with)")
    if record_sink is not None and not callable(getattr(record_sink, "put", None)):
        raise ConfigError("PoseServer: record_sink must have put(record)")
    lo, hi = _SECONDS_RANGE
    for name, value in (("idle_timeout_s", idle_timeout_s), ("read_timeout_s", read_timeout_s),
                        ("max_dt_s", max_dt_s), ("hello_timeout_s", hello_timeout_s)):
        if not (isinstance(value, int | float) and not isinstance(value, bool) and lo <= value <= hi):
            raise ConfigError(f"PoseServer: {name} must be a number of seconds in [{lo:g}, {hi:g}], got {value!r}")
    for name, value in (("max_connections", max_connections), ("max_pending", max_pending),
                        ("rate_burst", rate_burst)):
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
            raise ConfigError(f"PoseServer: {name} must be an integer >= 1, got {value!r}")
    for name, value in (("max_rate_hz", max_rate_hz), ("max_accept_hz", max_accept_hz)):
        if not (isinstance(value, int | float) and not isinstance(value, bool) and 1 <= value <= 1e6):
            raise ConfigError(f"PoseServer: {name} must be a number in [1, 1e6] Hz, got {value!r}")
    if allow_remote and token is None:
        raise ConfigError("PoseServer: allow_remote=True (--allow-remote) needs a token (--token-file FILE) "
                          "that every sensor must present; refusing to accept remote sensors without one")
    if token is not None:
        encode_hello(token)              # validates it: str or bytes, 1..MAX_TOKEN_BYTES
