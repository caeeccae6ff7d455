"""Profiles in, records out: files, the real-time stream and its server.

Files: ``reading`` (profile files with the options a sensor's export needs), ``records`` (pose
records as JSON lines or CSV, the simulator's truth CSV) and ``files`` (the ``estimate`` and
``calibrate-gauge`` verbs). The stream: ``protocol`` (binary profile frames) and ``lines`` (JSON
lines to the robot). The pose server: ``server``
(:class:`~posekit.profiler.stream.server.PoseServer`: construction, start/stop, frames submitted
from this process) with ``server_options`` (its checked options), ``server_receiver`` (the
receiving thread), ``server_worker`` (the worker thread), ``server_stats`` (its counters and
timings), ``server_records`` (record outputs) and ``server_support`` (addresses, the token, one
connection, logging, counters, the robot link); ``serve`` and ``replay`` (the ``serve`` and
``replay`` verbs) and ``soak`` (the server under attack, behind ``posekit bench server``). Around
it: ``stream_client`` (a sensor and a robot stub), ``sources`` and ``socket_source`` (where
profiles come from) and ``pose_filter`` (filters for a stream of estimates). It uses the estimator
and the simulator; nothing in the model, the estimator or the simulator imports it.
"""

__all__ = ["reading", "records", "protocol", "lines", "server", "server_options", "server_receiver",
           "server_worker", "server_stats", "server_records", "server_support", "stream_client", "sources",
           "socket_source", "pose_filter"]
