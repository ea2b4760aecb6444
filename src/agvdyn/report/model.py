"""The report's contents, computed once at assembly (:func:`contents_of`): every number the HTML
shows and every figure's input, per section, in frozen objects; :mod:`agvdyn.report.document`
only formats them."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from agvdyn import figure_data
from agvdyn.platform import PARAMETER_NAMES, PARAMETER_UNITS
from agvdyn.report.plan_section import PlanSection, plan_section
from agvdyn.report.reference import parameter_table

__all__ = ["FileRow", "ModeRow", "SlipRow", "Quality", "ParameterRow", "ParameterSection", "CorrelationSection",
           "ResidualSection", "ValidationSection", "Facts", "ReportContents", "contents_of", "COORDINATE_UNITS"]

#: Unit of the generalized torque of each generalized coordinate.
COORDINATE_UNITS = {"alpha_l": "N m", "alpha_r": "N m", "alpha_v": "N m", "gamma_ch": "N m", "x_ch": "N", "y_ch": "N"}
_MODE_ORDER = ("1", "2", "2s", "3", "4")


def _pct(part: float, whole: float) -> float:
    return 100 * part / whole if whole else float("nan")


@dataclass(frozen=True)
class FileRow:
    """One log of the data-quality tables: its summary and the account of its samples."""

    path: str
    samples: int
    duration: float
    rate: float
    cuts: int
    labelled_runs: int
    clipped: int
    slip_events: int
    used: int
    used_pct: float
    counted: int
    edge: int
    slip: int
    no_mode: int
    not_selected: int
    too_short: int


@dataclass(frozen=True)
class ModeRow:
    """Rows kept per motion mode: samples used, coordinates, equation rows, kept for the fit."""

    label: str
    samples: int
    coordinates: tuple[str, ...]
    equations: int
    kept: int
    kept_pct: float


@dataclass(frozen=True)
class SlipRow:
    source: str
    t_start: float
    t_end: float
    duration_ms: float
    peak_mps: float
    wheels: tuple[str, ...]
    rows: int


@dataclass(frozen=True, eq=False)
class Quality:
    """The data-quality section (None in the report without a pre-flight check)."""

    files: tuple[FileRow, ...]
    timeline: figure_data.QualityTimeline
    modes: tuple[ModeRow, ...]
    edge_ms: float
    mismatch: tuple[tuple[str, int], ...]
    slip: tuple[SlipRow, ...]
    slip_thresholds: tuple[float, ...]
    excitation: tuple[Any, ...]
    notes: tuple[str, ...]


@dataclass(frozen=True)
class ParameterRow:
    """One parameter: value, std and 95 % interval (None: fixed), and the comparison."""

    name: str
    value: float
    std: float | None
    ci: tuple[float, float] | None
    unit: str
    fixed: bool
    reference: float
    deviation_pct: float
    deviation_in_std: float
    ok: bool | None


@dataclass(frozen=True, eq=False)
class ParameterSection:
    rows: tuple[ParameterRow, ...]
    reference_label: str | None
    method: str
    bandwidth: int | None
    estimator: str
    cond: float
    cond_unscaled: float
    n_rows: int
    n_samples: int
    offsets: tuple[tuple[str, float, float | None], ...]
    deviations: figure_data.ParameterDeviations | None


@dataclass(frozen=True, eq=False)
class CorrelationSection:
    """Pairs with |r| >= 0.9, strongest first, and the matrix."""

    pairs: tuple[tuple[str, str, float], ...]
    figure: figure_data.CorrelationMatrix


@dataclass(frozen=True, eq=False)
class ResidualSection:
    rms: tuple[tuple[str, float, str], ...]
    figure: figure_data.Residuals


@dataclass(frozen=True, eq=False)
class ValidationSection:
    """Per coordinate ``(key, nrmse, nrmse without stiction, rms error, rms measured, unit, rows,
    rows moving)`` and Fig. 6."""

    source: str
    rows: tuple[tuple[str, float, float, float, float, str, int, int], ...]
    figure: figure_data.TorqueFigure


@dataclass(frozen=True)
class Facts:
    """The facts under the verdict."""

    cond: float | None
    worst_nrmse: float | None
    reference: str | None
    platform: str


@dataclass(frozen=True, eq=False)
class ReportContents:
    """Everything the HTML shows besides the verdict and provenance texts; None: no such section."""

    facts: Facts
    quality: Quality | None
    plan: PlanSection | None
    parameters: ParameterSection | None
    correlation: CorrelationSection | None
    residuals: ResidualSection | None
    fit: figure_data.TorqueFigure | None
    validation: ValidationSection | None
    parameter_table: Any = None


def _quality(checked, cuts, identification, settings: Mapping[str, Any]) -> Quality:
    files = []
    for k, f in enumerate(checked.files):
        s, c = f.summary, f.rows.counts
        files.append(FileRow(s.path or "<log>", s.n_samples, s.duration, s.rate, len(cuts[k]) if k < len(cuts) else 0,
                             len(s.segments), sum(c.clipped_stop.values()), len(f.rows.slip_events), c.used,
                             _pct(c.used, c.samples), c.samples, c.edge, c.slip, c.no_mode, c.not_selected,
                             c.too_short))
    samples: dict[str, int] = {}
    kept: dict[str, int] = {}
    coords: dict[str, tuple[str, ...]] = {}
    for f in checked.files:
        for key, v in f.rows.counts.per_mode.items():
            samples[key] = samples.get(key, 0) + v
        for b in f.rows.blocks:
            kept[b.mode.label] = kept.get(b.mode.label, 0) + int(b.keep.sum())
            coords[b.mode.label] = b.coordinates
    modes = []
    for m in (m for m in _MODE_ORDER if m in samples):
        equations = samples[m] * len(coords.get(m, ()))
        modes.append(ModeRow(m, samples[m], coords.get(m, ()), equations, kept.get(m, 0),
                             _pct(kept.get(m, 0), equations)))
    mismatch: dict[str, int] = {}
    for f in checked.files:
        for key, v in f.rows.counts.label_mismatch.items():
            mismatch[key] = mismatch.get(key, 0) + v
    slip = tuple(SlipRow(e.source, e.t_start, e.t_end, 1000 * (e.t_end - e.t_start), e.peak_mps, tuple(e.wheels),
                         e.rows) for f in checked.files for e in f.rows.slip_events)
    notes = [f"{f.summary.path or '<log>'}: {g}" for f in checked.files for g in f.gaps]
    notes += list(checked.warnings) + (list(identification.notes) if identification else [])
    edge_ms = 1000 * settings.get("edge_guard", float("nan")) / settings.get("filter_cutoff_rad_s", float("nan"))
    return Quality(tuple(files), figure_data.quality_timeline(checked.files, cuts), tuple(modes), edge_ms,
                   tuple(mismatch.items()), slip, tuple(f.rows.slip_threshold for f in checked.files),
                   tuple(checked.excitation), tuple(dict.fromkeys(notes)))  # the identification notes its cuts too


def _parameters(ident, reference, table) -> ParameterSection:
    rows = []
    for name in PARAMETER_NAMES:
        row = table.loc[name]
        fixed = bool(row["fixed"])
        rows.append(ParameterRow(name, row["value"], None if fixed else row["std"],
                                 None if fixed else (row["ci_low"], row["ci_high"]), PARAMETER_UNITS[name], fixed,
                                 row["reference"], row["deviation_pct"], row["deviation_in_std"], row["ok"]))
    unc = ident.uncertainty
    deviations = None if reference is None else figure_data.parameter_deviations(
        ident, reference.parameters, reference.std, label=reference.label)
    return ParameterSection(
        tuple(rows), None if reference is None else reference.label, "" if unc is None else unc.method,
        None if unc is None else unc.bandwidth_steps, ident.estimator, ident.condition_number,
        ident.condition_number_unscaled, ident.n_rows, ident.n_samples,
        tuple((n, v, ident.offsets_std.get(n)) for n, v in ident.offsets.items()), deviations)


def _correlation(ident) -> CorrelationSection | None:
    if ident.correlation is None or not ident.correlation.names:
        return None
    figure = figure_data.correlation_matrix(ident)
    names, r = figure.names, figure.matrix
    pairs = sorted(((abs(r[i, j]), names[i], names[j], r[i, j]) for i in range(len(names))
                    for j in range(i + 1, len(names)) if abs(r[i, j]) >= 0.9), reverse=True)
    return CorrelationSection(tuple((a, b, float(v)) for _, a, b, v in pairs), figure)


def _validation(val) -> ValidationSection:
    rows = tuple((str(k), r["nrmse"], r["nrmse_moving"], r["rms_error"], r["rms_measured"],
                  COORDINATE_UNITS.get(str(k).rpartition(":")[2], ""), r["n_rows"], r["n_moving"])
                 for k, r in val.table.iterrows())
    return ValidationSection(str(val.source), rows, figure_data.validation_torques(val))


def contents_of(report) -> ReportContents:
    """The contents of a :class:`~agvdyn.report.assemble.Report` (its results, reference, checks)."""
    ident, val = report.identification, report.validation
    worst = None
    if val is not None:
        worst = max((x for x in val.nrmse_moving.values() if x == x), default=float("nan"))
    facts = Facts(None if ident is None else ident.condition_number, worst,
                  None if report.reference is None else report.reference.label, report.geometry.name)
    quality = None if report.preflight is None else _quality(report.preflight, report.cuts, ident,
                                                             report.provenance.settings)
    plan = plan_section(report.plan, report.plan_notes, ident)
    if ident is None:
        return ReportContents(facts, quality, plan, None, None, None, None,
                              None if val is None else _validation(val))
    table = parameter_table(ident, report.reference)
    residuals = ResidualSection(tuple((k, v, COORDINATE_UNITS.get(k.rpartition(":")[2], ""))
                                      for k, v in ident.residual_rms.items()), figure_data.residuals(ident))
    return ReportContents(facts, quality, plan, _parameters(ident, report.reference, table), _correlation(ident),
                          residuals, figure_data.identification_torques(ident),
                          None if val is None else _validation(val), table)

