"""The factors of the tuning study: which configuration keys it perturbs and over which ranges.

A factor is a dotted key of the configuration (:func:`study_base`: the profile's values as bare
numbers): a number (drawn in ``[low, high]``), an item of a tuple key (``simulation.force_n[2]``,
``cell.sensors.distances_mm[1]``) or a whole tuple key (``cell.sensors.distances_mm``,
``simulation.force_n``), whose draw is a scale applied to every item (``[low, high]`` default
``1 ± spread``): the sensors move out together, the force grows. An integer parameter
(``filter.particles``, ``filter.anneal_stages``) takes its draw rounded (:func:`factor_value`).
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError

__all__ = [
    "DEFAULT_FACTORS",
    "Factor",
    "factor_value",
    "get_dotted",
    "is_tuple_factor",
    "make_factors",
    "set_dotted",
    "study_base",
]

#: The filter parameters perturbed by default (dotted keys of :class:`~posekit.seam.frontend.config.SeamConfig`).
DEFAULT_FACTORS = ("profile.walk.x_mm", "profile.walk.y_mm", "profile.walk.z_mm", "profile.walk.rx_deg",
                   "profile.walk.ry_deg", "profile.walk.rz_deg", "profile.plateau.d0_mm",
                   "profile.plateau.kd_mm_per_n", "profile.plateau.d0_deg", "profile.plateau.kd_deg_per_n",
                   "filter.regularize_h", "filter.ess_threshold")


@dataclass(frozen=True)
class Factor:
    """One perturbed parameter: a dotted config key drawn uniformly from ``[low, high]`` (its unit)."""

    name: str
    low: float
    high: float

    def __post_init__(self):
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.low < self.high):
            raise ConfigError(f"study factor '{self.name}': expected a range low < high, "
                              f"got [{self.low:g}, {self.high:g}]")


def _split_index(key: str) -> tuple[str, int | None]:
    """``'simulation.force_n[2]'`` → ``('simulation.force_n', 2)``; ``'a.b'`` → ``('a.b', None)``."""
    if key.endswith("]") and "[" in key:
        name, _, idx = key[:-1].rpartition("[")
        try:
            return name, int(idx)
        except ValueError:
            raise ConfigError(f"study factor '{key}': expected KEY[INDEX] with an integer index") from None
    return key, None


def get_dotted(data: Mapping, key: str):
    """``data['a']['b']`` for ``key='a.b'`` (``'a.b[i]'``: item i of a tuple key); ConfigError naming
    the key when it does not exist."""
    name, idx = _split_index(key)
    node = data
    for part in name.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise ConfigError(f"study factor '{key}': no such configuration key")
        node = node[part]
    if idx is not None:
        if not isinstance(node, (list, tuple)) or not -len(node) <= idx < len(node):
            size = len(node) if isinstance(node, (list, tuple)) else "no"
            raise ConfigError(f"study factor '{key}': '{name}' has {size} items; expected an index within them")
        node = node[idx]
    return node


def set_dotted(data: dict, key: str, value) -> None:
    """Set ``data['a']['b'] = value`` for ``key='a.b'`` in place (the key must exist); ``'a.b[i]'``
    sets item i of a tuple key."""
    get_dotted(data, key)
    name, idx = _split_index(key)
    *path, last = name.split(".")
    node = data
    for part in path:
        node = node[part]
    if idx is None:
        node[last] = value
    else:
        items = list(node[last])
        items[idx] = value
        node[last] = items


def is_tuple_factor(base: Mapping, name: str) -> bool:
    """Whether ``name`` is a whole tuple key (``cell.sensors.distances_mm``, ``simulation.force_n``): its
    factor value is a scale applied to every item."""
    value = get_dotted(base, name)
    return isinstance(value, (list, tuple))


def factor_value(base: Mapping, name: str, x: float):
    """The configuration value of factor ``name`` drawn as ``x``: ``x`` itself (rounded for an
    integer key), or for a whole tuple key the base items scaled by ``x``."""
    value = get_dotted(base, name)
    if isinstance(value, (list, tuple)):
        return [float(v) * float(x) for v in value]
    return int(round(x)) if type(value) is int else float(x)


def make_factors(base: Mapping, names: Sequence[str] | None = None, *, spread: float = 0.5,
                 ranges: Mapping[str, tuple[float, float]] | None = None) -> tuple[Factor, ...]:
    """Factors around a base configuration.

    Parameters
    ----------
    base : mapping
        The base configuration as a dict (:func:`study_base`).
    names : sequence of str, optional
        Dotted keys to perturb (default :data:`DEFAULT_FACTORS`, less those whose base value
        is 0 and that have no explicit range).
    spread : float
        Relative half-range: a factor is drawn from ``[v (1 - spread), v (1 + spread)]`` around
        its base value v; 0 < spread < 1.
    ranges : mapping of str to (low, high), optional
        Explicit ranges that replace the relative one (for parameters whose base is 0).

    Returns
    -------
    tuple of Factor
    """
    if not 0.0 < spread < 1.0:
        raise ConfigError(f"study spread: expected a fraction 0 < spread < 1, got {spread:g}")
    ranges = dict(ranges or {})
    explicit = names is not None
    names = list(names if explicit else DEFAULT_FACTORS)
    for k in ranges:
        if k not in names:
            names.append(k)
    factors = []
    for name in names:
        value = get_dotted(base, name)
        if name in ranges:
            lo, hi = ranges[name]
            factors.append(Factor(name, float(lo), float(hi)))
            continue
        if isinstance(value, (list, tuple)):  # a tuple key: one scale for all of its items
            if not value or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                raise ConfigError(f"study factor '{name}': expected a tuple of numbers, got {value!r}")
            factors.append(Factor(name, 1.0 - spread, 1.0 + spread))
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"study factor '{name}': expected a numeric parameter, got {value!r}")
        if value == 0:
            if explicit:
                raise ConfigError(f"study factor '{name}': its base value is 0, so a relative range is empty; "
                                  f"give an explicit range {name}=LOW:HIGH")
            continue
        a, b = sorted((value * (1 - spread), value * (1 + spread)))
        factors.append(Factor(name, float(a), float(b)))
    if not factors:
        raise ConfigError("study: no factor to perturb")
    return tuple(factors)


def study_base(config) -> dict:
    """The configuration as the mapping a study perturbs: ``SeamConfig.model_dump`` with the profile's values as
    bare numbers (``profile.walk.z_mm``, ``profile.plateau.d0_mm`` are factors like any other key)."""
    base = config.model_dump(mode="json")
    base["profile"] = config.profile.plain()
    return base
