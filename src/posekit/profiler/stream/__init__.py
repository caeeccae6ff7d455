"""Profiles in, records out: files, the real-time stream and its server.

``reading`` (profile files with the options a sensor's export needs) and ``records`` (pose
records as JSON lines or CSV, the simulator's truth CSV); ``protocol`` (binary profile frames)
and ``lines`` (JSON lines to the robot); ``server`` with ``server_receiver``, ``server_worker``,
``server_records`` and ``server_support``; ``stream_client`` (a sensor and a robot stub);
``sources`` and ``socket_source`` (where profiles come from); ``pose_filter`` (filters for a
stream of estimates). It uses the estimator and the simulator; nothing in the model, the
estimator or the simulator imports it.
"""

__all__ = ["reading", "records", "protocol", "lines", "server", "server_receiver", "server_worker", "server_records",
           "server_support", "stream_client", "sources", "socket_source", "pose_filter"]
