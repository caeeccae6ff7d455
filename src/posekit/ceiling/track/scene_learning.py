"""``posekit ceiling learn-scene``: the static lights of the empty scene, from a short recording.

Record the ceiling with the laser off (or the robot standing still) for a few seconds; every
spot the laser detector finds there is chained over the frames by the camera's model of static
lights (:class:`~posekit.ceiling.detect.scene.StaticLights`), and those the motion test finds
static — a lamp, an exit sign, a smoke-detector LED, a glint, steady or blinking — are written
to SCENE.json with their image position, ceiling position (through the calibration and the
lens), colour and centroid jitter. ``track --scene SCENE.json`` then knows them from the first
frame on instead of learning them online.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..detect.dots import DotDetector
from ..detect.scene import MOVING, Light, StaticLights, save_scene
from .cameras import Camera
from .setup import _as_calibration, _as_lens, fit_calibration
from .sources import is_live_source, open_frames, open_live

__all__ = ["SceneLearning", "learn_scene"]


@dataclass
class SceneLearning:
    """Result of :func:`learn_scene`.

    Attributes
    ----------
    lights : list of Light
        Static lights (image px, ceiling mm, colour, jitter px 1σ, frames seen).
    image_size : (int, int)
        ``(width, height)`` of the frames, px.
    frames : int
        Frames read.
    jitter_px : float
        The scene's centroid jitter (the model's ``scene_jitter_px``), px.
    moving : int
        Spots that the test found moving (the laser was on, or something moved): not lights.
    warnings : list of str
    """

    lights: list
    image_size: tuple
    frames: int
    jitter_px: float
    moving: int = 0
    warnings: list = field(default_factory=list)


def learn_scene(source, calibration, *, camera=None, out=None, fps: float | None = None,
                max_frames: int | None = None, colors=("red", "green"), min_share: float = 0.1) -> SceneLearning:
    """Learn the static lights of a recording of the empty ceiling.

    Parameters
    ----------
    source : path or str
        Video file, folder of images, camera index or stream URL.
    calibration : Calibration or path
        The homography of this camera (``posekit ceiling calibrate``).
    camera : CameraModel or path, optional
        The lens (``posekit ceiling camera``): centroids are undistorted before the homography.
    out : path, optional
        Write SCENE.json there (``{"image_size", "frames", "jitter_px", "source", "lights": [...]}``).
    fps, max_frames :
        As for ``track`` (a camera needs ``max_frames``).
    colors : tuple of str
        Laser colours whose spots are looked for.
    min_share : float
        A light must have been seen in at least this share of the frames (and 8 of them).

    Returns
    -------
    SceneLearning

    Raises
    ------
    InputFileError, CalibrationError, ConfigError
        Unreadable input or calibration, a calibration of another resolution.
    """
    live = is_live_source(source)
    src = open_live(source, max_frames=max_frames, fps=fps) if live else open_frames(source, fps, max_frames=max_frames)
    notes: list = []
    cal = fit_calibration(_as_calibration(calibration), src.image_size, str(source), notes=notes)
    cam = Camera(cal, src.image_size, lens=_as_lens(camera))
    det = DotDetector(tuple(colors))
    model = StaticLights(jitter_floor_px=cam.detection_std_px)
    n, moving_tracks = 0, set()
    for fr in src:
        n += 1
        if fr.image is None:
            continue
        dots = det.detect(fr.image)
        states = model.update(fr.index, [(d.u, d.v) for d in dots], [d.color for d in dots])
        for k, s in enumerate(states):
            if s == MOVING:
                moving_tracks.add((round(dots[k].u / 20), round(dots[k].v / 20)))
    lights = model.lights(min_seen=max(8, int(np.ceil(min_share * n))))
    if lights:
        xy, _ = cam.measurement(np.array([(lt.u, lt.v) for lt in lights]))
        lights = [Light(lt.u, lt.v, lt.jitter_px, lt.colour, lt.seen, float(p[0]), float(p[1]))
                  for lt, p in zip(lights, xy)]
    warnings = list(notes) + list(getattr(src, "warnings", []))
    if moving_tracks:
        warnings.append(f"{len(moving_tracks)} moving spot(s) were seen (the laser on, or the robot moving): they "
                        "are not part of the scene; record it with the laser off or the robot still")
    res = SceneLearning(lights, tuple(src.image_size), n, model.scene_jitter_px(), len(moving_tracks), warnings)
    if out is not None:
        save_scene(Path(out), lights, src.image_size, n, res.jitter_px, str(source))
    return res
