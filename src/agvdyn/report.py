"""HTML report of an identification (and validation): Table 2, Fig. 5, Fig. 6, inputs, settings.

One self-contained HTML file: the figures are embedded as base64 PNG, no external files.
Written atomically (``agvdyn._files.write_text_atomically``).
"""
from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from agvdyn import plots
from agvdyn._files import write_text_atomically
from agvdyn.platform import PAPER_CONDITION_NUMBER, PAPER_PARAMETERS, PAPER_STD, PARAMETER_NAMES, PARAMETER_UNITS, Parameters

__all__ = ["parameter_table", "reference_parameters", "report_html", "write_report", "figure_png"]


def reference_parameters(logs) -> tuple[Parameters, dict[str, float], str]:
    """What to compare identified parameters with: the simulator's true parameters from a log
    sidecar (``true_parameters``) when present, else Table 2 of the paper.

    Returns (parameters, standard deviations, label).
    """
    for log in logs:
        side = getattr(log, "sidecar", None) or {}
        for key in ("true_parameters", "parameters"):
            data = side.get(key)
            if isinstance(data, dict):
                values = {n: (v.get("value") if isinstance(v, dict) else v) for n, v in data.items()}
                if all(isinstance(values.get(n), (int, float)) for n in PARAMETER_NAMES):
                    return Parameters(**{n: values[n] for n in PARAMETER_NAMES}), {}, f"simulator truth: sidecar {key}"
    return PAPER_PARAMETERS, dict(PAPER_STD), "paper, Table 2"


def parameter_table(identification, reference: Parameters = PAPER_PARAMETERS,
                    reference_std: Mapping[str, float] = PAPER_STD, *, rel_tolerance: float = 0.05,
                    n_std: float = 3.0) -> pd.DataFrame:
    """Table 2 with the reference alongside.

    Columns: ``value``, ``std``, ``reference``, ``reference_std``, ``deviation_pct`` (100 (value /
    reference - 1)), ``deviation_in_std`` (|value - reference| / std) and ``ok``: within
    ``rel_tolerance`` of the reference or within ``n_std`` standard deviations, whichever is wider
    (the acceptance rule of issue 4). Fixed parameters have ``ok`` = None.
    """
    rows = []
    for name in PARAMETER_NAMES:
        value = getattr(identification.parameters, name)
        ref = getattr(reference, name)
        std = identification.std.get(name, math.nan)
        fixed = name in identification.fixed
        dev = value - ref
        in_std = abs(dev) / std if std and math.isfinite(std) and std > 0 else math.nan
        ok = None if fixed else bool(abs(dev) <= max(rel_tolerance * abs(ref), n_std * std if math.isfinite(std) else 0))
        rows.append({
            "name": name, "value": value, "std": std, "unit": PARAMETER_UNITS[name], "fixed": fixed,
            "reference": ref, "reference_std": reference_std.get(name, math.nan),
            "deviation_pct": 100 * (value / ref - 1) if ref else math.nan, "deviation_in_std": in_std, "ok": ok,
        })
    return pd.DataFrame(rows).set_index("name")


def figure_png(fig, dpi: int = 110) -> str:
    """A figure as base64-encoded PNG."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _fmt(x: Any, digits: int = 4) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return "yes" if x else "NO"
    if isinstance(x, float):
        if not math.isfinite(x):
            return ""
        return f"{x:.{digits}f}" if abs(x) >= 1e-3 or x == 0 else f"{x:.3e}"
    return html.escape(str(x))


def _table_html(frame: pd.DataFrame, columns: Mapping[str, str], index_name: str) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in [index_name, *columns.values()])
    body = []
    for idx, row in frame.iterrows():
        cells = "".join(f"<td>{_fmt(row[c])}</td>" for c in columns)
        cls = ' class="bad"' if row.get("ok") is False else ""
        body.append(f"<tr{cls}><td>{html.escape(str(idx))}</td>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _dict_html(data: Mapping[str, Any]) -> str:
    rows = "".join(f"<tr><td>{html.escape(str(k))}</td><td>{_fmt(v)}</td></tr>" for k, v in data.items())
    return f"<table>{rows}</table>"


_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
td:first-child, th:first-child { text-align: left; }
tr.bad td { background: #fdd; }
img { max-width: 100%; }
.note { color: #555; font-size: 0.9em; }
"""


