"""The simulator: hydraulic long-reach arm with non-kinematic errors, eye-in-hand camera with
ArUco rendering and detection, the work cell, drifting VO, one look-then-move episode and the
paper's repeated-run experiments."""
