"""What :class:`~posekit.profiler.stream.server.PoseServer` counted and timed: :meth:`ServerStats.stats`
and :meth:`ServerStats.timings`.

:class:`ServerStats` is a mixin: it holds no state of its own and reads the server's
(``_counts``, ``_reasons``, ``_n_conns``, ``_n_suspect``, ``_tim``, ``_tim_n`` under
``_stats_lock``; ``_queues`` under ``_cond``), which the receiver
(:mod:`~posekit.profiler.stream.server_receiver`) and the worker
(:mod:`~posekit.profiler.stream.server_worker`) write.
"""

from collections import Counter

import numpy as np

__all__ = ["ServerStats", "TIMING_KEYS"]

#: The per-frame stages of :meth:`ServerStats.timings`, in the columns of the server's ``_tim``.
TIMING_KEYS = ("DT", "QW", "CD", "PC")


class ServerStats:
    """Counters and per-stage timings of a running :class:`~posekit.profiler.stream.server.PoseServer`."""

    def stats(self) -> dict:
        """Counters since :meth:`~posekit.profiler.stream.server.PoseServer.start`.

        Returns
        -------
        dict
            ``received`` (well-formed frames decoded), ``processed`` (frames that went
            through detection and pose, ok or not), ``ok`` and ``suspect`` (processed frames
            with a pose and that verdict), ``errors`` (processed frames whose profile or
            controller failed; ``processed == ok + suspect + errors``), ``dropped`` (oldest frames pushed out of
            the full buffer), ``rejected`` (malformed stretches of the stream and NaN
            storms) with ``reasons`` (a :class:`collections.Counter` by reason),
            ``disconnects`` (every close, by either side), ``connections`` (accepted),
            ``connected`` (sensors open now: connections that proved themselves),
            ``timeouts`` (closed by the hello, idle or read timeout),
            ``auth_failures`` (closed for a missing, malformed or wrong hello),
            ``evictions`` (sensors closed for a new one, see ``max_connections``), ``shed``
            (connections that had not proved themselves closed for newer ones, or sent too much
            without doing so, and sensors refused because all places were taken by streaming
            ones), ``rate_limited`` (times a sensor was read more slowly for its rate),
            ``accept_limited`` (times new connections were left waiting, see ``max_accept_hz``), ``bad_stamps``
            (frames whose sensor stamp was not believed: DT unknown), ``cold_restarts``
            (warm starts that fell back to the closed form), ``sent``/``unsent`` records and
            ``robot_connects``/``robot_failures``, and ``queued``. Once idle, ``received ==
            processed + dropped + reasons['nan_storm']``.
        """
        with self._stats_lock:
            c = self._counts
            out = dict(vars(c))
            out["reasons"] = Counter(self._reasons)
            out["connected"] = self._n_conns
            out["suspect"] = self._n_suspect
        with self._cond:
            out["queued"] = sum(len(q) for q in self._queues.values())
        return out

    def timings(self) -> dict:
        """Per-stage times of the processed frames (the most recent ``history``), ms.

        Returns
        -------
        dict of str to ndarray, shape (k,)
            ``DT`` (sensor stamp → last byte received; NaN where the stamp was not
            believed, see ``max_dt_s``), ``QW`` (wait in the buffer),
            ``CD`` (NaN check + corner detection), ``PC`` (pose + covariance +
            controller), oldest first.
        """
        with self._stats_lock:
            h = self._tim.shape[0]
            n = self._tim_n
            if n <= h:
                arr = self._tim[:n].copy()
            else:
                i = n % h
                arr = np.concatenate([self._tim[i:], self._tim[:i]])
        return {k: arr[:, j] for j, k in enumerate(TIMING_KEYS)}
