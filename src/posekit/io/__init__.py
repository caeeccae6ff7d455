"""Safe input and output shared by every system.

Every reader goes through this layer: existence, permissions, size (declared array sizes and
image dimensions included, checked before anything is allocated), encoding (UTF-8 with or
without a byte-order mark, the same rule everywhere), nesting depth and number size of YAML and
JSON, and a suffix/content mismatch named as such — each failure one line,
``FILE: what was wrong; what was expected``. Every writer of a run's folder or a single file
goes through :func:`staged_folder` / :func:`atomic_file` (a ``--jsonl`` stream through
:func:`open_stream`), so nothing is ever half-written, no special file (a device, a named pipe)
is ever replaced, and no file posekit did not write is ever deleted without ``--overwrite``.
The limits are in :class:`Limits` (``--max-input-mb`` / ``--max-image-mp`` raise them).
"""

from .._numbers import parse_int, parse_number
from ._arrays import load_npy, load_npz_member, npz_members
from ._files import check_input_file, read_bytes, read_text, sniff
from ._images import check_frame_size, image_size, read_image
from ._limits import Limits, check_rows, get_limits, quote, set_limits
from ._numbers import number_array
from ._output import MARKER, atomic_file, check_out_folder, open_stream, staged_folder, write_error, write_text_atomic
from ._structured import check_document, load_json, load_yaml, parse_json, parse_yaml

__all__ = [
    # limits and messages
    "Limits",
    "get_limits",
    "set_limits",
    "quote",
    "check_rows",
    # files, text, structured documents
    "check_input_file",
    "read_bytes",
    "read_text",
    "sniff",
    "load_yaml",
    "load_json",
    "parse_yaml",
    "parse_json",
    "check_document",
    # numbers by value
    "parse_number",
    "parse_int",
    "number_array",
    # arrays
    "load_npy",
    "load_npz_member",
    "npz_members",
    # images
    "image_size",
    "read_image",
    "check_frame_size",
    # output
    "staged_folder",
    "atomic_file",
    "check_out_folder",
    "write_text_atomic",
    "open_stream",
    "write_error",
    "MARKER",
]
