"""Result files shared by every system: CSV tables, JSON, PNG figures and ``report.html``.

A study, simulation or experiment writes its tables as CSV, its figures as PNG (matplotlib with
the Agg backend, so it runs on a machine without a screen) and one self-contained
``report.html`` that embeds each figure (base64) beside a link to its file. The systems keep
what their reports say; this module keeps how the files are written.
"""

import base64
import csv
import html
import json
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

__all__ = [
    "pyplot",
    "save_figure",
    "write_csv",
    "to_jsonable",
    "write_json",
    "html_table",
    "html_figure",
    "write_html",
]

_STYLE = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
          "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
          "text-align:right}th{background:#eee}img{max-width:100%}figure{margin:1.5em 0}"
          "pre{background:#f6f6f6;padding:.5em;overflow-x:auto}")


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (imported on first use: plotting is optional)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_figure(fig, path, *, dpi: int = 110) -> Path:
    """Lay out ``fig``, write it as PNG to ``path``, close it and return the path."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)
    return Path(path)


def write_csv(path, rows: Iterable[Mapping], columns: Sequence[str]) -> Path:
    """Write dict rows with exactly ``columns`` (floats with 6 significant digits, NaN as 'nan';
    a key a row lacks is an empty cell)."""
    path = Path(path)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in rows:
            w.writerow([f"{v:.6g}" if isinstance(v, float) else v
                        for v in (row.get(c, "") for c in columns)])
    return path


def to_jsonable(obj):
    """``obj`` with NumPy arrays and scalars turned into Python ones and NaN/inf into None."""
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON (see :func:`to_jsonable`)."""
    path = Path(path)
    path.write_text(json.dumps(to_jsonable(data), indent=2) + "\n", encoding="utf-8")
    return path


def _default_cell(value, column: str) -> str:
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return "–" if math.isnan(v) else f"{v:.4g}"
    return html.escape(str(value))


def html_table(rows: Iterable[Mapping], columns: Sequence[str], headers: Sequence[str] | None = None,
               cell: Callable[[object, str], str] | None = None) -> str:
    """An HTML table of dict rows.

    Parameters
    ----------
    rows : iterable of mapping
        One mapping per row; a missing key is an empty cell.
    columns : sequence of str
        The keys to show, in order.
    headers : sequence of str, optional
        Column headings (default: ``columns``).
    cell : callable ``(value, column) -> str``, optional
        Formats one cell as HTML (default: floats with 4 significant digits, NaN as '–',
        anything else escaped).
    """
    cell = cell or _default_cell
    head = "".join(f"<th>{html.escape(h)}</th>" for h in (headers or columns))
    body = "".join("<tr>" + "".join(f"<td>{cell(r.get(c, ''), c)}</td>" for c in columns) + "</tr>"
                   for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def html_figure(path, caption: str) -> str:
    """A ``<figure>`` that embeds the PNG at ``path`` (base64) and links the file by name."""
    path = Path(path)
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    name = html.escape(path.name)
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{name}">'
            f'<figcaption>{html.escape(caption)} (<a href="{name}">{name}</a>)</figcaption></figure>')


def write_html(out, title: str, intro: str, sections: Iterable[tuple[str, str]]) -> Path:
    """Write ``out/report.html``: a title, an intro (HTML) and ``(heading, HTML)`` sections."""
    body = "".join(f"<h2>{html.escape(h)}</h2>{content}" for h, content in sections)
    text = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1>{intro}{body}</body></html>")
    path = Path(out) / "report.html"
    path.write_text(text, encoding="utf-8")
    return path
