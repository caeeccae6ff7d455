"""The model of the world the profiler measures: the multi-plane gauge.

Part of the profiler's four kinds of part (DESIGN.md "Layout"): the **model** (``gauge/`` and
:mod:`posekit.profiler.sensor`: what the gauge and the sensor are — plain data and their
geometry), the **estimator** (``estimate/``: pure on its inputs, never imports ``sim/`` or
``studies/``), the **simulator** (``sim/``: may use the model, never the estimator) and the
**studies** (``studies/``, ``loop/``: experiments, tables, figures). ``stream/`` carries profiles
in and records out.

Modules: ``model`` (the gauge file, validation, ridges, bundled gauges), ``raycast`` (first
face hit of a ray), ``ambiguity`` (the load-time check that the profiles can tell the mounting;
it measures with the estimator's kernels), ``design`` (random gauges within the design rules),
``datum`` (how far an as-built gauge lies from its drawing), ``bundle`` and ``calibration``
(the as-built gauge from profiles) and ``check`` (the batch test of a gauge file). The
public names are exported by :mod:`posekit.profiler`; the sub-package lists its modules only,
since re-exporting them here would close import circles at run time (``ambiguity`` and
``calibration`` use the estimator, which uses ``model``).
"""

__all__ = ["model", "raycast", "ambiguity", "design", "datum", "bundle", "calibration", "check"]
