"""The estimator: gauges and their design rules, the LJ-X8400-like sensor model and the
realistic simulator, corner detection (model-based and RDP), the closed form and the ML
refinement with its covariance and verdict, the batch pipeline, evaluation, profile/record
files and the as-built gauge calibration. The public names are re-exported by
:mod:`posekit.profiler`."""
