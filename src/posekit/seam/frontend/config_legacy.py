"""Configurations in the layout before issue 26, mapped onto ``cell`` / ``simulation`` / ``filter`` / ``profile``.

The old layout had the sections ``robot``, ``process``, ``sensors`` and a ``filter`` of 65 keys. Each old key
either moves (``robot.model`` -> ``cell.robot.model``, ``process.force_n`` -> ``simulation.force_n``,
``sensors.noise_mm`` -> ``simulation.laser_noise_mm``, ``filter.d0_mm`` -> the profile's ``plateau.d0_mm`` ...),
or no longer exists: a removed key holding its old default is dropped (what replaced it is fitted or fixed), one
holding another value is a one-line error that names what replaced it. :func:`map_old_layout` returns the mapped
mapping and the one-line note (empty for a configuration already in the current layout).
"""

from typing import Any

from posekit.errors import ConfigError

__all__ = ["REMOVED_FILTER_KEYS", "map_old_layout"]

_ROBOT_CELL = ("model", "urdf", "base_link", "tip_link", "ik_seed_deg", "tool_length_mm", "tool")
_ROBOT_SIM = ("joint_noise_deg", "kinematic_error_mm", "kinematic_error_deg")
_SENSORS_CELL = ("count", "distances_mm", "mounts", "angle")
_SENSORS_SIM = {"noise_mm": "laser_noise_mm", "range_mm": "laser_range_mm", "dropout": "laser_dropout",
                "angle_noise_deg": "angle_noise_deg"}
_FILTER_SAME = ("particles", "resampler", "ess_threshold", "regularize_h", "anneal_ess", "anneal_stages",
                "integrity_window", "integrity_alpha_degraded", "integrity_alpha_lost", "integrity_ess_min",
                "integrity_recovery", "trend_lambda", "trend_eps_mm",
                "reacquire_walk_scale", "integrity_window_long")  # (the last two: keys of the current layout)
_FILTER_MOVED = {"reacquire_transition_scale": ("filter", "reacquire_walk_scale"),
                 "compliance_rad_per_nm": ("cell", "compliance_rad_per_nm"),
                 "init_offset_mm": ("simulation", "start_offset_mm"),
                 "init_offset_deg": ("simulation", "start_offset_deg")}
#: Old filter keys now in the profile: (old default, profile section, profile key); "sensors" applies to each.
_FILTER_TO_PROFILE = {
    "d0_mm": (3.0, "plateau", "d0_mm"), "kd_mm_per_n": (1e-4, "plateau", "kd_mm_per_n"),
    "d0_deg": (0.35, "plateau", "d0_deg"), "kd_deg_per_n": (1.1e-4, "plateau", "kd_deg_per_n"),
    "plateau_max_force_n": (12000.0, "plateau", "max_force_n"),
    "robot_floor_t_mm": (0.3, "plateau", "tail_mm"), "robot_floor_r_deg": (0.05, "plateau", "tail_deg"),
    "joint_sigma_deg": (0.005, "joints", "sigma_deg"), "laser_sigma_mm": (0.05, "sensors", "sigma_mm"),
    "angle_sigma_deg": (0.2, "sensors", "angle_sigma_deg"),
}
_WALK = "the walk per tool axis is fitted from data: profile walk.* (posekit seam tune)"
_BOUND = "the spread bound runs the profile's walk and noise (no key)"
#: Old filter keys that no longer exist: their last default and what replaced them.
REMOVED_FILTER_KEYS = {
    "sigma_t_mm": (0.01, _WALK), "sigma_r_deg": (0.005, _WALK), "transition_force": ("rate", _WALK),
    "k_force_t": (4e-6, _WALK), "k_force_r": (4e-7, _WALK), "k_rate_t_mm_per_n": (2e-4, _WALK),
    "k_rate_r_deg_per_n": (4e-4, _WALK), "force_rate_smoothing": (5.0, _WALK), "k_travel_t_mm_per_mm": (0.02, _WALK),
    "k_travel_r_deg_per_mm": (0.01, _WALK), "k_load_travel_t": (2.8e-6, _WALK), "k_load_travel_r": (1.2e-6, _WALK),
    "axis_scale_t": ((0.1, 0.3, 1.0), _WALK), "axis_scale_r": ((1.0, 0.8, 0.07), _WALK),
    "load_axis_scale_t": ((1.0, 1.0, 1.0), _WALK), "load_axis_scale_r": ((1.0, 1.0, 0.7), _WALK),
    "walk_adapt_rate": (0.2, _WALK), "walk_adapt_window": (20.0, _WALK), "walk_adapt_max": (10.0, _WALK),
    "walk_adapt_nis": (1.0, _WALK), "reacquire_isotropic_steps": (200, _WALK),
    "bending_plateau": (True, "the rotation plateau is always the bending one (profile plateau.*)"),
    "search_window_mm": (10.0, "the seam is searched as far as the robot plateau reaches (profile plateau.*)"),
    "init_sigma_t_mm": (1.0, "the first cloud is drawn from the robot density (profile plateau.*)"),
    "init_sigma_r_deg": (0.4, "the first cloud is drawn from the robot density (profile plateau.*)"),
    "init_from_robot": (True, "the first cloud is drawn from the robot density (profile plateau.*)"),
    "anneal_jitter": (0.5, "the tempering moves use filter.regularize_h"),
    "spread_bound": (1.0, _BOUND), "spread_bound_k_travel": (0.0, _BOUND), "bound_inflation": (0.0, _BOUND),
    "bound_inflation_reacquire": (1.0, _BOUND), "bound_reacquire_steps": (500, _BOUND),
    "spread_shrink_reacquire": (0.97, _BOUND), "bound_drift_share": (0.5, _BOUND),
    "bound_particle_noise": (1.0, _BOUND), "cloud_floor": (0.2, _BOUND),
    "laser_inflation": (0.5, "the laser likelihood is widened by filter.regularize_h² times the cloud's spread"),
    "laser_inflation_cap": (3.0, "the laser likelihood is widened by filter.regularize_h² times the cloud's spread"),
}
_NEW_SECTIONS = ("cell", "simulation", "profile")


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    try:
        return abs(float(a) - float(b)) <= 1e-12 * max(1.0, abs(float(b)))
    except (TypeError, ValueError):
        return a == b


