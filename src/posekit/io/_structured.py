"""YAML and JSON documents with the limits every reader shares: size and encoding (through
:func:`~posekit.io.read_text`), nesting depth, the length of integer literals, finite numbers.

A document nested thousands deep would exhaust Python's recursion inside the parser, and a
4,300-digit integer trips Python's int-conversion limit; both are one-line errors here.
"""

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


def parse_yaml(text: str, source: str, *, error=InputFileError):
    """``yaml.safe_load`` of ``text`` under the shared limits; ``source`` names it in messages."""
    _guard_digits(text, source, error)
    try:
        data = yaml.safe_load(text)
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


def load_yaml(path, *, expected: str, error=InputFileError):
    """Read and parse a YAML file under the shared limits."""
    return parse_yaml(read_text(path, expected=expected, error=error), str(path), error=error)


def load_json(path, *, expected: str, error=InputFileError):
    """Read and parse a JSON file under the shared limits."""
    return parse_json(read_text(path, expected=expected, error=error), str(path), error=error)
