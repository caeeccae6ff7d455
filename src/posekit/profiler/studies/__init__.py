"""Experiments, tables and figures (DESIGN.md "Layout": the studies of the profiler).

They use the model, the simulator and the estimator, and nothing else imports them (the CLI
aside). ``evaluate`` (accuracy against simulated truth), ``study`` (Table I and what the
design studies share), ``study_noise`` (Fig. 3), ``study_limits`` (Fig. 4), ``study_report``
(CSV, PNG, report.html) and ``gauge_check_rates`` (both error rates of the gauge-file test).
"""

__all__ = ["evaluate", "study", "study_noise", "study_limits", "study_report", "gauge_check_rates"]