def _is_old(data: dict) -> bool:
    if any(k in data for k in ("robot", "process", "sensors")):
        return True
    f = data.get("filter")
    return isinstance(f, dict) and any(k in f for k in (*REMOVED_FILTER_KEYS, *_FILTER_TO_PROFILE, *_FILTER_MOVED))


def map_old_layout(data: dict, source: str) -> tuple[dict, str]:
    """``(mapped, note)``: ``data`` in the current layout and a one-line note of what was mapped ("" when the
    layout is current). Raises ConfigError (one line) for a removed key holding a value other than its old
    default, or for a mapping that mixes both layouts."""
    if not _is_old(data):
        return data, ""
    mixed = [k for k in _NEW_SECTIONS if k in data and k != "profile"]
    if mixed:
        raise ConfigError(f"{source}: sections of both layouts ('{mixed[0]}' and robot/process/sensors); expected "
                          "the current one: seed, trajectory, cell, simulation, filter, profile")
    out: dict[str, Any] = {k: v for k, v in data.items() if k in ("seed", "trajectory", "profile")}
    cell: dict[str, Any] = {}
    sim: dict[str, Any] = {}
    filt: dict[str, Any] = {}
    prof: dict[str, Any] = {}
    moved: list[str] = []
    dropped = 0

    def section(name):
        v = data.get(name)
        if v is None:
            return {}
        if isinstance(v, str) and name == "robot":
            return {"model": v}
        if not isinstance(v, dict):
            raise ConfigError(f"{source}: {name}: expected a mapping, got {type(v).__name__}")
        return v

    robot = section("robot")
    for k, v in robot.items():
        if k in _ROBOT_CELL:
            cell.setdefault("robot", {})[k] = v
            moved.append(f"robot.{k} -> cell.robot.{k}")
        elif k in _ROBOT_SIM:
            sim[k] = v
            moved.append(f"robot.{k} -> simulation.{k}")
        else:
            raise ConfigError(f"{source}: unknown key 'robot.{k}'")
    for k, v in section("process").items():
        sim[k] = v
        moved.append(f"process.{k} -> simulation.{k}")
    for k, v in section("sensors").items():
        if k in _SENSORS_CELL:
            cell.setdefault("sensors", {})[k] = v
            moved.append(f"sensors.{k} -> cell.sensors.{k}")
        elif k in _SENSORS_SIM:
            sim[_SENSORS_SIM[k]] = v
            moved.append(f"sensors.{k} -> simulation.{_SENSORS_SIM[k]}")
        else:
            raise ConfigError(f"{source}: unknown key 'sensors.{k}'")
    for k, v in section("filter").items():
        if k in _FILTER_SAME:
            filt[k] = v
        elif k in _FILTER_MOVED:
            sec, key = _FILTER_MOVED[k]
            {"filter": filt, "cell": cell, "simulation": sim}[sec][key] = v
            moved.append(f"filter.{k} -> {sec}.{key}")
        elif k in _FILTER_TO_PROFILE:
            old, sec, key = _FILTER_TO_PROFILE[k]
            if _same(v, old):
                dropped += 1
                continue
            if sec == "sensors":
                prof.setdefault("sensors", [{}])[0][key] = v
            else:
                prof.setdefault(sec, {})[key] = v
            moved.append(f"filter.{k} -> profile {sec}.{key}")
        elif k in REMOVED_FILTER_KEYS:
            old, why = REMOVED_FILTER_KEYS[k]
            if not _same(v, old):
                raise ConfigError(f"{source}: filter.{k}: removed (issue 26); {why}")
            dropped += 1
        else:
            raise ConfigError(f"{source}: unknown key 'filter.{k}'")
    if cell:
        out["cell"] = cell
    if sim:
        out["simulation"] = sim
    if filt:
        out["filter"] = filt
    if prof:
        if isinstance(out.get("profile"), dict):
            raise ConfigError(f"{source}: profile values both in 'profile' and in the old 'filter'; expected one")
        if isinstance(out.get("profile"), str) and out["profile"] != "default":
            raise ConfigError(f"{source}: filter.{next(iter(prof))}-style values with profile: {out['profile']}; "
                              "expected them in the profile file")
        out["profile"] = prof
    shown = ", ".join(moved[:3]) + (f" (+{len(moved) - 3} more)" if len(moved) > 3 else "")
    note = (f"{source}: the layout before issue 26, mapped: {shown or 'nothing moved'}; {dropped} old default(s) "
            "dropped (the profile replaces them); --dump-config prints the new layout")
    return out, note
