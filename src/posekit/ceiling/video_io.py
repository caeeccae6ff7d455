"""Frames with timestamps from a video file or a folder of images.

:func:`open_frames` accepts a video file that OpenCV can decode (``cv2.VideoCapture``) or a
folder of images sorted by file name (``cv2.imread``). Timestamps are ``index / fps`` with
the frame rate from ``fps=``, else the video container, else
:data:`DEFAULT_FPS` (the paper's camera; ``fps_source`` says which).
Bad input is an :class:`~posekit.errors.InputFileError` with a one-line message naming
the path: a missing path, a file OpenCV cannot decode as a video, an empty folder or one
without images, an image file that does not decode, frames that change size.
"""

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._extras import require
from ..errors import ConfigError, InputFileError
from ..io import check_frame_size, check_input_file, read_image

__all__ = ["IMAGE_SUFFIXES", "DEFAULT_FPS", "Frame", "FrameSource", "open_frames", "list_images"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
"""File suffixes (case-insensitive) taken as images in a folder."""

DEFAULT_FPS = 15.0
"""Frame rate assumed when neither the caller nor the container gives one (the paper's camera)."""


@dataclass
class Frame:
    """One frame.

    Attributes
    ----------
    index : int
        Frame number from 0.
    time_s : float
        ``index / fps``, s.
    image : ndarray, shape (H, W, 3), uint8
        BGR image (a grey image is converted to BGR).
    name : str
        Image file name, or ``"frame N"`` for a video.
    """

    index: int
    time_s: float
    image: np.ndarray
    name: str


def list_images(folder: Path) -> list[Path]:
    """Image files of ``folder`` (by suffix, hidden files skipped), sorted by name.

    Raises
    ------
    InputFileError
        The folder has no image file (empty, or only other files).
    """
    folder = Path(folder)
    try:
        files = sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))
    except PermissionError:
        raise InputFileError(f"{folder}: permission denied (cannot list the folder); expected a readable "
                             "folder of images") from None
    except OSError as exc:
        raise InputFileError(f"{folder}: cannot list the folder ({exc.strerror or exc})") from None
    images = [p for p in files if p.suffix.lower() in IMAGE_SUFFIXES]
    if not images:
        if not files:
            raise InputFileError(f"{folder}: empty folder; expected images ({', '.join(IMAGE_SUFFIXES)}) "
                                 "sorted by name")
        shown = ", ".join(p.name for p in files[:3]) + (", ..." if len(files) > 3 else "")
        raise InputFileError(f"{folder}: no image files among {len(files)} file(s) ({shown}); "
                             f"expected {', '.join(IMAGE_SUFFIXES)}")
    return images


def _as_bgr(img: np.ndarray) -> np.ndarray:
    cv2 = require("cv2", "vision", "reading video and images (ceiling track)")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


class FrameSource:
    """Iterable over the :class:`Frame` s of a video file or an image folder.

    Use :func:`open_frames` to build one. The first frame is decoded on opening so that a
    bad input fails at once; ``image_size`` is ``(width, height)``, ``fps`` the frame
    rate used for the timestamps and ``fps_source`` one of ``"argument"``,
    ``"container"``, ``"default"``. ``len()`` is the frame count (for a video, the
    container's count, which may be approximate).
    """

    def __init__(self, path: Path, fps: float | None = None):
        cv2 = require("cv2", "vision", "reading video and images (ceiling track)")
        self.path = Path(path)
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise ConfigError(f"--fps must be a positive number, got {fps!r}")
        if not self.path.exists():
            raise InputFileError(f"{self.path}: no such file or folder; expected a video file or a folder of images")
        self.is_folder = self.path.is_dir()
        container_fps = 0.0
        if self.is_folder:
            self._files = list_images(self.path)
            first = self._read_image(self._files[0])
            self._count = len(self._files)
        else:
            check_input_file(self.path, expected="a video file or a folder of images")
            cap = cv2.VideoCapture(str(self.path))
            if cap.isOpened():  # the container's frame size, before a frame is decoded
                w, h = cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)
                if w > 0 and h > 0:
                    try:
                        check_frame_size(w, h, str(self.path))
                    except InputFileError:
                        cap.release()
                        raise
            ok, first = (cap.read() if cap.isOpened() else (False, None))
            if not ok or first is None:
                cap.release()
                raise InputFileError(f"{self.path}: cannot read a video frame from this file (not a video "
                                     "OpenCV can decode); expected a video file or a folder of images")
            container_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            self._count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
            cap.release()
        first = _as_bgr(first)
        self.image_size = (int(first.shape[1]), int(first.shape[0]))
        if fps is not None:
            self.fps, self.fps_source = float(fps), "argument"
        elif np.isfinite(container_fps) and 0 < container_fps < 1e4:
            self.fps, self.fps_source = container_fps, "container"
        else:
            self.fps, self.fps_source = DEFAULT_FPS, "default"

    def _read_image(self, p: Path) -> np.ndarray:
        img = read_image(p)  # the header's size is checked before decoding
        if img is None:
            raise InputFileError(f"{p}: cannot decode this file as an image")
        return img

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[Frame]:
        size = self.image_size
        if self.is_folder:
            for i, p in enumerate(self._files):
                img = _as_bgr(self._read_image(p))
                self._check_size(img, size, p.name)
                yield Frame(i, i / self.fps, img, p.name)
            return
        cv2 = require("cv2", "vision", "reading video and images (ceiling track)")
        cap = cv2.VideoCapture(str(self.path))
        try:
            i = 0
            while True:
                ok, img = cap.read()
                if not ok or img is None:
                    break
                img = _as_bgr(img)
                self._check_size(img, size, f"frame {i}")
                yield Frame(i, i / self.fps, img, f"frame {i}")
                i += 1
        finally:
            cap.release()

    def _check_size(self, img, size, name):
        if (img.shape[1], img.shape[0]) != size:
            raise InputFileError(f"{self.path}: {name} is {img.shape[1]}x{img.shape[0]} px but the first frame "
                                 f"is {size[0]}x{size[1]} px; every frame must have the same size")


def open_frames(path: str | Path, fps: float | None = None) -> FrameSource:
    """Open a video file or a folder of images for reading.

    Parameters
    ----------
    path : str or Path
        Video file (any container OpenCV decodes: .avi, .mp4, ...) or folder of images
        (``IMAGE_SUFFIXES``, sorted by name; hidden and non-image files are skipped).
    fps : float, optional
        Frame rate for the timestamps, Hz (overrides the container's).

    Returns
    -------
    FrameSource

    Raises
    ------
    InputFileError
        Missing path, undecodable video, empty folder or no images, an image that does
        not decode (raised while iterating), a frame of another size.
    ConfigError
        ``fps`` is not positive.
    """
    return FrameSource(Path(path), fps)
