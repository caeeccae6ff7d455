"""The simulator: profiles of a gauge as the sensor would measure them, with a known truth.

It may use the model (:mod:`posekit.profiler.gauge`, :mod:`posekit.profiler.sensor`) and never
the estimator (a test checks that no module here imports ``estimate/``; DESIGN.md "Layout"):
a simulator that borrowed the estimator's parts would hide the estimator's mistakes. Every
function that draws takes a seed or generator. Modules: ``poses`` (nominal, random and smooth
sensor poses), ``render`` (the ideal gauge seen by the fan, plus the sensor noise),
``realism`` (what a real cell adds: the as-built gauge and its surroundings) and
``realism_render`` (casting that scene). The public names are exported by :mod:`posekit.profiler`.
"""

__all__ = ["poses", "render", "realism", "realism_render"]
