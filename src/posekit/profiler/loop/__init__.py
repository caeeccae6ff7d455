"""The closed loop of the paper's §IV-C, an experiment: robot and sensor simulators, the PD
compensation, step-response metrics, the Table III/IV experiment over loopback sockets and
its report, and the OpenCV camera pipeline that Table III compares against.

Modules: ``robotsim``, ``control``, ``response``, ``loop_sim``, ``loop``, ``loop_report``,
``chessboard`` (the simulated camera) and ``camera_peer`` (its OpenCV pipeline, timed).
"""

__all__ = ["robotsim", "control", "response", "loop_sim", "loop", "loop_report", "chessboard", "camera_peer"]
