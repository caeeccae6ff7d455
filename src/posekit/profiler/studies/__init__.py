"""Gauge design studies on Dask: Table I (corners and gauges), Fig. 3 (noise), Fig. 4 (limits),
and their reports."""
