"""Submit 40 rendered profiles (noise, a few bad ones) to a PoseServer; print every record without its
timing, the stats without timing-dependent counters, and the option errors: diff main vs branch."""
import json
import time

import numpy as np

from posekit.errors import PosekitError
from posekit.profiler import bundled_gauge, nominal_pose, render_profiles
from posekit.profiler.stream.server import PoseServer


class Sink:
    def __init__(self):
        self.records = []

    def put(self, rec):
        self.records.append(rec)


g = bundled_gauge("demo-5")
rng = np.random.default_rng(0)
sink = Sink()
with PoseServer(g, freeze_gc=False, record_sink=sink, queue_size=100) as server:
    for k in range(40):
        prof = render_profiles(g, nominal_pose(g), rng=k)
        if k % 10 == 3:
            prof = prof * np.nan
        if k % 10 == 7:
            prof = prof[:5]
        server.submit(prof, t_sensor_ns=time.perf_counter_ns())
        time.sleep(0.01)
    t0 = time.time()
    while len(sink.records) < 40 and time.time() - t0 < 10:
        time.sleep(0.05)
    st = server.stats()
    tim = server.timings()
for r in sink.records:
    r = dict(r)
    r.pop("timing_ms"); r.pop("t_sensor_ns")
    print(json.dumps(r, sort_keys=True, default=str))
print({k: v for k, v in sorted(st.items()) if k not in ("bad_stamps",)})
print(sorted(tim), [len(v) for v in tim.values()])
for kw in [dict(method="x"), dict(queue_size=0), dict(idle_timeout_s=0.0), dict(max_rate_hz=0), dict(allow_remote=True),
           dict(token=""), dict(significance=2), dict(noise="x"), dict(pose_filter=object()), dict(record_sink=1),
           dict(max_pending=True), dict(history=0), dict(nan_storm_fraction=1.0), dict(listen=("10.0.0.1", 0)),
           dict(method="cf", pose_filter=type("F", (), {"update": lambda *a: None})())]:
    try:
        PoseServer(g, freeze_gc=False, **kw)
        print(kw, "accepted")
    except PosekitError as exc:
        print(type(exc).__name__, exc)
