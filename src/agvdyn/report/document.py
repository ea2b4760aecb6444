"""The report as one self-contained HTML file: verdict, data quality, parameters, correlation,
residuals, Fig. 5, Fig. 6 and provenance. Figures are embedded as base64 PNG; no script, no
external file. Written atomically (``agvdyn._files.write_text_atomically``).

The renderer only formats: every number and figure input is in ``report.contents``
(:mod:`agvdyn.report.model`, computed when the report was assembled)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from agvdyn import plots
from agvdyn._files import write_text_atomically
from agvdyn.platform import PAPER_CONDITION_NUMBER
from agvdyn.report._format import count, esc, figure_png, nbytes, num, percent, plain, table, unit, value_std_ci
from agvdyn.report._format import img as _img
from agvdyn.report._format import yes_no
from agvdyn.report.assemble import Outcome, Report, report_of
from agvdyn.report.plan_section import plan_html
from agvdyn.report.reference import Reference
from agvdyn.report.model_section import model_html
from agvdyn.report.track_section import track_html

__all__ = ["figure_png", "report_html", "write_report"]

_CSS = """
:root { --ok: #1b7f3b; --warn: #a36100; --bad: #b3261e; --line: #d8dce0; --muted: #5b6670; }
* { box-sizing: border-box; }
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #1d2327;
       margin: 0; background: #f4f6f8; }
main { max-width: 1240px; margin: 0 auto; padding: 24px 28px 48px; background: #fff; }
h1 { font-size: 26px; margin: 0 0 4px; }
h2 { font-size: 20px; margin: 36px 0 10px; padding-bottom: 4px; border-bottom: 2px solid var(--line); }
h3 { font-size: 16px; margin: 22px 0 6px; }
.meta, .note, figcaption { color: var(--muted); font-size: 13px; }
.verdict { border-radius: 8px; padding: 14px 18px; margin: 18px 0 8px; border: 2px solid; }
.verdict.identified { border-color: var(--ok); background: #eef8f1; }
.verdict.warnings { border-color: var(--warn); background: #fff6e6; }
.verdict.refused { border-color: var(--bad); background: #fdeeee; }
.verdict .label { font-size: 24px; font-weight: 700; letter-spacing: .01em; }
.verdict.identified .label { color: var(--ok); } .verdict.warnings .label { color: var(--warn); }
.verdict.refused .label { color: var(--bad); }
.verdict p { margin: 6px 0; } .verdict ul { margin: 6px 0 0; padding-left: 22px; }
.facts { display: flex; flex-wrap: wrap; gap: 8px 28px; margin: 10px 0 0; font-size: 14px; }
.facts b { font-variant-numeric: tabular-nums; }
nav { font-size: 14px; margin: 10px 0 0; } nav a { margin-right: 14px; color: #0b5cad; text-decoration: none; }
table { border-collapse: collapse; margin: 6px 0 14px; font-size: 13.5px; font-variant-numeric: tabular-nums; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 10px; text-align: right; white-space: nowrap; }
th { background: #f0f2f4; font-weight: 600; border-bottom: 2px solid var(--line); white-space: normal;
     vertical-align: bottom; }
.l { text-align: left; } td.l { white-space: normal; }
tr.bad td { background: #fdecea; } tr.fixed td { color: var(--muted); } tr.chosen td { background: #eef8f1; }
.unit { white-space: nowrap; }
.scroll { overflow-x: auto; }
figure { margin: 8px 0 18px; } figure img { display: block; max-width: 100%; height: auto; }
code, .hash { font-family: ui-monospace, "DejaVu Sans Mono", monospace; font-size: 12.5px; }
pre { white-space: pre-wrap; background: #f6f7f8; padding: 10px; border-radius: 6px; font-size: 13px; }
.grid { display: grid; grid-template-columns: repeat(auto-fill, minmax(330px, 1fr)); gap: 0 24px; }
.grid table { width: 100%; }
"""

_SECTIONS = (("verdict", "Verdict"), ("data-quality", "Data quality"), ("plan", "Excitation plan"),
             ("models", "Model"), ("parameters", "Parameters"),
             ("correlation", "Correlation"), ("residuals", "Residuals"), ("fit", "Fit (Fig. 5)"),
             ("validation", "Validation (Fig. 6)"), ("tracking", "Payload tracking"), ("provenance", "Provenance"))


def _verdict(report: Report) -> str:
    v, facts_ = report.verdict, report.contents.facts
    cls = {Outcome.IDENTIFIED: "identified", Outcome.WARNINGS: "warnings", Outcome.REFUSED: "refused"}[v.outcome]
    parts = [f'<section id="verdict" class="verdict {cls}"><div class="label">{esc(v.outcome.value.capitalize())}'
             f"</div><p>{esc(v.summary)}</p>"]
    if v.reasons:
        title = "Why" if v.outcome is Outcome.REFUSED else "Warnings"
        parts.append(f"<b>{title}:</b><ul>" + "".join(f"<li>{esc(r)}</li>" for r in v.reasons) + "</ul>")
    if report.refusal is not None:
        parts.append(f"<details><summary>Full message</summary><pre>{esc(report.refusal)}</pre></details>")
    facts = []
    if facts_.cond is not None:
        facts.append(f"cond(&Theta;<sub>1,w</sub><sup>T</sup>&Theta;<sub>1,w</sub>) <b>{num(facts_.cond, 3)}</b>")
    if facts_.worst_nrmse is not None:
        facts.append(f"validation NRMSE without stiction rows &le; <b>{num(facts_.worst_nrmse, 2)}</b>")
    facts.append(f"reference <b>{esc(facts_.reference) if facts_.reference else 'none'}</b>")
    facts.append(f"platform <b>{esc(facts_.platform)}</b>")
    parts.append('<div class="facts">' + "".join(f"<span>{f}</span>" for f in facts) + "</div></section>")
    return "".join(parts)


def _per_mode(modes) -> str:
    body = [[esc(plots.mode_name(m.label)), count(m.samples), esc(", ".join(m.coordinates)), count(m.equations),
             count(m.kept), count(m.equations - m.kept), percent(m.kept_pct, 3)] for m in modes]
    return table(["mode", "samples used", "generalized coordinates", "equation rows", "kept for the fit",
                  "left out: stiction and its guard", "kept"], body, align="lrl")


def _quality(report: Report) -> str:
    q = report.contents.quality
    parts = ['<section id="data-quality"><h2>Data quality</h2>']
    if q is None:
        return parts[0] + '<p class="note">No pre-flight check (results computed elsewhere).</p></section>'
    body = [[f"<code>{esc(f.path)}</code>", count(f.samples), f"{num(f.duration, 4)}&nbsp;s",
             f"{num(f.rate, 4, trim=True)}&nbsp;Hz", count(f.cuts), count(f.labelled_runs), count(f.clipped),
             count(f.slip_events), count(f.used), percent(f.used_pct, 3)] for f in q.files]
    parts.append(table(["file", "samples", "duration", "rate", "cuts (dropouts)", "labelled runs",
                        "clipped at the stops", "slip events", "samples used", "used"], body))
    parts.append(_img(plots.quality_figure(q.timeline),
                      "Per file: segment labels (coloured by the mode they name), the motion mode of each row from "
                      "its configuration, rows kept for the regression, wheel slip, cuts between recordings."))
    parts.append("<h3>Rows kept per motion mode</h3>")
    parts.append(_per_mode(q.modes))
    parts.append("<h3>Samples left out, and why</h3>")
    body = [[f"<code>{esc(f.path)}</code>", count(f.counted), count(f.edge), count(f.slip), count(f.no_mode),
             count(f.not_selected), count(f.too_short), count(f.used)] for f in q.files]
    parts.append(table(["file", "samples", "filter edges", "wheel slip", "in no motion mode", "not selected (--segments)",
                        "stretch too short", "used"], body))
    parts.append(f'<p class="note">Filter edges: the first and last {num(q.edge_ms, 3)}&nbsp;ms of '
                 "each continuous recording (zero-phase filter transients). In no motion mode: the "
                 "chassis moves with steering angles of no mode of eq. (9), or steers while moving laterally or "
                 "rotating. Stiction rows are left out per generalized coordinate (table above). Rows clipped at "
                 "the steering stops are kept (their angle is set to the stop).</p>")
    if q.mismatch:
        parts.append("<h3>Labels next to the detected modes</h3>")
        parts.append(table(["label", "rows in another mode than the label names"],
                           [[esc(k), count(v)] for k, v in q.mismatch]))
        parts.append('<p class="note">Labels are hints: every row\'s mode comes from its configuration, so a label '
                     "that also covers the wheel alignment before an experiment, or lags, is counted here and does "
                     "not change the parameters.</p>")
    parts.append("<h3>Wheel slip</h3>")
    if q.slip:
        parts.append(table(["file", "start", "end", "duration", "peak slip speed", "wheels", "samples"],
                           [[f"<code>{esc(e.source)}</code>", f"{num(e.t_start, decimals=3)}&nbsp;s",
                             f"{num(e.t_end, decimals=3)}&nbsp;s", f"{num(e.duration_ms, 3)}&nbsp;ms",
                             f"{num(e.peak_mps, 3)}&nbsp;m/s", esc(", ".join(e.wheels)), count(e.rows)]
                            for e in q.slip], align="lrrrrl"))
    else:
        thresholds = ", ".join(f"{num(x, 3, trim=True)}&nbsp;m/s" for x in q.slip_thresholds)
        parts.append(f"<p>No wheel slip found (threshold on the rolling-constraint residual: {thresholds}).</p>")
    parts.append("<h3>Excitation of each parameter by the rows kept</h3>")
    parts.append(table(["parameter", "status", "variance inflation", "relative std", "excited by"],
                       [[esc(e.name), esc(e.status), num(e.inflation, 3), percent(100 * e.relative_std, 2),
                         esc(e.excited_by)] for e in q.excitation], align="llrrl",
                       row_classes=["bad" if e.status in ("weak", "not excited") else "" for e in q.excitation]))
    if q.notes:
        parts.append("<h3>Notes</h3><ul>" + "".join(f"<li>{esc(n)}</li>" for n in q.notes) + "</ul>")
    parts.append("</section>")
    return "".join(parts)


_METHODS = {"hac": "heteroscedasticity- and autocorrelation-consistent (Bartlett) covariance",
            "classic": "classic covariance of eq. (25)", "bootstrap": "block bootstrap",
            "jackknife": "delete-one-block jackknife"}


def _parameters(report: Report) -> str:
    sec = report.contents.parameters
    parts = ['<section id="parameters"><h2>Parameters</h2>']
    if sec is None:
        return parts[0] + "<p>None: the identification was refused (see the verdict).</p></section>"
    compared = sec.reference_label is not None
    header = ["parameter", "value", "std", "95&nbsp;% interval", "unit", "estimated or fixed"]
    if compared:
        header += [f"reference<br><span class=note>{esc(sec.reference_label)}</span>", "deviation",
                   "|deviation| / std", "within 5&nbsp;% or 3&nbsp;std"]
    body, classes = [], []
    for row in sec.rows:
        value, std_text, ci_text = value_std_ci(row.value, row.std, row.ci)
        if row.fixed:
            value = num(row.value, 5, trim=True)
        cells = [esc(row.name), value, std_text, ci_text, unit(row.unit), "fixed" if row.fixed else "estimated"]
        if compared:
            cells += [num(row.reference, 5, trim=True),
                      "&ndash;" if row.fixed else percent(row.deviation_pct, 2, signed=True),
                      num(row.deviation_in_std, 2), yes_no(row.ok)]
        body.append(cells)
        classes.append("fixed" if row.fixed else ("bad" if row.ok is False else ""))
    parts.append('<div class="scroll">' + table(header, body, align="lrrrll", row_classes=classes) + "</div>")
    bw = sec.bandwidth
    parts.append(
        f"<p>std: {esc(_METHODS.get(sec.method, ''))}{f', bandwidth {count(bw)} samples' if bw else ''}; 95&nbsp;% "
        f"interval = value &plusmn; 1.96&nbsp;std. Estimator: {esc(sec.estimator)}. "
        f"cond(&Theta;<sub>1,w</sub><sup>T</sup>&Theta;<sub>1,w</sub>) of the column-scaled stacked regressor "
        f"(eq. 25) = <b>{num(sec.cond, 4)}</b> (paper: {PAPER_CONDITION_NUMBER}); unscaled: "
        f"{num(sec.cond_unscaled, 3)}. {count(sec.n_rows)} equation rows from "
        f"{count(sec.n_samples)} samples.</p>")
    if not compared:
        parts.append('<p class="note">No comparison: no reference was given (<code>--reference FILE</code>), the '
                     "logs carry no simulator truth and the platform is not the paper's prototype, so Table 2 "
                     "does not apply.</p>")
    if sec.offsets:
        parts.append("<h3>Motor-torque offsets (nuisance parameters, motor side)</h3>")
        parts.append(table(["offset", "value", "std", "unit"],
                           [[esc(n), *value_std_ci(v, sd, None)[:2], unit("N m")] for n, v, sd in sec.offsets],
                           align="lrrl"))
    if sec.deviations is not None:
        parts.append(_img(plots.parameter_figure(sec.deviations),
                          f"Deviation of each estimate from the reference ({sec.deviations.label}), with +-3 std bars."))
    parts.append("</section>")
    return "".join(parts)


def _correlation(report: Report) -> str:
    sec = report.contents.correlation
    if sec is None:
        return ""
    text = ("Strongly correlated (|r| &ge; 0.9): " + ", ".join(f"{esc(a)} and {esc(b)} ({num(v, 2, signed=True)})"
                                                             for a, b, v in sec.pairs) +
            ". The data determine a combination of these better than each one; their std already include this."
            if sec.pairs else "No pair of estimates is correlated beyond |r| = 0.9.")
    return (f'<section id="correlation"><h2>Correlation of the estimates</h2><p>{text}</p>'
            + _img(plots.correlation_figure(sec.figure), "Correlation matrix of the estimated parameters.", "narrow")
            + "</section>")


def _residuals(report: Report) -> str:
    sec = report.contents.residuals
    if sec is None:
        return ""
    rows = [[esc(k), num(v, 3, trim=True), unit(u)] for k, v, u in sec.rms]
    return ('<section id="residuals"><h2>Residuals</h2><p>Residual = measured &minus; model generalized torque on '
            "the rows of the fit. White residuals stay inside the grey band of the autocorrelation; a slow decay "
            "means correlated errors, which the HAC standard deviations account for up to the marked bandwidth."
            "</p>" + _img(plots.residual_figure(sec.figure), "Residuals over time and their autocorrelation.")
            + "<h3>Residual RMS per segment and generalized coordinate</h3>"
            + table(["segment:coordinate", "RMS", "unit"], rows, align="lrl") + "</section>")


def _fit(report: Report) -> str:
    fit = report.contents.fit
    if fit is None:
        return ""
    return ('<section id="fit"><h2>Identification fit (cf. Fig. 5)</h2><p>Measured and model generalized torques '
            "of each segment. The model is drawn on the rows the fit uses; shaded: rows left out (stiction and "
            "its guard, filter edges, slip), where the tanh Coulomb term would switch with noise.</p>"
            + _img(plots.identification_figure(fit), "Identification experiment: generalized torques.")
            + "</section>")


def _validation(report: Report) -> str:
    sec = report.contents.validation
    if sec is None:
        return ""
    body = [[esc(k), num(nrmse, decimals=3), num(moving, decimals=3), num(err, 3), num(meas, 3), unit(u), count(n),
             count(n_moving)] for k, nrmse, moving, err, meas, u, n, n_moving in sec.rows]
    return (f'<section id="validation"><h2>Validation on <code>{esc(sec.source)}</code> (cf. Fig. 6)</h2>'
            "<p>NRMSE = RMS(measured &minus; model) / RMS(measured) per generalized coordinate: over all rows "
            "(as Fig. 6) and without the stiction rows. The prediction is drawn where the second is computed, "
            "with the stiction handling of the fit.</p>"
            + table(["coordinate", "NRMSE", "NRMSE without stiction", "RMS error", "RMS measured", "unit", "rows",
                     "rows moving"], body, align="lrrrrl")
            + _img(plots.validation_figure(sec.figure), "Validation experiment: generalized torques.") + "</section>")


def _provenance(report: Report) -> str:
    p = report.provenance
    files = table(["role", "file", "size", "SHA-256"],
                  [[esc(f.role), f"<code>{esc(f.path)}</code>", nbytes(f.size) if f.size is not None else "unreadable",
                    f'<span class="hash">{esc(f.sha256 or "")}</span>'] for f in p.files], align="llrl")
    facts = {"agvdyn": esc(p.version), "created": esc(p.created), "platform": esc(p.platform),
             **{k: esc(v) for k, v in p.environment.items()}}
    if p.command:
        facts["command"] = f"<code>{esc(p.command)}</code>"
    settings = list(p.settings.items())
    half = (len(settings) + 1) // 2
    grid = "".join(table(["setting", "value"], [[esc(k), plain(v)] for k, v in chunk], align="ll")
                   for chunk in (settings[:half], settings[half:]))
    return ('<section id="provenance"><h2>Provenance</h2><h3>Input files</h3><div class="scroll">' + files + "</div>"
            + "<h3>Software and platform</h3>" + table(None, [[k, v] for k, v in facts.items()], align="ll")
            + "<h3>Settings</h3>" + f'<div class="grid">{grid}</div></section>')


def report_html(report: Report) -> str:
    """The report as an HTML string (figures embedded, no script)."""
    title = esc(report.title)
    sections = [_quality(report), plan_html(report.contents.plan), model_html(report.models),
                _parameters(report), _correlation(report), _residuals(report), _fit(report), _validation(report),
                track_html(report.tracking), _provenance(report)]
    html_all = "".join(sections)
    nav = "".join(f'<a href="#{k}">{v}</a>' for k, v in _SECTIONS if k == "verdict" or f'id="{k}"' in html_all)
    head = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width, initial-scale=1'><title>{title}</title>"
            f"<style>{_CSS}</style></head><body><main><h1>{title}</h1>"
            f"<div class='meta'>platform {esc(report.provenance.platform)} &middot; agvdyn "
            f"{esc(report.provenance.version)} &middot; {esc(report.provenance.created)}</div>")
    body = [head, _verdict(report), f"<nav>{nav}</nav>", *sections, "</main></body></html>"]
    return "\n".join(body)


def write_report(path: str | os.PathLike, report: Any, validation: Any = None, *,
                 reference: Reference | None = None, **kwargs: Any) -> Path:
    """Write the HTML report atomically. ``report``: a :class:`Report`, or an
    :class:`~agvdyn.identification.Identification` (with ``validation``, ``reference`` and the
    keywords of :func:`agvdyn.report.report_of`) to report on results computed elsewhere."""
    if not isinstance(report, Report):
        report = report_of(report, validation, reference=reference, **kwargs)
    return write_text_atomically(path, report_html(report))
