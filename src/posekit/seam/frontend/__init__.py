"""The front end: configuration and the cell, the fitted profile and its tuner, the robot program,
simulated and recorded episodes, the online tracker, studies, sensor design, report and plots.

Modules:

- configuration: ``config`` (the YAML configuration, loading and overrides), ``config_types``
  (validated numbers, transforms, size limits), ``config_cell`` (robot and sensors of the cell),
  ``config_legacy`` (the layout before issue 26), ``config_messages`` (one-line error messages);
- the profile and its tuner: ``profile`` (the profile file), ``tune`` (``posekit seam tune``),
  ``tune_fit`` (its shared numerical pieces), ``tune_intervals`` (the 1σ of the tuned values),
  ``tune_truth`` (``tune --with-truth``), ``tune_nis`` (the integrity test's calibration), ``tune_filter`` (the particle filter over
  recorded episodes, for the steps that judge it), ``tune_latency`` (a latency not pinned: its effect on the pose);
- the robot program: ``trajectories`` (seams and nominal programs);
- simulated episodes: ``simulate`` (the simulated world: true robot, process, sensors),
  ``episode`` (the particle filter over one simulated episode, :func:`run_episode`),
  ``episode_metrics`` (pooled accuracy, speed and integrity: ``metrics.json``), ``seam_frame``
  (errors and coordinates in the nominal seam frame);
- recorded episodes and the online tracker: ``logs``, ``logs_setup``, ``tracker``;
- studies: ``compare`` (configurations side by side), ``study`` (the Monte-Carlo tuning study),
  ``study_factors`` (the perturbed parameters), ``study_effects`` (OLS effects and ranking),
  ``design`` (sensor placement);
- output: ``report`` (CSV and report files), ``plots``;
- the library call of each CLI verb: ``commands``, ``commands_batch``.

The public names are exported by :mod:`posekit.seam`; the sub-package lists its modules only.
"""

__all__ = ["commands", "commands_batch", "compare", "config", "config_cell", "config_legacy", "config_messages",
           "config_types", "design", "episode", "episode_metrics", "logs", "logs_setup", "plots", "profile",
           "report", "seam_frame", "simulate", "study", "study_effects", "study_factors", "tracker",
           "trajectories", "tune", "tune_filter", "tune_fit", "tune_intervals", "tune_latency", "tune_nis",
           "tune_truth"]
