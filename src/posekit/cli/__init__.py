"""The ``posekit`` command: one sub-command group per system.

It has no Python API of its own: ``posekit.cli.main.main(argv)`` runs the command in-process
(the entry point), and every verb calls one public library function of its system.
"""

__all__ = ["main"]
