"""HTML building blocks of the report: escaping, numbers, tables, notes, the jinja2
environment (autoescape on) and the stylesheet (templates/report.css)."""
from __future__ import annotations

import html
import math
import re
from functools import lru_cache

import numpy as np
from markupsafe import Markup

CHANNELS = ("CN", "Cm", "CY", "Cn", "Cl")


@lru_cache(maxsize=1)
def env():
    """The jinja2 environment of the report templates (package data, autoescape on)."""
    import jinja2

    return jinja2.Environment(loader=jinja2.PackageLoader("aerosid.report", "templates"), autoescape=True,
                              undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                              keep_trailing_newline=True)


def render(template: str, **context) -> str:
    """A template rendered with escaping on; pass HTML built here as ``html_safe(...)``."""
    return env().get_template(template).render(**context)


def html_safe(fragment: str) -> Markup:
    """A fragment built by the helpers of this package (which escape their inputs)."""
    return Markup(fragment)


@lru_cache(maxsize=1)
def css() -> str:
    from importlib.resources import files

    return files("aerosid.report").joinpath("templates", "report.css").read_text(encoding="utf-8")


# --------------------------------------------------------------------------- HTML helpers
class _H(str):
    """Text that is already HTML (never escaped again)."""


def _e(x) -> str:
    return html.escape("" if x is None else str(x), quote=True)


def _finite(x) -> bool:
    try:
        return x is not None and not isinstance(x, bool) and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def _num(x, fmt: str = ".4g") -> str:
    return format(float(x), fmt) if _finite(x) else "—"


def _cell(v) -> str:
    if isinstance(v, _H):
        return v
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return _e(_num(v))
    if isinstance(v, (int, np.integer)):
        return _e(str(int(v)))
    return _e(v)


_NUMERIC = re.compile(r"^(?:[-+]?(?:\d[\d,]*\.?\d*|\.\d+)(?:e[-+]?\d+)?(?: %)?|\[.*\]|[×x][\d.]+.*)$")


def _align(v) -> str:
    """' class="n"' for a number (right-aligned), ' class="c"' for a dash (centred), '' for text."""
    if isinstance(v, (_H, bool, np.bool_)):
        return ""
    if isinstance(v, (int, float, np.integer, np.floating)):
        return ' class="n"' if _finite(v) else ' class="c"'
    text = str(v).strip() if isinstance(v, str) else ""
    if text in ("—", "nan"):
        return ' class="c"'
    return ' class="n"' if text and _NUMERIC.match(text) else ""


def _table(headers, rows, *, id: str | None = None, cls: str = "", caption: str | None = None) -> str:
    """An HTML table; numbers right-aligned, text left-aligned (a header follows its
    column).  Wide tables scroll inside their own box, not the page."""
    plain = [r for r in rows if not isinstance(r, _H)]
    num_col = [any(j < len(r) and _align(r[j]) == ' class="n"' for r in plain) for j in range(len(headers))]
    out = [f'<div class="scroll"><table{f" id={_q(id)}" if id else ""}{f" class={_q(cls)}" if cls else ""}>']
    if caption:
        out.append(f"<caption>{_e(caption)}</caption>")
    out.append("<thead><tr>" + "".join(f'<th{_align(1.0) if num_col[j] else ""}>{_cell(h)}</th>'
                                       for j, h in enumerate(headers)) + "</tr></thead><tbody>")
    for row in rows:
        if isinstance(row, _H):  # a complete pre-built <tr>
            out.append(row)
        else:
            out.append("<tr>" + "".join(f"<td{_align(c)}>{_cell(c)}</td>" for c in row) + "</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


def _q(s: str) -> str:
    return '"' + _e(s) + '"'


def _p(text: str, cls: str = "") -> str:
    return f'<p{f" class={_q(cls)}" if cls else ""}>{_e(text)}</p>'


def _note(text: str) -> str:
    return _p(text, "note")


def _heat(ratio) -> str:
    """Background colour of a residual-RMS ratio cell: white at 1, red above, blue below."""
    if not _finite(ratio):
        return "#f4f4f4"
    r = float(ratio)
    if r >= 1:
        t = min((r - 1) / 1.5, 1.0)
        return f"rgb(255,{int(255 - 140 * t)},{int(255 - 140 * t)})"
    t = min((1 - r) / 0.8, 1.0)
    return f"rgb({int(255 - 60 * t)},{int(255 - 30 * t)},255)"


def _span(a, b) -> str:
    if not (_finite(a) and _finite(b)):
        return "—"
    return f"{round(float(a), 2) + 0.0:.2f}–{round(float(b), 2) + 0.0:.2f} s"


def _pct(x, fmt: str) -> str:
    return format(100 * float(x), fmt) + " %" if _finite(x) else "—"


