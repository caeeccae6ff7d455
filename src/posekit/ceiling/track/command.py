"""The ``posekit ceiling track`` verb as one library call (:func:`track`): the rules that tie its
options together (dots and robots, one calibration per camera, the outputs), the tracking and the
outputs written row by row. The command only parses the flags and prints the summary."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ...errors import ConfigError
from ...verdict import track_exit_code
from .outputs import ReaderGone, TrackOutputs
from .pipeline import parse_dots, track_video
from .sources import is_live_source
from .types import TrackerConfig

__all__ = ["TrackPlan", "TrackRun", "plan_track", "track_input"]


@dataclass(frozen=True)
class TrackPlan:
    """The checked options of a track run: every input, its calibration, the dots, the robots."""

    inputs: tuple
    calibrations: tuple
    dots: tuple
    robots: int
    config: TrackerConfig
    camera: object          # None, one lens file for all inputs, or a list (one per input)
    scene: object           # None, one scene file for all inputs, or a list (one per input)
    detector_options: dict | None
    live: bool


@dataclass
class TrackRun:
    """What :func:`track` did: the tracker's result (None if interrupted or the reader left), the row
    counts per status, the frames written, and how the run ended."""

    plan: TrackPlan
    result: object | None
    counts: dict
    rows: int
    interrupted: bool = False
    gone: str | None = None
    to_stdout: bool = False

    @property
    def frames(self) -> int:
        """Frames tracked (rows / robots)."""
        return self.rows // self.plan.robots

    @property
    def exit_code(self) -> int:
        """0; 1 (:func:`~posekit.verdict.track_exit_code`) when the reader of the stream left before
        the input was read whole; 130 when a file input was interrupted."""
        if self.gone:
            return track_exit_code(False)
        if self.interrupted and not self.plan.live:
            return 130
        return 0


def plan_track(input, calibration, *, input2: Sequence = (), dots: str = "red", robots: int | None = None,
               line_method: str = "moments", max_predict_s: float = 1.0, camera=None, scene=None,
               live: bool = False, out=None, jsonl=None, udp=None) -> TrackPlan:
    """Check the options of ``posekit ceiling track`` together; a one-line ConfigError naming the flags.

    ``calibration``, ``camera`` and ``scene`` are a path or a list of paths: one calibration per input
    (``input`` then ``input2``), a lens and a scene once for all inputs or once per input.
    ``dots``: ``'red'``, ``'red,green'``, ``'line'`` or ``'red,red'`` (two robots, as ``robots=2``).
    """
    inputs = (input, *input2)
    cals = tuple(calibration) if isinstance(calibration, (list, tuple)) else (calibration,)
    if len(cals) != len(inputs):
        raise ConfigError(f"--calibration given {len(cals)} time(s) for {len(inputs)} input(s); "
                          "give one calibration per camera, in the order INPUT, --input2 ...")
    if dots.replace(" ", "") == "red,red":
        if robots not in (None, 2):
            raise ConfigError(f"--dots red,red means two robots; got --robots {robots}")
        robots, parsed = 2, ("red",)
    else:
        parsed = parse_dots(dots)
    robots = 1 if robots is None else robots
    if robots > 1 and (parsed != ("red",) or input2):
        raise ConfigError("--robots: several robots are tracked with one red dot each (--dots red) and one camera")
    try:
        config = TrackerConfig(dots=parsed, max_predict_s=max_predict_s)
    except ConfigError:
        raise ConfigError(f"--max-predict-s must be a number >= 0, got {max_predict_s:g}") from None
    if out is None and jsonl is None and udp is None:
        raise ConfigError("no output: give --out TRACK.csv, --jsonl FILE|- or --udp HOST:PORT")
    if out is not None and Path(out).is_dir():
        raise ConfigError(f"--out {out}: is a folder; expected a CSV file name")
    scene, camera = _per_input("--scene", scene, inputs), _per_input("--camera", camera, inputs)
    live = live or any(is_live_source(s) for s in inputs)
    options = {"method": line_method} if parsed == ("line",) and line_method != "moments" else None
    return TrackPlan(inputs, cals, parsed, robots, config, camera, scene, options, live)


def _per_input(flag: str, value, inputs):
    """None, one path for every input, or one per input (a list of one is that one path)."""
    if value is None or not isinstance(value, (list, tuple)):
        return value
    if len(value) not in (1, len(inputs)):
        raise ConfigError(f"{flag} given {len(value)} time(s) for {len(inputs)} input(s); give it once for "
                          "all inputs or once per input")
    return list(value) if len(value) > 1 else value[0]


def track_input(input, calibration, *, input2: Sequence = (), dots: str = "red", robots: int | None = None,
          line_method: str = "moments", fps: float | None = None, max_predict_s: float = 1.0, camera=None,
          scene=None, out=None, jsonl=None, udp=None, allow_remote: bool = False, live: bool = False,
          loop: int = 1, max_frames: int | None = None, progress: Callable | None = None) -> TrackRun:
    """``posekit ceiling track``: track the laser dot(s) and write the rows as they come.

    The arguments are the command's flags by the same names (:func:`plan_track`; ``fps``: frame rate
    of a file, Hz, default the video's; ``out``: the CSV, renamed into place at the end or on
    Ctrl-C; ``jsonl``: a file or ``'-'`` for stdout; ``udp``: ``HOST:PORT``). A KeyboardInterrupt
    ends the run with every row so far written (``interrupted``); a reader of ``jsonl='-'`` that
    leaves ends it too (``gone``). The rows are :class:`~posekit.ceiling.track.outputs.TrackOutputs`'.
    """
    plan = plan_track(input, calibration, input2=input2, dots=dots, robots=robots, line_method=line_method,
                      max_predict_s=max_predict_s, camera=camera, scene=scene, live=live, out=out, jsonl=jsonl,
                      udp=udp)
    outputs = TrackOutputs(None if out is None else Path(out), jsonl, udp, allow_remote=allow_remote,
                           robots=plan.robots)
    run = TrackRun(plan, None, outputs.counts, 0, to_stdout=outputs.to_stdout)
    try:
        common = dict(fps=fps, camera=plan.camera, loop=loop, max_frames=max_frames, live=live,
                      progress=None if plan.live else progress)
        if plan.robots > 1:
            from .multitrack import track_robots_video
            run.result = track_robots_video(plan.inputs[0], plan.calibrations[0], plan.robots, config=plan.config,
                                            on_row=outputs.write, **common)
        else:
            run.result = track_video(list(plan.inputs), list(plan.calibrations), plan.dots, config=plan.config,
                                     detector_options=plan.detector_options, on_row=outputs.write,
                                     scene=plan.scene, **common)
    except KeyboardInterrupt:
        run.interrupted = True
    except ReaderGone as exc:
        run.gone = str(exc)
        _silence_stdout()
    except BaseException:
        outputs.close(discard=True)
        raise
    finally:
        run.rows = outputs.frames
    outputs.close()                          # the CSV is renamed into place, complete, even after Ctrl-C
    run.counts = outputs.counts
    return run


def _silence_stdout() -> None:
    """Point stdout at /dev/null once its reader is gone, so that the interpreter's last flush
    does not print "Broken pipe" (stderr stays)."""
    import os
    import sys
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass
