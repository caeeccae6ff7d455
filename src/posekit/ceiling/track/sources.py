"""Frames with timestamps from a video file or a folder of images.

:func:`open_frames` accepts a video file that OpenCV can decode (``cv2.VideoCapture``) or a
folder of images sorted by file name (``cv2.imread``). Timestamps are ``index / fps`` with
the frame rate from ``fps=``, else the video container, else
:data:`DEFAULT_FPS` (the paper's camera; ``fps_source`` says which).
Bad input is an :class:`~posekit.errors.InputFileError` with a one-line message naming
the path: a missing path, a file OpenCV cannot decode as a video, an empty folder or one
without images. An image in a folder that does not decode, or a frame of another size than
the first, is not an error: its :class:`Frame` has ``image=None`` and the reason in ``error``
(the tracker writes a ``lost`` row with it and goes on); what an image decoder prints goes
into that reason, never to the terminal. A video that ends before the frame count its header
declares is read to its end; ``FrameSource.warnings`` then says how many frames were
declared and how many decoded.

Live input (:func:`open_live`): a camera index (``0``), a device (``/dev/video0``) or a
stream URL (``rtsp://``, ``http://``, ...) read with ``cv2.VideoCapture``; each frame is
stamped with the capture clock (seconds since the first frame). A video file can be played
through the same path (``loop=``: as many passes), which is how the live path is tested.
"""

import os
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..._extras import require
from ...errors import ConfigError, InputFileError
from ...io import check_frame_size, check_input_file, read_image

