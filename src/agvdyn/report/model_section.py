"""The report's "Model" section (issue 30): the comparison of the paper's model with its extensions
(:func:`agvdyn.identification.compare_models`) and the model the data chose.

:func:`model_section` takes a :class:`~agvdyn.identification.ModelSelection` to the numbers the
page shows (:class:`ModelSection`); :func:`model_html` renders them. The report runs the comparison
when asked (``make_report(..., models="compare")``, ``agvdyn report --compare-models``); its
identification is then the chosen model's.
"""
from __future__ import annotations

import html
import math
from dataclasses import dataclass
from typing import Any

__all__ = ["ModelRow", "ModelSection", "model_section", "model_html", "REPORT_MODELS"]

#: What ``make_report(models=...)`` accepts: the paper's model alone, or the comparison (auto's choice).
REPORT_MODELS = ("paper", "compare")


@dataclass(frozen=True)
class ModelRow:
    """One candidate: its label, the parameters it adds, its scores, whether chosen, and why it was
    not usable (refused or undetermined), if so."""

    label: str
    added: tuple[str, ...]
    bic: float
    residual_rms: float
    nrmse_holdout: float
    nrmse_validation: float | None
    chosen: bool
    note: str = ""


@dataclass(frozen=True)
class ModelSection:
    """The comparison: one row per candidate (paper first), the chosen label, the found delay and
    Stribeck velocities of the chosen model, and the effective row count behind the BIC."""

    rows: tuple[ModelRow, ...]
    chosen: str
    chosen_values: dict[str, str]
    n_effective: float
    correlation_steps: float

    def to_dict(self) -> dict[str, Any]:
        return {"chosen": self.chosen, "chosen_values": dict(self.chosen_values),
                "n_effective": self.n_effective, "correlation_steps": self.correlation_steps,
                "rows": [{"model": r.label, "parameters_added": list(r.added), "bic": _num(r.bic),
                          "residual_rms": _num(r.residual_rms), "nrmse_holdout": _num(r.nrmse_holdout),
                          "nrmse_validation": None if r.nrmse_validation is None else _num(r.nrmse_validation),
                          "chosen": r.chosen, "note": r.note} for r in self.rows]}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _note(score: Any) -> str:
    if score.error:
        return f"refused: {score.error}"
    if score.undetermined:
        return "undetermined: " + ", ".join(score.undetermined)
    from agvdyn.identification.selection_rows import comparison_note

    return comparison_note(score.versus_paper)


def _chosen_values(ident: Any) -> dict[str, str]:
    """The chosen model's searched and added values as text (value +- std)."""
    if ident is None:
        return {}
    out = {}
    model = ident.model
    if model.delay != 0.0:
        std = ident.delay_std_s
        out["delay_s"] = f"{1e3 * float(model.delay):.2f} ms" + (
            "" if std is None else (" (undetermined)" if not math.isfinite(std) else f" +- {1e3 * std:.2f} ms"))
    for name, value in ident.extra.items():
        std = ident.extra_std.get(name)
        out[name] = f"{value:.4g}" + ("" if std is None else f" +- {std:.2g}")
    return out


def model_section(selection: Any) -> ModelSection:
    """The section of a :class:`~agvdyn.identification.ModelSelection`."""
    rows = tuple(ModelRow(s.label, tuple(s.parameters_added), s.bic, s.residual_rms, s.nrmse_holdout,
                          s.nrmse_validation, s.chosen, _note(s)) for s in selection.scores)
    chosen = selection.scores[selection.chosen]
    return ModelSection(rows, chosen.label, _chosen_values(chosen.identification), float(selection.n_effective),
                        float(selection.correlation_steps))


def _cell(x: float | None, digits: int = 4) -> str:
    return "&ndash;" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _row_html(r: ModelRow) -> str:
    attr, mark = (' class="chosen"', "&#10003;") if r.chosen else ("", "")
    added = html.escape(", ".join(r.added)) or "&ndash;"
    return (f"<tr{attr}><td>{html.escape(r.label)}</td><td>{added}</td><td>{_cell(r.bic, 6)}</td>"
            f"<td>{_cell(r.residual_rms)}</td><td>{_cell(r.nrmse_holdout)}</td><td>{_cell(r.nrmse_validation)}</td>"
            f"<td>{mark}</td><td>{html.escape(r.note)}</td></tr>")


def model_html(section: ModelSection | None) -> str:
    """The section's HTML (empty when the report did not compare models)."""
    if section is None:
        return ""
    head = ("<tr><th>model</th><th>adds</th><th>BIC</th><th>residual RMS</th><th>held-out NRMSE</th>"
            "<th>validation NRMSE</th><th>chosen</th><th>note</th></tr>")
    body = "".join(_row_html(r) for r in section.rows)
    values = "".join(f"<li>{html.escape(k)} = {html.escape(v)}</li>" for k, v in section.chosen_values.items())
    return (f'<section id="models"><h2>Model</h2><p>The data chose <b>{html.escape(section.chosen)}</b>: an '
            "extension of the paper's model is kept only when it lowers the BIC and the held-out error and its "
            "parameters are possible and determined (docs/identification.md). BIC on "
            f"{section.n_effective:,.0f} effective rows (residual correlation {section.correlation_steps:.1f} "
            f"samples).</p><table>{head}{body}</table>"
            + (f"<p>Values of the chosen model:</p><ul>{values}</ul>" if values else "") + "</section>")
