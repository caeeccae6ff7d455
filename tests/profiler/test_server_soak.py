"""The pose server under attack (issue 28, deliverable 8): 16 sensors at 25 Hz with a token, 20
hostile clients (silent connects, floods of frames and of garbage, wrong tokens, an insider
flooding empty frames) for 3 s on loopback.

Measured before this round's server (`python -m posekit bench server`, 8 s, same harness):
2.7-3.5 % of the good frames processed, latency p50 207-269 ms, p99 913-994 ms, 343-398
sensors evicted. The longer soak, with the latency targets, is ``posekit bench server``.
"""

from posekit.profiler.stream.soak import run_soak


def test_sixteen_sensors_keep_their_frames_under_attack():
    r = run_soak(sensors=16, rate_hz=25.0, hostile=20, duration_s=3.0, seed=0)
    print(r.summary())
    st = r.stats
    # every frame the good sensors sent was processed, none of them was evicted; how fast (p99 <= 10 ms)
    # and whether the sensors kept their 25 Hz schedule are timings: `posekit bench server` reports them
    assert r.sent >= 16 * 25, r.summary()
    assert r.delivered >= 0.99, r.summary()
    assert r.evictions == 0 and r.send_failures == 0, r.summary()
    # the attack happened and was turned away: wrong or missing tokens, clients that never proved
    # themselves, the insider slowed down
    assert r.hostile_connects >= 20 and st["auth_failures"] > 0 and st["shed"] + st["timeouts"] > 0, st
