"""Real-time streams: the PKPF protocol, the pose server and its receiver, sensor and robot
clients, profile sources (files, simulator, socket, a vendor SDK) and the pose filter."""
