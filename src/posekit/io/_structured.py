"""YAML and JSON documents with the limits every reader shares: size and encoding (through
:func:`~posekit.io.read_text`), nesting depth, the length of integer literals, finite numbers.

A document nested thousands deep would exhaust Python's recursion inside the parser, and a
4,300-digit integer trips Python's int-conversion limit; both are one-line errors here.

YAML is read by value, not by tag: a document holds mappings, lists, text, numbers, booleans and
nulls (what JSON holds). The core tags that only say which of those a value is (``!!str``,
``!!int``, ``!!float``, ``!!bool``, ``!!null``, ``!!seq``, ``!!map``) are read as the value they
make, and a value they cannot make (``!!int 1.5``, ``!!float 'x'``) is a one-line error naming the
line; every other tag (``!!binary``, ``!!timestamp``, ``!!set``, ``!!omap``, ``!!pairs``, custom
``!tags``) is refused in one line. An unquoted date (``2024-01-01``) stays text. The configuration
models then validate the values like any others.
"""

import binascii
import json
import math
import re

import yaml

from posekit.errors import InputFileError

from ._files import read_text
from ._limits import get_limits, quote

__all__ = ["check_document", "load_json", "load_yaml", "parse_json", "parse_yaml"]

_LONG_INT = re.compile(r"(?<![\w.])[-+]?\d{%d,}(?![\w.])")


def check_document(data, source: str, *, error=InputFileError, max_nodes: int | None = None) -> None:
    """Raise ``error`` if ``data`` nests deeper than the limit or holds a non-finite number or an
    integer longer than the limit (walks the tree iteratively); with ``max_nodes``, also if the tree
    holds more values than that (YAML aliases expanding a small text into a huge tree)."""
    lim = get_limits()
    stack = [(data, 1, "")]
    seen = 0
    while stack:
        node, depth, where = stack.pop()
        seen += 1
        if max_nodes is not None and seen > max_nodes:
            raise error(f"{source}: expands to more than {max_nodes:,} values (YAML aliases); expected a plain "
                        "document")
        if isinstance(node, dict):
            items = node.items()
        elif isinstance(node, (list, tuple)):
            items = enumerate(node)
        else:
            if isinstance(node, bool):
                continue
            if isinstance(node, int) and abs(node) >= 10**lim.number_digits:
                raise error(f"{source}: {where or 'value'}: an integer of more than {lim.number_digits} digits; "
                            "expected a count, seed or size of sensible magnitude")
            if isinstance(node, float) and not math.isfinite(node):
                raise error(f"{source}: {where or 'value'}: expected a finite number, got {node!r}")
            continue
        if depth > lim.nesting:
            raise error(f"{source}: nested more than {lim.nesting} levels deep; expected a flat configuration")
        for key, value in items:
            stack.append((value, depth + 1, f"{where}.{key}" if where else str(key)))


def _guard_digits(text: str, source: str, error) -> None:
    """Reject integer literals longer than the limit before a parser converts them."""
    lim = get_limits()
    m = re.compile(_LONG_INT.pattern % (lim.number_digits + 1)).search(text)
    if m:
        line = text.count("\n", 0, m.start()) + 1
        raise error(f"{source}: line {line}: a number of {len(m.group().lstrip('+-'))} digits "
                    f"({quote(m.group(), 24)}); expected at most {lim.number_digits} digits")


_TAG = "tag:yaml.org,2002:"
#: Tags that only name a JSON kind of value; anything else is refused.
_PLAIN_TAGS = {_TAG + t for t in ("str", "int", "float", "bool", "null", "seq", "map", "merge", "value")}
_Base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _TagError(yaml.YAMLError):
    """A tag posekit does not read, or a value its tag cannot make."""

    def __init__(self, message: str, mark):
        super().__init__(message)
        self.message = message
        self.problem_mark = mark


class _Loader(_Base):
    """The safe loader (libyaml's when available), reading values by kind, not by tag."""

    yaml_implicit_resolvers = {k: [(tag, rx) for tag, rx in v if tag != _TAG + "timestamp"]
                               for k, v in _Base.yaml_implicit_resolvers.items()}

    def construct_object(self, node, deep=False):
        tag = node.tag
        if tag not in _PLAIN_TAGS:
            shown = tag.replace(_TAG, "!!")
            raise _TagError(f"the YAML tag {shown[:40]!r} is not read (posekit reads text, numbers, booleans, "
                            "lists and mappings); write the value without it", node.start_mark)
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, TypeError, KeyError, OverflowError, binascii.Error) as exc:
            if isinstance(exc, yaml.YAMLError):
                raise
            shown = tag.replace(_TAG, "!!")
            value = node.value if isinstance(node.value, str) else "..."
            raise _TagError(f"{shown} {quote(value, 24)} is not a valid {shown[2:]}", node.start_mark) from None


def parse_yaml(text: str, source: str, *, error=InputFileError):
    """Parse YAML ``text`` (safely, by value: see the module) under the shared limits; ``source``
    names it in messages."""
    _guard_digits(text, source, error)
    try:
        data = yaml.load(text, Loader=_Loader)  # noqa: S506 (a SafeLoader subclass)
    except _TagError as exc:
        mark = exc.problem_mark
        at = f"line {mark.line + 1}: " if mark is not None else ""
        raise error(f"{source}: {at}{exc.message}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise error(f"{source}: not valid YAML{at}") from None
    except RecursionError:
        raise error(f"{source}: nested more than {get_limits().nesting} levels deep; "
                    "expected a flat configuration") from None
    # Without aliases every value takes at least one character of the text: a larger tree is an
    # alias bomb ("billion laughs"), refused before anything walks or validates it.
    check_document(data, source, error=error, max_nodes=2 * len(text) + 64)
    return data


def parse_json(text: str, source: str, *, error=InputFileError):
    """``json.loads`` of ``text`` under the shared limits (NaN/Infinity rejected, naming the key)."""
    _guard_digits(text, source, error)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{source}: not valid JSON (line {exc.lineno} column {exc.colno}: {exc.msg})") from None
    except ValueError as exc:  # e.g. Python's int-conversion limit
        raise error(f"{source}: {str(exc)[:80]}; expected numbers of sensible size") from None
    except RecursionError:
        raise error(f"{source}: nested more than {get_limits().nesting} levels deep; "
                    "expected a flat document") from None
    check_document(data, source, error=error)
    return data


def load_yaml(path, *, expected: str, error=InputFileError, limit: int | None = None):
    """Read and parse a YAML file under the shared limits (``limit``: the reader's own, smaller
    size limit in bytes, checked before anything is parsed)."""
    return parse_yaml(read_text(path, expected=expected, error=error, limit=limit), str(path), error=error)


def load_json(path, *, expected: str, error=InputFileError, limit: int | None = None):
    """Read and parse a JSON file under the shared limits (``limit`` as in :func:`load_yaml`)."""
    return parse_json(read_text(path, expected=expected, error=error, limit=limit), str(path), error=error)
