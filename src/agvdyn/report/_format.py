"""Numbers, units and small tables as HTML, formatted for people: significant digits, thousands
separators, powers of ten instead of ``e-05``, units that never wrap, ``yes``/``no``."""
from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = ["esc", "num", "count", "percent", "unit", "yes_no", "nbytes", "plain", "value_std_ci", "table",
           "figure_png", "img"]

#: Below this magnitude (or from ``10**LARGE`` on) numbers are written as a power of ten.
SMALL = 1e-3
LARGE = 5
#: Resolution of the embedded figures (a 12 in wide figure is 1,200 px, the page's width).
DPI = 100
_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def esc(x: Any) -> str:
    """Any value as escaped HTML text."""
    return html.escape(str(x))


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _power(x: float, digits: int) -> str:
    mantissa, exponent = f"{x:.{max(digits - 1, 0)}e}".split("e")
    return f"{mantissa}&#8239;&times;&#8239;10<sup>{int(exponent)}</sup>"


def num(x: Any, digits: int = 4, *, decimals: int | None = None, signed: bool = False, trim: bool = False) -> str:
    """``x`` with ``digits`` significant digits (or a fixed number of ``decimals``) as HTML:
    ``842.07``, ``12,950``, ``3.2 x 10^-5``; a dash for None and NaN. ``trim``: no trailing
    zeros after the decimal point (``0.02`` rather than ``0.0200``)."""
    if not _finite(x):
        return "&ndash;" if x is None or isinstance(x, float) else esc(x)
    x = float(x)
    sign = "+" if signed and x > 0 else ""
    if x != 0 and (abs(x) < SMALL or abs(x) >= 10**LARGE) and decimals is None:
        return sign + _power(x, digits)
    if decimals is None:
        magnitude = math.floor(math.log10(abs(x))) if x != 0 else 0
        decimals = digits - 1 - magnitude
        if decimals < 0:  # round to the significant digits: 739,508 -> 740,000 with 2
            x = round(x, decimals)
            decimals = 0
    text = f"{x:,.{decimals}f}"
    if trim and "." in text:
        text = text.rstrip("0").rstrip(".")
    return sign + text.replace("-", "&minus;")


def count(n: Any) -> str:
    """An integer count with thousands separators (``10,500``)."""
    if n is None or (isinstance(n, float) and not math.isfinite(n)):
        return "&ndash;"
    return f"{int(n):,}"


def percent(x: Any, digits: int = 2, *, signed: bool = False) -> str:
    """A fraction already in percent, ``+1.6&nbsp;%``."""
    if not _finite(x):
        return "&ndash;"
    return f"{num(x, digits, signed=signed)}&nbsp;%"


def unit(text: str) -> str:
    """A unit as HTML that does not wrap: ``kg m^2`` -> ``kg&nbsp;m²``."""
    out = esc(text).replace("^2", "\u00b2").replace("^-1", "\u207b\u00b9").replace(" ", "&nbsp;")
    return f'<span class="unit">{out}</span>'


def yes_no(flag: Any) -> str:
    """``yes``, ``no``, or a dash for None."""
    return "&ndash;" if flag is None else ("yes" if flag else "no")


def nbytes(n: int) -> str:
    """A file size: ``1.2&nbsp;MB``; bytes with separators below 10 kB."""
    if n < 10_000:
        return f"{n:,}&nbsp;bytes"
    for size, name in ((1e9, "GB"), (1e6, "MB"), (1e3, "kB")):
        if n >= size:
            return f"{num(n / size, 3)}&nbsp;{name}"
    return f"{n:,}&nbsp;bytes"


def plain(x: Any) -> str:
    """A settings value: booleans yes/no, None as ``none``, floats with 4 digits, lists joined."""
    if x is None:
        return "none"
    if isinstance(x, bool):
        return yes_no(x)
    if isinstance(x, float):
        if math.isinf(x):
            return "&infin;" if x > 0 else "&minus;&infin;"
        return num(x, 4) if abs(x) >= 1e4 or abs(x) < SMALL else f"{x:g}"
    if isinstance(x, int):
        return f"{x:,}" if abs(x) >= 10_000 else str(x)
    if isinstance(x, (list, tuple)):
        return ", ".join(plain(v) for v in x) or "none"
    if isinstance(x, Mapping):
        return ", ".join(f"{esc(k)}: {plain(v)}" for k, v in x.items()) or "none"
    return esc(x)


def value_std_ci(value: float, std: float | None, ci: Sequence[float] | None) -> tuple[str, str, str]:
    """Value, std and 95 % interval written to the same last digit: the second significant digit of
    the std, but with 3 to 6 significant digits of the value."""
    if std is None or not _finite(std) or std <= 0:
        return num(value, 5), "&ndash;", "&ndash;"
    magnitude = math.floor(math.log10(abs(value))) if value else 0
    decimals = 1 - math.floor(math.log10(std))
    decimals = min(max(decimals, 2 - magnitude), 5 - magnitude)
    decimals = max(decimals, 0)
    ci_text = "&ndash;" if ci is None else f"{num(ci[0], decimals=decimals)} &hellip; {num(ci[1], decimals=decimals)}"
    return num(value, decimals=decimals), num(std, 2), ci_text


def table(header: Sequence[str] | None, rows: Iterable[Sequence[str]], *, align: str = "l",
          row_classes: Sequence[str] | None = None) -> str:
    """An HTML table from cells that are already HTML. ``align``: one letter per column, ``l`` (text)
    or ``r`` (numbers); columns beyond it are right-aligned. ``header`` None: no header row."""
    def cls(i: int) -> str:
        return " class=l" if i < len(align) and align[i] == "l" else ""

    head = "" if header is None else (
        "<thead><tr>" + "".join(f"<th{cls(i)}>{h}</th>" for i, h in enumerate(header)) + "</tr></thead>")
    body = []
    for k, row in enumerate(rows):
        rc = f' class="{row_classes[k]}"' if row_classes and row_classes[k] else ""
        cells = "".join(f"<td{cls(i)}>{c}</td>" for i, c in enumerate(row))
        body.append(f"<tr{rc}>{cells}</tr>")
    return f"<table>{head}<tbody>{''.join(body)}</tbody></table>"


def figure_png(fig, dpi: int = DPI) -> str:
    """A figure as base64-encoded PNG."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, facecolor="white")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def img(fig, alt: str, cls: str = "") -> str:
    """A figure embedded as ``<figure>`` with its caption ``alt``."""
    return (f'<figure class="{cls}"><img alt="{esc(alt)}" src="data:image/png;base64,{figure_png(fig)}">'
            f"<figcaption>{esc(alt)}</figcaption></figure>")
