"""Input checks shared by the localcal simulator modules."""

import numpy as np

from posekit.errors import GeometryError

__all__ = ["rigid_transform"]


def rigid_transform(T, name: str) -> np.ndarray:
    """Return ``T`` as a float64 (4, 4) rigid transform or raise a one-line GeometryError."""
    try:
        T = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        raise GeometryError(f"{name}: expected a (4, 4) rigid transform, got {type(T).__name__}") from None
    if T.shape != (4, 4):
        raise GeometryError(f"{name}: expected a (4, 4) rigid transform, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise GeometryError(f"{name}: expected a (4, 4) rigid transform, found NaN or inf")
    R = T[:3, :3]
    if (
        np.max(np.abs(R.T @ R - np.eye(3))) > 1e-6
        or np.linalg.det(R) <= 0
        or np.max(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-9
    ):
        raise GeometryError(
            f"{name}: expected a rigid transform (orthonormal rotation block with det +1, "
            f"last row [0, 0, 0, 1])"
        )
    return T
