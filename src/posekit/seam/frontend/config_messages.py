"""One-line messages for configuration errors: the dotted key, what was expected, what arrived, the key's range.

``describe(root, err)`` turns one pydantic error of a model rooted at ``root`` into
``filter.particles: expected >= 1, got 0`` or ``cell.sensors.noise_mm: expected <= 1000, got 1e+308 (allowed
0..1000 mm)``; the range and unit come from the field's constraints and its ``json_schema_extra['unit']``.
"""

from typing import Annotated, get_args, get_origin

import annotated_types
from pydantic import BaseModel
from pydantic.fields import FieldInfo

__all__ = ["describe"]


def _show(value) -> str:
    """An offending value for a message: its ``repr``, at most 80 characters."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _fmt(x) -> str:
    """A bound for messages: ``100000`` (not ``100000.0``), ``1e-09``, ``0.5``."""
    if isinstance(x, float):
        return str(int(x)) if x.is_integer() and abs(x) < 1e16 else f"{x:g}"
    return str(x)


def _item_metadata(annotation) -> list:
    """The constraints of one element of a tuple annotation (``tuple[X, ...] | None`` included)."""
    for arg in get_args(annotation):
        if get_origin(arg) is tuple:
            return _item_metadata(arg)
        if get_origin(arg) is Annotated:
            out = []
            for m in get_args(arg)[1:]:
                out.extend(m.metadata if isinstance(m, FieldInfo) else [m])
            return out
    return []


def _allowed(root, loc) -> tuple[str, bool] | None:
    """``('0..1000 mm', is_integer)`` for the numeric key at ``loc`` of the model ``root``; None for other keys."""
    model, field, item = root, None, False
    for part in loc:
        if isinstance(part, int):
            item = True
        elif model is not None:
            field = model.model_fields.get(str(part))
            if field is None:
                return None
            ann = field.annotation
            model = ann if isinstance(ann, type) and issubclass(ann, BaseModel) else None
        # a further string part is pydantic's name of a union member: the field is known
    if field is None or model is not None:
        return None
    meta = _item_metadata(field.annotation) if item else field.metadata
    lo = hi = None
    lo_open = hi_open = False
    for m in meta:
        if isinstance(m, (annotated_types.Ge, annotated_types.Gt)):
            lo, lo_open = (m.ge, False) if isinstance(m, annotated_types.Ge) else (m.gt, True)
        elif isinstance(m, (annotated_types.Le, annotated_types.Lt)):
            hi, hi_open = (m.le, False) if isinstance(m, annotated_types.Le) else (m.lt, True)
    if lo is None and hi is None:
        return None
    if lo is not None and hi is not None and not lo_open and not hi_open:
        text = f"{_fmt(lo)}..{_fmt(hi)}"
    else:
        parts = [f"{'>' if lo_open else '>='} {_fmt(lo)}"] if lo is not None else []
        parts += [f"{'<' if hi_open else '<='} {_fmt(hi)}"] if hi is not None else []
        text = " and ".join(parts)
    unit = (field.json_schema_extra or {}).get("unit", "") if isinstance(field.json_schema_extra, dict) else ""
    return (f"{text} {unit}" if unit else text), isinstance(lo if lo is not None else hi, int)


def describe(root, err: dict) -> str:
    """One-line description of one pydantic error: ``key: what was expected, got what``.

    A number out of its range also gets the key's whole range and unit,
    ``cell.sensors.range_mm: expected <= 10000, got 1e+308 (allowed 0..10000 mm)``, except an integer
    under its lower bound, whose bound says it all (``filter.particles: expected >= 1, got 0``).
    """
    loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
    kind = err["type"]
    ctx = err.get("ctx") or {}
    got = err.get("input")
    allowed = _allowed(root, err["loc"])
    tail = f" (allowed {allowed[0]})" if allowed else ""
    if kind == "extra_forbidden":
        return f"unknown key '{loc}'"
    if kind == "missing":
        *parent, last = err["loc"]
        if isinstance(last, int) and isinstance(got, (list, tuple)):  # a tuple with too few items
            return f"{'.'.join(str(p) for p in parent)}: too few values (no item {last}), got {_show(list(got))}"
        return f"missing key '{loc}'"
    if kind == "too_long":
        return f"{loc}: expected at most {ctx.get('max_length', '?')} values, got {_show(got)}"
    if kind == "finite_number":
        return f"{loc}: expected a finite number, got {_show(got)}{tail}"
    if kind == "bool_not_number":
        return f"{loc}: expected a number, got the boolean {str(got).lower()}{tail}"
    if kind == "int_parsing_size":  # a float far beyond any integer key's range (1e30)
        return f"{loc}: expected an integer, got {_show(got)}{tail}"
    bounds = {
        "greater_than": ">",
        "greater_than_equal": ">=",
        "less_than": "<",
        "less_than_equal": "<=",
    }
    if kind in bounds:
        limit = next(iter(ctx.values())) if ctx else "?"
        if kind.startswith("greater") and allowed and allowed[1]:
            tail = ""  # an integer under its lower bound (a count, a seed): the bound says it all
        return f"{loc}: expected {bounds[kind]} {limit}, got {_show(got)}{tail}"
    if kind == "literal_error":
        return f"{loc}: expected one of {ctx.get('expected', '?')}, got {_show(got)}"
    if kind == "value_error":
        return f"{loc}: {ctx.get('error', err['msg'])}" if loc != "(top level)" else str(
            ctx.get("error", err["msg"])
        )
    if kind in ("model_type", "dict_type"):
        return f"{loc}: expected a mapping, got {type(got).__name__}"
    if kind.endswith(("_type", "_parsing", "_from_float")):
        return f"{loc}: {err['msg'][0].lower() + err['msg'][1:]} (got {_show(got)}){tail}"
    return f"{loc}: {err['msg']}{tail}"
