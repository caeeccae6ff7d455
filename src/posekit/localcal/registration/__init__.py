"""Trajectory registration: trajectory files, timestamp association, robust Umeyama alignment,
correspondence-free coarse alignment and rigid CPD, and ``match_trajectories`` on top of them."""
