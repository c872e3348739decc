"""HTML building blocks of the report: escaping, tables, folded blocks, and rendering metric value trees."""
from __future__ import annotations

import base64
import datetime as _dt
import html
import json
import math
import os
import re
from typing import Any, Iterable

import numpy as np

IMAGE_TYPES = {".png": "image/png", ".svg": "image/svg+xml"}
MAX_INLINE_ENTRIES = 12      # dicts/lists longer than this are folded into a <details> element
MAX_ROWS_SHOWN = 2000        # rows of a folded table actually written

CSS = """
*{box-sizing:border-box}
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0 auto;max-width:1880px;padding:.4em 1.5em;
color:#222;line-height:1.35;overflow-wrap:break-word}
h1{font-size:1.35em;margin:.2em 0;border-bottom:2px solid #446;padding-bottom:.15em}
h2{border-bottom:1px solid #aab;margin-top:2em}#summary h2{display:none}
h3{margin-top:1.5em}code,pre{font-family:Menlo,Consolas,monospace;font-size:.9em}
pre{background:#f5f5f8;padding:.6em;overflow-x:auto;max-height:30em}
.tscroll{max-width:100%;overflow-x:auto;margin:.5em 0 1em 0}
table{border-collapse:collapse;font-size:.92em}
th,td{border:1px solid #ccd;padding:.2em .6em;text-align:left;vertical-align:top}
th{background:#eef}td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr:nth-child(even) td{background:#fafafd}
.note{background:#fff8e0;border-left:4px solid #e0b000;padding:.5em 1em;margin:1em 0}
.bad{color:#b00}.muted{color:#777}#summary .note{padding:.25em .8em;margin:.35em 0;font-size:.88em}
#summary p.bad{margin:.3em 0;font-size:.9em}
.figs{display:flex;flex-wrap:wrap;gap:1em;align-items:flex-start}
figure{margin:0;border:1px solid #dde;padding:.5em;max-width:100%;min-width:0;background:#fff}
figure img{max-width:100%;max-height:720px;height:auto;display:block}
figure a.full{display:block;cursor:zoom-in}
figcaption{font-size:.9em;margin-top:.3em;overflow-wrap:anywhere}figcaption pre{max-height:12em;margin:.3em 0 0 0}
details{margin:.3em 0 1em 0}summary{cursor:pointer;color:#335}
nav{font-size:.9em;margin:.2em 0}nav h2{display:none}nav ul{display:inline;padding:0;margin:0}
nav li{display:inline-block;margin-right:1.1em}
.runline{font-size:.88em;margin:.3em 0 .5em 0;color:#333}.small{font-size:.8em;margin:.2em 0}
.problem{display:flex;flex-wrap:wrap;gap:.6em 1.2em;align-items:flex-start;border-top:1px solid #dde;padding:.4em 0}
.ptable{flex:0 1 auto;min-width:0;max-width:100%}.ptable h3{margin:.1em 0 .3em 0;font-size:1em}
.ptable .tscroll{margin:.2em 0}
.pfigs{display:flex;flex-wrap:wrap;gap:.6em;flex:1 1 auto;justify-content:flex-start;min-width:0;max-width:100%}
figure.thumb{padding:.2em;flex:0 1 auto;min-width:0}figure.thumb img{max-height:720px;max-width:100%}
figure.thumb figcaption{font-size:.8em;margin-top:.1em}
figure.pointer{border-style:dashed;color:#555}
table.summary-table{font-size:.86em;margin:0}table.summary-table td,table.summary-table th{padding:.12em .45em}
td.best{font-weight:bold;color:#064;background:#e6f5ea !important}
@media (max-width:700px){body{padding:.3em .6em}.pfigs{flex-basis:100%}figure{padding:.25em}}
"""


def esc(value: Any) -> str:
    """``str(value)`` escaped for HTML text and attribute values."""
    return html.escape(str(value), quote=True)


def format_value(v: Any) -> str:
    """Text of a scalar cell: floats with 6 significant digits, the rest as str."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else str(v)
    return str(v)


def is_scalar(v: Any) -> bool:
    """True for None, bool, numbers, strings and 0-d arrays."""
    return v is None or isinstance(v, (bool, int, float, str, np.generic)) or \
        (isinstance(v, np.ndarray) and v.ndim == 0)


def _cell(v: Any) -> str:
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v.item()
    numeric = isinstance(v, (int, float, np.number)) and not isinstance(v, bool)
    return f'<td class="num">{esc(format_value(v))}</td>' if numeric else f"<td>{esc(format_value(v))}</td>"


def table(header: list[str], rows: Iterable[list[Any]], cls: str = "", raw_cols: tuple[int, ...] = ()) -> str:
    """An HTML table; cells are escaped scalars, except columns in ``raw_cols`` (already HTML)."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = []
    for r in rows:
        cells = "".join(f"<td>{c}</td>" if i in raw_cols else _cell(c) for i, c in enumerate(r))
        body.append(f"<tr>{cells}</tr>")
    attr = f' class="{cls}"' if cls else ""
    return scroll_box(f"<table{attr}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>")


