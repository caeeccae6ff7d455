"""Images and video frames with their size checked from the header before decoding.

A PNG whose header claims 65,535 × 65,535 pixels, or a valid 30,000 × 30,000 PNG of 2.6 MB,
would make OpenCV allocate gigabytes; the width and height are read from the header first
(Pillow opens an image lazily, without decoding it) and checked against the pixel limit.
OpenCV's own log lines are silenced while reading, so nothing leaks before posekit's one-line
error.
"""

import struct
import warnings
from pathlib import Path

import numpy as np

from posekit.errors import InputFileError

from .._extras import require
from ._files import check_input_file
from ._limits import get_limits

__all__ = ["check_frame_size", "image_size", "read_image"]


def check_frame_size(width: int, height: int, source: str, *, error=InputFileError) -> None:
    """Raise ``error`` if a ``width × height`` frame exceeds the pixel limit."""
    limit = get_limits().image_pixels
    if int(width) * int(height) > limit:
        raise error(f"{source}: {int(width)} x {int(height)} pixels, above the {limit / 1e6:g} MP image limit "
                    "(raise it with --max-image-mp or resize the images)")


def image_size(path, *, error=InputFileError) -> tuple[int, int] | None:
    """``(width, height)`` from an image file's header without decoding it, or None when the
    format is one Pillow does not know (OpenCV may still read it)."""
    from PIL import Image

    path = Path(path)
    try:
        with path.open("rb") as fh:
            head = fh.read(24)
    except OSError:
        return None
    if len(head) >= 24 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":  # the size: first chunk
        return struct.unpack(">II", head[16:24])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            with Image.open(path) as im:
                return int(im.size[0]), int(im.size[1])
        except Image.DecompressionBombError as exc:
            raise error(f"{path}: image too large ({str(exc)[:60]}); expected at most "
                        f"{get_limits().image_pixels / 1e6:g} MP") from None
        except (OSError, ValueError, SyntaxError):  # unknown or broken header
            return None


def _silence_opencv():
    cv2 = require("cv2", "vision", "reading images")

    try:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    except AttributeError:  # an OpenCV build without the logging module
        pass
    return cv2


def read_image(path, flags=None, *, error=InputFileError) -> np.ndarray | None:
    """Decode an image file with OpenCV after the header's size check.

    Returns None when the file exists but cannot be decoded (the caller decides whether that
    is an error or a ``lost`` frame); raises ``error`` for a missing, unreadable or oversized
    file.
    """
    path = Path(path)
    check_input_file(path, expected="an image file", error=error)
    size = image_size(path, error=error)
    if size is not None:
        check_frame_size(*size, str(path), error=error)
    cv2 = _silence_opencv()
    try:
        img = cv2.imread(str(path), cv2.IMREAD_COLOR if flags is None else flags)
    except cv2.error:
        return None
    if img is not None:
        check_frame_size(img.shape[1], img.shape[0], str(path), error=error)
    return img
