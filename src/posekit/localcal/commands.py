"""``posekit localcal match`` and ``handeye`` as library calls on files: read both trajectories,
register them, write the result (and for ``match`` the residuals and figures).

>>> from posekit.localcal import match_files
>>> run = match_files("camera.tum", "robot.tum", "match.json", max_dt_s=0.01)   # doctest: +SKIP
>>> run.result.status, run.result.verdict.std                                   # doctest: +SKIP

The trajectories are read by :func:`~posekit.localcal.registration.formats.read_trajectory`;
``camera_read`` / ``kinematic_read`` are its keyword arguments for each input (``fmt``, ``topic``,
``rate_hz``, ``tf_parent``, ``tf_child``).
"""

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

from posekit.io import check_out_folder, staged_folder, write_text_atomic
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.formats import read_trajectory
from posekit.localcal.registration.handeye import HandEyeResult, calibrate_handeye
from posekit.localcal.registration.match import Registration, match_trajectories

__all__ = ["FileRun", "handeye_files", "match_files", "read_pair"]


@dataclass(frozen=True)
class FileRun:
    """What a file command read, computed and wrote.

    Attributes
    ----------
    result : Registration or HandEyeResult
        The estimate with its verdict (``result.verdict``: :class:`posekit.verdict.Verdict`).
    camera, kinematic : Trajectory
        The inputs as read (s, mm).
    written : dict of str to Path
        ``"json"`` and, when asked for, ``"residuals"`` and ``"plot"``.
    """

    result: Registration | HandEyeResult
    camera: Trajectory
    kinematic: Trajectory
    written: dict = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        """0 when the result is ok, else 1 (:func:`posekit.verdict.batch_exit_code`)."""
        from posekit.verdict import batch_exit_code

        return batch_exit_code([self.result.status])


def read_pair(camera, kinematic, camera_read: dict | None = None, kinematic_read: dict | None = None):
    """Read the camera and the kinematic trajectory (in that order).

    Returns
    -------
    camera, kinematic : Trajectory
    notes : list of str
        What the readers decided for the user (a format the rows chose against the suffix).
    """
    notes = []
    cam = read_trajectory(camera, **(camera_read or {}), notes=notes)
    kin = read_trajectory(kinematic, **(kinematic_read or {}), notes=notes)
    return cam, kin, notes


def _write_json(out, result) -> Path:
    return write_text_atomic(out, json.dumps(result.to_json(), indent=2) + "\n")


def match_files(camera, kinematic, out, *, camera_read: dict | None = None, kinematic_read: dict | None = None,
                residuals=None, plot=None, overwrite: bool = False, **options) -> FileRun:
    """``posekit localcal match``: the transform that maps the camera trajectory into the robot base.

    Parameters
    ----------
    camera, kinematic : path
        Camera poses in the VO/SLAM world frame; TCP poses in the robot base frame.
    out : path
        The result JSON (DESIGN.md's fields), written atomically, also when ``suspect``.
    camera_read, kinematic_read : dict, optional
        Keyword arguments of ``read_trajectory`` for each input.
    residuals : path, optional
        Also write every pose pair's residual (CSV, :mod:`posekit.localcal.match_report`).
    plot : path, optional
        Also write ``trajectories.png`` and ``error.png`` to this folder (checked before any work).
    overwrite : bool
        Replace an existing ``plot`` folder.
    **options
        :func:`~posekit.localcal.registration.match.match_trajectories`'s options
        (``use_timestamps``, ``max_dt_s``, ``time_offset_s``, ``max_offset_s``, ``with_scale``,
        ``outlier_fraction``, ``matcher``).
    """
    if plot is not None:                      # before the work: a plot folder we may not write is one line
        check_out_folder(plot, overwrite=overwrite, flag="--plot")
    src, dst, notes = read_pair(camera, kinematic, camera_read, kinematic_read)
    names = (str(camera), str(kinematic))
    reg = match_trajectories(src, dst, names=names, **options)
    reg = replace(reg, notes=tuple(notes) + tuple(reg.notes))
    written = {}
    if residuals is not None:
        from posekit.localcal.match_report import write_residuals

        written["residuals"] = write_residuals(reg, residuals)
    if plot is not None:
        from posekit.localcal.match_report import plot_match

        with staged_folder(plot, overwrite=overwrite, flag="--plot") as tmp:
            plot_match(reg, src, dst, tmp, names=names)
        written["plot"] = Path(plot)
    written["json"] = _write_json(out, reg)
    return FileRun(reg, src, dst, written)


def handeye_files(camera, kinematic, out, *, camera_read: dict | None = None, kinematic_read: dict | None = None,
                  **options) -> FileRun:
    """``posekit localcal handeye``: the camera mount and the camera's world frame in the robot base.

    Parameters
    ----------
    camera, kinematic : path
        Camera poses ``T_world_camera`` (VO/SLAM); tool poses ``T_base_tool``.
    out : path
        The result JSON (DESIGN.md's fields), written atomically, also when ``suspect``.
    camera_read, kinematic_read : dict, optional
        Keyword arguments of ``read_trajectory`` for each input.
    **options
        :func:`~posekit.localcal.registration.handeye.calibrate_handeye`'s options (``max_dt_s``,
        ``time_offset_s``, ``max_offset_s``, ``noise_mm``, ``noise_deg``, ``max_std_t_mm``,
        ``max_std_rot_deg``).
    """
    cam, kin, notes = read_pair(camera, kinematic, camera_read, kinematic_read)
    res = calibrate_handeye(cam, kin, names=(str(camera), str(kinematic)), **options)
    res = replace(res, notes=list(notes) + list(res.notes))
    return FileRun(res, cam, kin, {"json": _write_json(out, res)})