def scroll_box(inner: str) -> str:
    """``inner`` (a table) in its own box that scrolls sideways when it is wider than the page."""
    return f'<div class="tscroll">{inner}</div>'


def folded(summary: str, inner: str, open_: bool = False) -> str:
    """``inner`` HTML inside a <details> element titled ``summary`` (text)."""
    return f"<details{' open' if open_ else ''}><summary>{esc(summary)}</summary>{inner}</details>"


def anchor(text: str) -> str:
    """An id-safe slug of ``text``."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "x"


def human_size(n: int) -> str:
    """Bytes as ``12 B`` / ``3.4 KiB`` / ``1.2 MiB`` / ``5.0 GiB``."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)


def json_pre(obj: Any) -> str:
    """``obj`` as indented JSON in a <pre> block."""
    return f"<pre>{esc(json.dumps(obj, indent=2, sort_keys=False, default=str))}</pre>"


def data_uri(path: str) -> str:
    """The image file ``path`` (PNG or SVG) as a base64 data URI."""
    mime = IMAGE_TYPES[os.path.splitext(path)[1].lower()]
    with open(path, "rb") as fh:
        return f"data:{mime};base64,{base64.b64encode(fh.read()).decode('ascii')}"


def when(t: float | None) -> str:
    """A UNIX time as ``YYYY-MM-DD HH:MM:SS UTC`` ("?" when unknown)."""
    if not t:
        return "?"
    return _dt.datetime.fromtimestamp(t, _dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


# ---------------------------------------------------------------------------------------------
# rendering a metric value tree
# ---------------------------------------------------------------------------------------------
def render_value(v: Any) -> str:
    """HTML for a metric value: scalars as text, dicts as tables (nested or matrix), big ones folded."""
    if is_scalar(v):
        return esc(format_value(v.item() if isinstance(v, np.ndarray) else v))
    if isinstance(v, np.ndarray):
        return _render_array(v)
    if isinstance(v, (list, tuple)):
        return _render_list(list(v))
    if isinstance(v, dict):
        return _render_dict(v)
    return esc(repr(v))


def _render_array(a: np.ndarray) -> str:
    desc = f"array {a.dtype} shape {tuple(a.shape)}"
    if a.size <= MAX_INLINE_ENTRIES and a.ndim == 1:
        return esc(", ".join(format_value(x) for x in a.tolist())) + f' <span class="muted">({esc(desc)})</span>'
    if a.size and np.issubdtype(a.dtype, np.number):
        finite = a[np.isfinite(a)] if np.issubdtype(a.dtype, np.floating) else a
        if finite.size:
            desc += (f": min {format_value(float(finite.min()))}, mean {format_value(float(finite.mean()))}, "
                     f"max {format_value(float(finite.max()))}")
    if a.ndim == 2 and a.size <= 400:
        return folded(desc, table([""] + [str(j) for j in range(a.shape[1])],
                                  [[i] + row for i, row in enumerate(a.tolist())]))
    return esc(desc)


def _render_list(v: list) -> str:
    if all(is_scalar(x) for x in v):
        text = ", ".join(format_value(x) for x in v)
        if len(v) <= MAX_INLINE_ENTRIES and len(text) <= 200:
            return esc(text) if v else '<span class="muted">(empty)</span>'
        rows = [[i, x] for i, x in enumerate(v[:MAX_ROWS_SHOWN])]
        return folded(f"list of {len(v)} values", table(["#", "value"], rows) + _more(len(v)))
    rows = [[i, render_value(x)] for i, x in enumerate(v[:MAX_ROWS_SHOWN])]
    inner = table(["#", "value"], rows, raw_cols=(1,)) + _more(len(v))
    return inner if len(v) <= MAX_INLINE_ENTRIES else folded(f"list of {len(v)} entries", inner)


def _more(n: int) -> str:
    return f'<p class="muted">... {n - MAX_ROWS_SHOWN} more not shown</p>' if n > MAX_ROWS_SHOWN else ""


def _render_dict(d: dict) -> str:
    items = list(d.items())
    if not items:
        return '<span class="muted">(empty)</span>'
    if all(is_scalar(x) for _, x in items):
        inner = table(["key", "value"], [[k, x] for k, x in items[:MAX_ROWS_SHOWN]]) + _more(len(items))
    elif all(isinstance(x, dict) and x and all(is_scalar(y) for y in x.values()) for _, x in items):
        cols = list(dict.fromkeys(c for _, x in items for c in x))
        if len(cols) <= 16:     # a matrix: rows = outer keys, columns = inner keys
            rows = [[k] + [x.get(c, "") for c in cols] for k, x in items[:MAX_ROWS_SHOWN]]
            inner = table([""] + cols, rows) + _more(len(items))
        else:
            inner = table(["key", "value"], [[k, _render_dict(x)] for k, x in items[:MAX_ROWS_SHOWN]],
                          raw_cols=(1,)) + _more(len(items))
    else:
        inner = table(["key", "value"], [[k, render_value(x)] for k, x in items[:MAX_ROWS_SHOWN]],
                      raw_cols=(1,)) + _more(len(items))
    return inner if len(items) <= MAX_INLINE_ENTRIES else folded(f"{len(items)} entries", inner)
