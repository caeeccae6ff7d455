"""The estimator: one laser profile (or a batch) → the pose ``T_G_F`` with its covariance and verdict.

Pure on its inputs (a profile array, a :class:`~posekit.profiler.gauge.model.Gauge`, the noise
it assumes): no files, no simulator. It never imports ``sim/`` or ``studies/`` (a test checks
it; DESIGN.md "Layout"). Modules: ``segments``, ``face_fit``, ``faces``, ``corner_params`` and
``corners`` (corner detection, paper §II-D), ``closed_form`` (eq. 9–14), ``refine`` (the ML
refinement, eq. 15), ``covariance`` (the error model), ``consistency`` (the χ² tests that make
an estimate 'ok' or 'suspect'), ``result`` (:class:`~posekit.profiler.estimate.result.PoseEstimate`
and its :class:`posekit.verdict.Verdict`), ``solve`` (corners → pose), ``pipeline`` (profile and
batch → pose and records) and ``fast`` (the unchecked real-time path). The public names are
exported by :mod:`posekit.profiler`.
"""

__all__ = ["segments", "face_fit", "faces", "corner_params", "corners", "closed_form", "refine", "covariance",
           "consistency", "result", "solve", "pipeline", "fast"]