__all__ = ["IMAGE_SUFFIXES", "DEFAULT_FPS", "Frame", "FrameSource", "LiveSource", "open_frames", "open_live",
           "is_live_source", "list_images"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
"""File suffixes (case-insensitive) taken as images in a folder."""

DEFAULT_FPS = 15.0
"""Frame rate assumed when neither the caller nor the container gives one (the paper's camera)."""

# FFmpeg inside OpenCV prints its own lines ("moov atom not found") beside the one-line error of a
# broken video; quiet unless the user set the level. Read when the first capture opens.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


@dataclass
class Frame:
    """One frame.

    Attributes
    ----------
    index : int
        Frame number from 0.
    time_s : float
        ``index / fps``, s.
    image : ndarray, shape (H, W, 3), uint8, or None
        BGR image (a grey image is converted to BGR); None when the frame could not be decoded.
    name : str
        Image file name, or ``"frame N"`` for a video.
    error : str
        Why ``image`` is None (empty otherwise).
    """

    index: int
    time_s: float
    image: np.ndarray | None
    name: str
    error: str = ""


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

    def __init__(self, path: Path, fps: float | None = None, max_frames: int | None = None):
        cv2 = require("cv2", "vision", "reading video and images (ceiling track)")
        self.path = Path(path)
        if max_frames is not None and int(max_frames) < 1:
            raise ConfigError(f"--max-frames must be at least 1, got {max_frames}")
        self.max_frames = None if max_frames is None else int(max_frames)
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise ConfigError(f"--frame-rate-hz must be a positive number, got {fps!r}")
        if not self.path.exists():
            raise InputFileError(f"{self.path}: no such file or folder; expected a video file or a folder of images")
        self.is_folder = self.path.is_dir()
        container_fps = 0.0
        self.warnings: list[str] = []
        self.decoded = 0
        if self.is_folder:
            self._files = list_images(self.path)
            first, why = None, ""
            for p in self._files:
                first, why = self._try_image(p)
                if first is not None:
                    break
            if first is None:
                raise InputFileError(f"{self.path}: none of the {len(self._files)} image file(s) decodes "
                                     f"({why}); expected a folder of images")
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

    def _try_image(self, p: Path) -> tuple[np.ndarray | None, str]:
        """The image of ``p`` (BGR) and "", or None and why it could not be read (with what the
        decoder said, which never reaches the terminal: libpng and libjpeg write to fd 2)."""
        with _captured_stderr() as said:
            try:
                img = read_image(p)  # the header's size is checked before decoding
            except InputFileError as exc:
                img, why = None, str(exc)
            else:
                why = "" if img is not None else f"{p}: cannot decode this file as an image"
        if img is None:
            text = " ".join(said.text.split())[:120]
            return None, why + (f" (decoder: {text})" if text else "")
        return _as_bgr(img), ""

    def __len__(self) -> int:
        return self._count if self.max_frames is None else min(self._count, self.max_frames)

    def __iter__(self) -> Iterator[Frame]:
        size = self.image_size
        self.decoded = 0
        if self.is_folder:
            files = self._files if self.max_frames is None else self._files[:self.max_frames]
            for i, p in enumerate(files):
                img, why = self._try_image(p)
                if img is not None:
                    img, why = self._check_size(img, size, p.name)
                if img is not None:
                    self.decoded += 1
                yield Frame(i, i / self.fps, img, p.name, why)
            return
        cv2 = require("cv2", "vision", "reading video and images (ceiling track)")
        cap = cv2.VideoCapture(str(self.path))
        try:
            i = 0
            while self.max_frames is None or i < self.max_frames:
                ok, img = cap.read()
                if not ok or img is None:
                    break
                img, why = self._check_size(_as_bgr(img), size, f"frame {i}")
                if img is not None:
                    self.decoded += 1
                yield Frame(i, i / self.fps, img, f"frame {i}", why)
                i += 1
            if self._count > 0 and i < self._count and (self.max_frames is None or i < self.max_frames):
                self.warnings.append(f"{self.path}: the header declares {self._count} frames but {i} were decoded "
                                     "(a truncated or damaged video?); tracked the decoded frames")
        finally:
            cap.release()

    def _check_size(self, img, size, name):
        """(img, "") or, for a frame of another size than the first, (None, why): a ``lost`` row."""
        if (img.shape[1], img.shape[0]) != size:
            return None, (f"{name} is {img.shape[1]}x{img.shape[0]} px but the first frame is {size[0]}x{size[1]} px "
                          "(skipped)")
        return img, ""


class _Said:
    text = ""


class _captured_stderr:
    """Redirect file descriptor 2 into a temporary file for the block; ``.text`` afterwards."""

    def __enter__(self):
        import tempfile
        self.said = _Said()
        try:
            self._tmp = tempfile.TemporaryFile()
            self._saved = os.dup(2)
            os.dup2(self._tmp.fileno(), 2)
        except OSError:
            self._saved = None
        return self.said

    def __exit__(self, *exc):
        if self._saved is not None:
            os.dup2(self._saved, 2)
            os.close(self._saved)
            self._tmp.seek(0)
            self.said.text = self._tmp.read(4096).decode("utf-8", "replace")
            self._tmp.close()
        return False


def open_frames(path: str | Path, fps: float | None = None, max_frames: int | None = None) -> FrameSource:
    """Open a video file or a folder of images for reading.

    Parameters
    ----------
    path : str or Path
        Video file (any container OpenCV decodes: .avi, .mp4, ...) or folder of images
        (``IMAGE_SUFFIXES``, sorted by name; hidden and non-image files are skipped).
    fps : float, optional
        Frame rate for the timestamps, Hz (overrides the container's).
    max_frames : int, optional
        Read at most this many frames.

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
    return FrameSource(Path(path), fps, max_frames)


_URL = re.compile(r"^(rtsp|rtsps|rtmp|http|https|udp|tcp|srt)://", re.IGNORECASE)


def is_live_source(source) -> bool:
    """True for a camera index (``0``, ``"1"``), a video device (``/dev/video0``) or a stream
    URL (``rtsp://``, ``http://``, ``https://``, ``udp://``, ``tcp://``, ``rtmp://``, ``srt://``)."""
    if isinstance(source, int):
        return True
    text = str(source)
    return text.isdigit() or bool(_URL.match(text)) or text.startswith("/dev/video")


class LiveSource:
    """Frames of a camera or a stream as they arrive, stamped with the capture clock.

    Use :func:`open_live`. For a camera or a stream, ``time_s`` of a frame is the clock
    (``time.monotonic``) when ``cv2.VideoCapture.read`` returned it, minus that of the first
    frame. A video file played through this path (``loop`` passes, frames keep counting) is
    stamped with its media time instead (frame / fps, continued across passes), since it
    decodes faster than it was recorded. ``fps`` is the rate the device announces (or
    ``fps=``). A read that fails is retried ``max_failures`` times (a stream that stalls)
    before the source ends; ``max_frames`` stops after that many frames. ``warnings``
    collects what the caller should print.
    """

    def __init__(self, source, *, loop: int = 1, max_frames: int | None = None, max_failures: int = 25,
                 clock=time.monotonic, fps: float | None = None):
        cv2 = require("cv2", "vision", "reading live video (ceiling track)")
        self.source = source
        self.path = str(source)
        self.loop = int(loop)
        self.max_frames = max_frames
        self.max_failures = int(max_failures)
        self.clock = clock
        self.warnings: list[str] = []
        self.decoded = 0
        if self.loop < 1:
            raise ConfigError(f"--loop must be at least 1, got {loop}")
        if max_frames is not None and int(max_frames) < 1:
            raise ConfigError(f"--max-frames must be at least 1, got {max_frames}")
        self._cap = self._open()
        ok, first = self._cap.read()
        if not ok or first is None:
            self._cap.release()
            raise InputFileError(f"{self.path}: no frame from this camera or stream (not connected, busy, or a "
                                 "format OpenCV cannot decode); expected a camera index, /dev/videoN or a stream URL")
        self._first = _as_bgr(first)
        self._t_first = None
        self.image_size = (int(self._first.shape[1]), int(self._first.shape[0]))
        announced = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if fps is not None:
            self.fps, self.fps_source = float(fps), "argument"
        elif np.isfinite(announced) and 0 < announced < 1e4:
            self.fps, self.fps_source = announced, "device"
        else:
            self.fps, self.fps_source = DEFAULT_FPS, "default"
        self.is_file = not is_live_source(source)
        if not self.is_file:
            self.fps_source = "capture clock"

    def _open(self):
        cv2 = require("cv2", "vision", "reading live video (ceiling track)")
        try:                                        # OpenCV's own warnings would break the one-line error
            cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
        except AttributeError:
            pass
        src = self.source
        if isinstance(src, str) and src.isdigit():
            src = int(src)
        elif isinstance(src, Path):
            src = str(src)
        cap = cv2.VideoCapture(src)
        if not cap.isOpened():
            cap.release()
            raise InputFileError(f"{self.path}: cannot open this camera or stream; expected a camera index, "
                                 "/dev/videoN, a stream URL (rtsp://, http://) or a video file")
        return cap

    def __iter__(self) -> Iterator[Frame]:
        cap, img = self._cap, self._first
        i, failures, passes = 0, 0, 1
        try:
            while True:
                if img is not None:
                    t = i / self.fps if self.is_file else self.clock()
                    if self._t_first is None:
                        self._t_first = t
                    img = _as_bgr(img)
                    if (img.shape[1], img.shape[0]) != self.image_size:
                        yield Frame(i, t - self._t_first, None, f"frame {i}",
                                    f"frame {i} is {img.shape[1]}x{img.shape[0]} px, expected "
                                    f"{self.image_size[0]}x{self.image_size[1]}")
                    else:
                        self.decoded += 1
                        yield Frame(i, t - self._t_first, img, f"frame {i}")
                    i += 1
                    failures = 0
                    if self.max_frames is not None and i >= self.max_frames:
                        return
                ok, img = cap.read()
                if ok and img is not None:
                    continue
                img = None
                if passes < self.loop and self.is_file:
                    cap.release()
                    cap = self._cap = self._open()
                    passes += 1
                    continue
                if self.is_file:
                    return
                failures += 1
                if failures > self.max_failures:
                    self.warnings.append(f"{self.path}: the stream stopped after {i} frames "
                                         f"({self.max_failures} reads in a row failed)")
                    return
                time.sleep(0.01)
        finally:
            cap.release()

    def close(self) -> None:
        self._cap.release()


def open_live(source, *, loop: int = 1, max_frames: int | None = None, fps: float | None = None,
              clock=time.monotonic) -> LiveSource:
    """Open a camera index, a device, a stream URL (or a video file played live) for tracking.

    Parameters
    ----------
    source : int, str or Path
        ``0`` / ``"0"`` (camera index), ``"/dev/video0"``, ``"rtsp://..."``, ``"http://..."``,
        or a video file (played as if it were a camera, ``loop`` times).
    loop : int
        Passes over a video file (ignored for a camera or a stream).
    max_frames : int, optional
        Stop after this many frames (a camera never ends by itself).
    fps : float, optional
        Frame rate of a video file's media time (default: the container's); a camera or a
        stream is stamped by ``clock``.
    clock : callable
        Returns seconds (``time.monotonic``).

    Raises
    ------
    InputFileError
        The camera or stream cannot be opened or gives no first frame.
    ConfigError
        ``loop`` < 1 or ``max_frames`` < 1.
    """
    return LiveSource(source, loop=loop, max_frames=max_frames, fps=fps, clock=clock)
