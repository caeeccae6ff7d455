"""Helpers shared by the ceiling tests: one verb's CLI run in-process, and a camera looking at a point."""

import argparse

import numpy as np

__all__ = ["look_at", "run_verb"]


def run_verb(add_parser, argv):
    """Parse ``argv`` (``[VERB, ...]``) with the parser that ``add_parser(subparsers)`` adds and run it.

    Returns the verb's exit code; a PosekitError propagates (as ``main`` would print it).
    """
    parser = argparse.ArgumentParser(prog="posekit ceiling")
    add_parser(parser.add_subparsers(dest="verb"))
    args = parser.parse_args([str(a) for a in argv])
    return args.func(args)


def look_at(C, target):
    """``(R_cam_world, t_cam_world)`` of a camera at ``C`` (mm; Z down from the ceiling) whose optical axis
    points at ``target`` (mm), image x along ``z_C x Z``."""
    C = np.asarray(C, dtype=float)
    z = np.asarray(target, dtype=float) - C
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ C