def report_html(identification, validation=None, *, reference: Parameters = PAPER_PARAMETERS,
                reference_std: Mapping[str, float] = PAPER_STD, reference_label: str = "paper, Table 2",
                title: str = "agvdyn identification report", inputs: Mapping[str, Any] | None = None) -> str:
    """The report as an HTML string (figures embedded)."""
    table = parameter_table(identification, reference, reference_std)
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>",
             f"<p class='note'>generated {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}</p>"]
    parts.append("<h2>Identified parameters (cf. Table 2)</h2>")
    parts.append(_table_html(table, {
        "value": "value", "std": "std", "unit": "unit", "fixed": "fixed",
        "reference": f"reference ({reference_label})", "reference_std": "reference std",
        "deviation_pct": "deviation [%]", "deviation_in_std": "|deviation| / std",
        "ok": "within 5 % or 3 std"}, "parameter"))
    parts.append(
        f"<p>cond(&Theta;<sub>1,w</sub><sup>T</sup>&Theta;<sub>1,w</sub>) of the column-scaled stacked regressor "
        f"(eq. 25) = <b>{identification.condition_number:.4g}</b> (paper: {PAPER_CONDITION_NUMBER}); unscaled "
        f"cond(&Theta;<sub>1</sub><sup>T</sup>&Theta;<sub>1</sub>) = {identification.condition_number_unscaled:.4g}. "
        f"{identification.n_rows} equation rows from {identification.n_samples} samples; fixed: "
        f"{', '.join(f'{n} = {getattr(identification.parameters, n)}' for n in identification.fixed) or 'none'}.</p>")
    parts.append(f"<img alt='parameters' src='data:image/png;base64,{figure_png(plots.parameter_figure(identification, reference, reference_std))}'>")
    parts.append("<h3>Residual RMS per generalized torque (kept rows)</h3>")
    parts.append(_dict_html(identification.residual_rms))
    parts.append("<h2>Identification experiment (cf. Fig. 5)</h2>")
    parts.append(f"<img alt='Fig. 5' src='data:image/png;base64,{figure_png(plots.identification_figure(identification))}'>")
    if validation is not None:
        parts.append(f"<h2>Validation on {html.escape(validation.source)} (cf. Fig. 6)</h2>")
        parts.append("<p>NRMSE = RMS(measured - model) / RMS(measured), per generalized coordinate; "
                     "with all rows (as Fig. 6) and without the stiction rows.</p>")
        parts.append(_table_html(validation.table, {
            "nrmse": "NRMSE", "nrmse_moving": "NRMSE without stiction rows", "rms_error": "RMS error",
            "rms_measured": "RMS measured", "n_rows": "rows", "n_moving": "rows moving"}, "coordinate"))
        parts.append(f"<img alt='Fig. 6' src='data:image/png;base64,{figure_png(plots.validation_figure(validation))}'>")
    parts.append("<h2>Inputs and settings</h2>")
    facts: dict[str, Any] = {"identification logs": ", ".join(identification.sources) or "(in memory)"}
    if validation is not None:
        facts["validation log"] = validation.source
    facts.update({f"platform {k}": v for k, v in identification.geometry.to_dict().items()})
    facts.update(identification.settings.to_dict())
    facts["estimator"] = identification.estimator
    facts.update(inputs or {})
    parts.append(_dict_html(facts))
    notes = list(identification.notes) + (list(validation.notes) if validation is not None else [])
    if notes:
        parts.append("<h3>Notes</h3><ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(path: str | os.PathLike, identification, validation=None, **kwargs: Any) -> Path:
    """Write the HTML report atomically; keyword arguments as :func:`report_html`."""
    return write_text_atomically(path, report_html(identification, validation, **kwargs))
