"""The ceiling simulator: a tiled ceiling seen by a fixed camera while a robot's laser dots move
on it, with what a real installation adds (lens, bloom, exposure, occluders, stray lights,
compression). Uses the models (camera, calibration), never the tracker's internals.

Modules: ``config`` (the scene, :class:`SceneConfig`), ``scene_geometry`` (camera, lens, homography,
robot path), ``effects`` (the realistic effects), ``render`` (the frames), ``video`` (the video and its
files), ``chessboard`` (lens-calibration views), ``simulation`` (the ``simulate`` verb)."""

from .config import REALISTIC, SceneConfig
from .render import CeilingScene, iter_frames
from .scene_geometry import true_homography
from .simulation import CeilingSimulation, dump_scene_config, scene_config, scene_effects, simulate, simulation_dots
from .video import render_video

__all__ = ["REALISTIC", "SceneConfig", "CeilingScene", "iter_frames", "render_video", "true_homography",
           "CeilingSimulation", "scene_config", "dump_scene_config", "scene_effects", "simulate", "simulation_dots"]
