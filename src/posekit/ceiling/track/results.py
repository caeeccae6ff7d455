"""The result of a track run: the rows, what is needed to plot them, and the timings."""

from dataclasses import dataclass, field

import numpy as np

from .types import STATUSES, TrackRow

__all__ = ["TrackResult"]


class _TimedRows:
    """What every per-frame track result shares: iteration over ``rows`` and the timings.

    Subclasses are dataclasses with ``rows``, ``seconds_total`` (s) and ``seconds_processing``
    (shape (N,), s per frame) fields; ``_n_frames`` gives the number of frames behind ``rows``.
    """

    def __iter__(self):
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    def _n_frames(self) -> int:
        return len(self.rows)

    @property
    def fps(self) -> float:
        """Frames per second end to end (decode + detect + map + filter)."""
        return self._n_frames() / self.seconds_total if self.seconds_total > 0 else float("nan")

    @property
    def processing_ms(self) -> float:
        """Median processing time per frame without decoding, ms."""
        return float(np.median(self.seconds_processing) * 1e3) if len(self.seconds_processing) else float("nan")


@dataclass
class TrackResult(_TimedRows):
    """Track of a video, with what is needed to plot and time it.

    Attributes
    ----------
    rows : list of TrackRow
        One per frame (iterate the result directly for the rows).
    image_uv : ndarray, shape (N, 2)
        Primary dot detected in the camera used at each frame, px (NaN where none
        was accepted): the trajectory in the image (the paper's Fig. 8).
    seconds_total : float
        Wall time of the whole run, decoding included, s.
    seconds_processing : ndarray, shape (N,)
        Wall time of detection + mapping + filtering per frame, s (decoding excluded).
    fps_source : str
        Where the frame rate of the timestamps came from.
    cameras : list of str
        Camera names.
    warnings : list of str
        What the sources reported (a video shorter than its header says, a stream that stopped).
    stats : dict
        ``rebuilds`` and ``relights`` of the detectors' backgrounds (a rebuild is a scene
        change the exposure gain did not explain; 0 on a steady scene), ``static_lights`` held
        at the end and where they came from (``scene``: ``"learned online"`` or ``"from the
        scene file"``).
    """

    rows: list[TrackRow]
    image_uv: np.ndarray
    seconds_total: float
    seconds_processing: np.ndarray
    fps_source: str = ""
    cameras: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)

    def xy(self) -> np.ndarray:
        """(N, 2) track in the world plane, mm (NaN where lost)."""
        return np.array([[r.x, r.y] for r in self.rows], dtype=float).reshape(-1, 2)

    def heading_deg(self) -> np.ndarray:
        return np.array([r.heading_deg for r in self.rows], dtype=float)

    def status(self) -> np.ndarray:
        return np.array([r.status for r in self.rows])

    def counts(self) -> dict[str, int]:
        s = self.status()
        return {k: int(np.sum(s == k)) for k in STATUSES}
