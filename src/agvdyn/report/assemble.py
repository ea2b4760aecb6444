"""What a report shows, computed once: pre-flight, identification (or its refusal), validation,
the reference, a verdict in plain words, and the provenance of every number.

:func:`make_report` runs the whole chain on loaded logs and never raises for a refusal of the
data: an :class:`UnidentifiableError` or :class:`ImplausibleError` becomes a report whose
verdict is ``refused`` and says why.
"""
from __future__ import annotations

import datetime as _dt
import functools
import hashlib
import math
import os
import platform as _platform
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

from agvdyn.identification import (
    DEFAULT_FIXED,
    EXCITATION,
    Identification,
    IdentificationSettings,
    ImplausibleError,
    LogRows,
    UnidentifiableError,
    identify,
    row_passes,
)
from agvdyn.io.log import sidecar_path
from agvdyn.platform import PARAMETER_UNITS, Geometry
from agvdyn.preflight import Preflight, preflight
from agvdyn.report.model import ReportContents, contents_of
from agvdyn.report.model_section import REPORT_MODELS, model_section
from agvdyn.report.plan import ExcitationPlan, PlanFile, excitation_plan
from agvdyn.report.reference import Reference, choose_reference, parameter_table
from agvdyn.report.track_section import tracking_section

__all__ = ["Outcome", "Verdict", "InputFile", "Provenance", "Report", "make_report", "report_of", "verdict_of",
           "input_file", "command_line", "MAX_VALIDATION_NRMSE"]

#: Largest NRMSE without stiction rows of a validation coordinate before the verdict warns.
#: The simulator gives 0.003-0.04 (docs/identification.md); 0.25 is a prediction clearly off.
MAX_VALIDATION_NRMSE = 0.25


class Outcome(str, Enum):
    """The verdict's headline."""

    IDENTIFIED = "identified"
    WARNINGS = "identified with warnings"
    REFUSED = "refused"


@dataclass(frozen=True)
class Verdict:
    """``outcome``; ``summary``: one sentence; ``reasons``: warnings or refusal reasons in plain words."""

    outcome: Outcome
    summary: str
    reasons: tuple[str, ...] = ()

    @property
    def exit_code(self) -> int:
        """0 identified (with or without warnings), 1 refused for data quality."""
        return 1 if self.outcome is Outcome.REFUSED else 0

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.outcome.value, "summary": self.summary, "reasons": list(self.reasons)}


@dataclass(frozen=True)
class InputFile:
    """One input: its role (identification log, sidecar, mapping, ...), path, size and SHA-256
    (a directory, such as a ROS 2 bag: the sum of its files' sizes and the hash of their
    relative names and contents)."""

    role: str
    path: str
    size: int | None
    sha256: str | None

    def to_dict(self) -> dict[str, Any]:
        return {"role": self.role, "path": self.path, "size": self.size, "sha256": self.sha256}


def input_file(role: str, path: str | os.PathLike) -> InputFile:
    """Size and SHA-256 of a file or directory; None for both when it cannot be read."""
    path = Path(path)
    digest = hashlib.sha256()
    try:
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        size = 0
        for f in files:
            if path.is_dir():
                digest.update(str(f.relative_to(path)).encode() + b"\0")
            with open(f, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    digest.update(chunk)
                    size += len(chunk)
    except OSError:
        return InputFile(role, str(path), None, None)
    return InputFile(role, str(path), size, digest.hexdigest())


@dataclass(frozen=True)
class Provenance:
    """Where the report's numbers come from: files, versions, platform, settings, date."""

    files: tuple[InputFile, ...]
    version: str
    platform: str
    settings: Mapping[str, Any]
    created: str
    environment: Mapping[str, str] = field(default_factory=dict)
    command: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"files": [f.to_dict() for f in self.files], "agvdyn": self.version, "platform": self.platform,
                "settings": dict(self.settings), "created": self.created, "environment": dict(self.environment),
                "command": self.command}


@dataclass(frozen=True, eq=False)
class Report:
    """Everything the HTML report shows (:func:`agvdyn.report.report_html`): the results, and
    ``contents``, the numbers and figure inputs of every section computed from them when the report
    is built (:func:`agvdyn.report.model.contents_of`)."""

    verdict: Verdict
    provenance: Provenance
    geometry: Geometry
    identification: Identification | None = None
    refusal: Exception | None = None
    validation: Any = None
    preflight: Preflight | None = None
    reference: Reference | None = None
    cuts: tuple[tuple[tuple[float, float], ...], ...] = ()
    title: str = "agvdyn identification report"
    plan: ExcitationPlan | None = None
    plan_notes: tuple[str, ...] = ()
    contents: ReportContents | None = None
    tracking: Any = None  # agvdyn.report.track_section.TrackSection: the "Payload tracking" section (issue 31)
    models: Any = None  # agvdyn.report.model_section.ModelSection: the "Model" section (issue 30)

    def __post_init__(self) -> None:
        if self.contents is None:  # every number and figure input, computed once here
            object.__setattr__(self, "contents", contents_of(self))

    @property
    def parameter_table(self):
        """:func:`parameter_table` against the report's reference (None: no identification)."""
        return self.contents.parameter_table

    def to_json_dict(self) -> dict[str, Any]:
        """What ``agvdyn report --json`` prints."""
        out: dict[str, Any] = self.verdict.to_dict()
        out["reference"] = None if self.reference is None else self.reference.label
        out["identification"] = None if self.identification is None else self.identification.to_json_dict()
        out["validation"] = None if self.validation is None else self.validation.to_json_dict()
        out["refusal"] = None if self.refusal is None else str(self.refusal)
        out["provenance"] = self.provenance.to_dict()
        out["plan"] = None if self.plan is None else self.plan.to_dict()
        if self.models is not None:
            out["models"] = self.models.to_dict()
        return out


def _version() -> str:
    from agvdyn import __version__

    return __version__


def _warnings(identification: Identification, reference: Reference | None, validation: Any,
                    checked: Preflight | None, max_nrmse: float) -> list[str]:
    reasons = list(identification.warnings)
    if reference is not None:
        table = parameter_table(identification, reference)
        for name, row in table.iterrows():
            if row["ok"] is False:
                unit = PARAMETER_UNITS[name]
                sigmas = row["deviation_in_std"]
                in_std = f", {sigmas:,.0f} std" if sigmas >= 100 else f", {sigmas:.2g} std" if sigmas == sigmas else ""
                reasons.append(f"{name} = {row['value']:.4g} {unit} is {row['deviation_pct']:+.1f} %{in_std} away from "
                               f"the {reference.label} ({row['reference']:.4g} {unit}): more than 5 % and 3 std")
    if validation is not None:
        for key, value in validation.nrmse_moving.items():
            if value == value and value > max_nrmse:
                reasons.append(f"the model predicts {key} of the validation log with NRMSE {value:.2f} without "
                               f"stiction rows (above {max_nrmse:g}): check the model or the validation log")
    if checked is not None:
        weak = [e for e in checked.excitation if e.status in ("weak", "not excited")]
        if weak:
            reasons.append("the pre-flight check rates " + ", ".join(f"{e.name} {e.status}" for e in weak) +
                           "; record: " + "; ".join(sorted({e.excited_by for e in weak})))
    return reasons


def _grouped(dependencies: Sequence[Any]) -> list[str]:
    """Refusal reasons, one line per (what is wrong, which experiment excites it)."""
    groups: dict[tuple[str, str], list[str]] = {}
    for d in dependencies:
        if math.isfinite(d.relative_std):
            how, item = "hardly excited", f"{d.name} (std {100 * d.relative_std:.0f} % of the value)"
        elif math.isfinite(d.inflation):
            how, item = "nearly a combination of the others", f"{d.name} (variance inflation {d.inflation:.3g})"
        elif not d.combination_of:
            how, item = "not excited at all", d.name
        else:
            how, item = f"a combination of {', '.join(d.combination_of)}", d.name
        excited_by = EXCITATION.get(d.name, "steering reversals in every segment")
        groups.setdefault((how, excited_by), []).append(item)
    return [f"{', '.join(items)}: {how}; excited by {excited_by}." for (how, excited_by), items in groups.items()]


def _refusal_summary(exc: Exception) -> tuple[str, list[str]]:
    if isinstance(exc, UnidentifiableError):
        names = [d.name for d in exc.dependencies]
        summary = (f"No parameters: the data do not determine {', '.join(names)}. Record the experiments named "
                   "below and identify again.")
        return summary, _grouped(exc.dependencies)
    if isinstance(exc, ImplausibleError):
        summary = "No parameters: the estimates are physically impossible, so the data or their signs are wrong."
        reasons = [i.describe() for i in exc.implausible]
        detail = str(exc).strip().splitlines()[-1].strip()  # the sign diagnosis: likely cause, or what to check
        if exc.cause and "likely cause" not in detail:
            detail = f"likely cause: {exc.cause}"
        if detail not in reasons:
            reasons.append(detail)
        return summary, reasons
    return f"No parameters: {exc}", []


def verdict_of(identification: Identification | None, refusal: Exception | None = None, validation: Any = None,
               reference: Reference | None = None, checked: Preflight | None = None, *,
               max_nrmse: float = MAX_VALIDATION_NRMSE) -> Verdict:
    """The verdict: refused (with the refusal's reasons), identified with warnings (the
    identification's warnings, parameters off the reference by more than 5 % and 3 std, a
    validation NRMSE without stiction rows above ``max_nrmse``, weak excitation in the pre-flight
    check), or identified."""
    if identification is None:
        summary, reasons = _refusal_summary(refusal if refusal is not None else ValueError("no identification"))
        return Verdict(Outcome.REFUSED, summary, tuple(reasons))
    ident = identification
    rel = {n: ident.std[n] / abs(getattr(ident.parameters, n)) for n in ident.std if getattr(ident.parameters, n)}
    worst = max(rel, key=rel.get) if rel else None
    r = ident.rows
    summary = (f"{len(ident.std)} parameters estimated from {r.used:,} of {r.samples:,} samples "
               f"({len(ident.sources)} file{'s' if len(ident.sources) != 1 else ''})")
    if worst is not None:
        summary += f"; largest relative std {100 * rel[worst]:.2g} % ({worst})"
    summary += f"; cond = {ident.condition_number:.3g}"
    if ident.fixed:
        summary += "; fixed: " + ", ".join(f"{n} = {getattr(ident.parameters, n):g}" for n in ident.fixed)
    if ident.slip_events:
        summary += f"; {len(ident.slip_events)} wheel-slip events left out ({r.slip:,} samples)"
    reasons = _warnings(ident, reference, validation, checked, max_nrmse)
    return Verdict(Outcome.WARNINGS if reasons else Outcome.IDENTIFIED, summary + ".", tuple(reasons))


def _cuts(rows: Sequence[LogRows]) -> tuple[tuple[tuple[float, float], ...], ...]:
    """Per log the time intervals between its continuous stretches (dropouts, joined recordings), from its row pass."""
    return tuple(r.gaps for r in rows)


def _files(logs: Sequence[Any], role: str) -> list[InputFile]:
    out = []
    for log in logs:
        path = getattr(log, "path", None)
        if not path:
            continue
        out.append(input_file(role, path))
        side = sidecar_path(path)
        if side.is_file():
            out.append(input_file(f"{role} sidecar", side))
    return out


def _provenance(logs: Sequence[Any], validation_logs: Sequence[Any], geometry: Geometry, settings: Mapping[str, Any],
                extra_files: Mapping[str, str | os.PathLike], command: str | None) -> Provenance:
    import matplotlib
    import numpy
    import scipy

    files = _files(logs, "identification log") + _files(validation_logs, "validation log")
    files += [input_file(role, path) for role, path in extra_files.items() if path is not None]
    env = {"python": _platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__,
           "matplotlib": matplotlib.__version__, "system": f"{_platform.system()} {_platform.machine()}"}
    created = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    return Provenance(tuple(files), _version(), geometry.describe(), dict(settings), created, env, command)


def _settings_dict(fixed: Mapping[str, float], settings: IdentificationSettings) -> dict[str, Any]:
    return {"fixed": dict(fixed) or None, **settings.to_dict()}


def make_report(logs: Sequence[Any], geometry: Geometry, *, fixed: Mapping[str, float] = DEFAULT_FIXED,
                settings: IdentificationSettings = IdentificationSettings(), validation_log: Any = None,
                reference: Reference | None = None, extra_files: Mapping[str, str | os.PathLike] | None = None,
                command: str | None = None, max_nrmse: float = MAX_VALIDATION_NRMSE,
                title: str = "agvdyn identification report", plan: PlanFile | str | os.PathLike | None = None,
                track: bool = False, tracking: Any = None, models: str = "paper") -> Report:
    """Pre-flight, identify, validate and judge: the contents of the report.

    Parameters
    ----------
    logs : loaded identification logs (:func:`agvdyn.identification.load_logs`).
    geometry : the platform.
    fixed, settings : as :func:`agvdyn.identification.identify`.
    validation_log : a loaded validation log (or None); validated only when identified.
    reference : parameters to compare with; None: the simulator truth of a sidecar, else Table 2
        for the paper's prototype, else no comparison (:func:`choose_reference`).
    extra_files : other inputs for the provenance, ``{role: path}`` (mapping, platform, reference file).
    command : the command line, for the provenance.
    plan : the plan file the logs were driven from (:func:`agvdyn.report.plan.read_plan`); None:
        the one a simulated log's sidecar leads to, if any (:func:`agvdyn.report.plan.plan_of_logs`).
    track : also replay the logs through the payload tracker with the identified parameters
        (:func:`agvdyn.online.track`) and show m_ch, C_ch over time with the detected changes.
    tracking : a tracking result to show instead: a :class:`~agvdyn.online.TrackResult`, or the
        path of a table ``agvdyn track --out`` wrote (:func:`agvdyn.report.track_section.read_track_table`).
    models : ``"paper"`` (the paper's model) or ``"compare"``: the paper's model and its extensions
        compared (:func:`agvdyn.identification.compare_models`, scored also on ``validation_log``), the
        report's identification the chosen one's, the "Model" section the comparison (issue 30).

    A refusal (:class:`UnidentifiableError`, :class:`ImplausibleError`) gives a report with the
    verdict ``refused``; other errors (bad input) propagate.
    """
    from agvdyn.validation import validate

    val = None
    rows = row_passes(logs, geometry, settings)  # the row pass of each log, once: identify, pre-flight, cuts
    ident, refusal, compared = _identified(logs, geometry, fixed, settings, rows, models, validation_log)
    checked = preflight(logs, geometry, fixed=fixed, settings=settings, rows=rows)
    if ident is not None and validation_log is not None:
        val = validate(validation_log, ident.model_parameters, geometry, settings=settings)
    ref = choose_reference(logs, geometry, reference)
    verdict = verdict_of(ident, refusal, val, ref, checked, max_nrmse=max_nrmse)
    excitation, plan_notes = _plan(logs, geometry, plan, ident, ref)
    extra = dict(extra_files or {})
    if excitation is not None:
        extra.setdefault("plan", excitation.file.path)
    prov = _provenance(logs, [] if validation_log is None else [validation_log], geometry,
                       _settings_dict(fixed, settings), extra, command)
    return Report(verdict, prov, geometry, ident, refusal, val, checked, ref, _cuts(rows), title,
                  excitation, plan_notes, tracking=tracking_section(logs, geometry, ident, track, tracking),
                  models=compared)


def _identified(logs: Sequence[Any], geometry: Geometry, fixed: Mapping[str, float], settings: IdentificationSettings,
                rows: Sequence[LogRows], models: str, validation_log: Any) -> tuple[Any, Exception | None, Any]:
    """``(identification, refusal, model section)``: the paper's model on the row passes, or with
    ``models="compare"`` the comparison of :func:`agvdyn.identification.compare_models` and its choice."""
    if models not in REPORT_MODELS:
        raise ValueError(f"models={models!r}: expected one of {REPORT_MODELS}")
    try:
        if models == "paper":
            return identify(logs, geometry, fixed=fixed, settings=settings, rows=rows, check_rows=True), None, None
        from agvdyn.identification import compare_models
        from agvdyn.validation import validation_score

        score = None if validation_log is None else functools.partial(validation_score, validation_log, settings=settings)
        selection = compare_models(list(logs), geometry, fixed=fixed, settings=settings, validation=score)
        return selection.identification, None, model_section(selection)
    except (UnidentifiableError, ImplausibleError) as exc:
        return None, exc, None


def _plan(logs: Sequence[Any], geometry: Geometry, plan: PlanFile | str | os.PathLike | None,
          ident: Identification | None, ref: Reference | None) -> tuple[ExcitationPlan | None, tuple[str, ...]]:
    """The excitation plan, its predicted std relative to the identified values (else the reference)."""
    if ident is not None:
        return excitation_plan(logs, geometry, plan, parameters=ident.parameters,
                               parameters_label="the identified values")
    if ref is not None:
        return excitation_plan(logs, geometry, plan, parameters=ref.parameters, parameters_label=ref.label)
    return excitation_plan(logs, geometry, plan)


def report_of(identification: Identification, validation: Any = None, *, reference: Reference | None = None,
              logs: Sequence[Any] = (), validation_logs: Sequence[Any] = (), checked: Preflight | None = None,
              extra_files: Mapping[str, str | os.PathLike] | None = None, command: str | None = None,
              title: str = "agvdyn identification report", max_nrmse: float = MAX_VALIDATION_NRMSE,
              plan: PlanFile | str | os.PathLike | None = None, track: bool = False, tracking: Any = None,
              selection: Any = None) -> Report:
    """A report of results computed elsewhere (Python API, ``make demo``): the verdict from them; the
    data-quality section only when the identification ``logs`` (loaded) or a pre-flight ``checked``
    are given; ``reference`` None: no comparison (see :func:`choose_reference`); ``plan``, ``track``
    (with ``logs``) and ``tracking`` as :func:`make_report` (``plan`` found by the sidecars of ``logs``
    when None); ``selection``: a :class:`~agvdyn.identification.ModelSelection` for the "Model" section."""
    geometry, settings = identification.geometry, identification.settings
    fixed = {n: getattr(identification.parameters, n) for n in identification.fixed}
    logs = list(logs)
    if checked is None and logs:  # the row pass of each log, once: pre-flight and cuts
        checked = preflight(logs, geometry, fixed=fixed, settings=settings)
    verdict = verdict_of(identification, None, validation, reference, checked, max_nrmse=max_nrmse)
    extra = dict(extra_files or {})
    if not logs:  # at least the names the identification recorded
        extra.update({f"identification log {i + 1}": s for i, s in enumerate(identification.sources)
                      if s and s != "<log>"})
    excitation, plan_notes = _plan(logs, geometry, plan, identification, reference)
    if excitation is not None:
        extra.setdefault("plan", excitation.file.path)
    prov = _provenance(logs, validation_logs, geometry, _settings_dict(fixed, settings), extra, command)
    return Report(verdict, prov, geometry, identification, None, validation, checked, reference,
                  _cuts([f.rows for f in checked.files]) if logs else (), title, excitation, plan_notes,
                  tracking=tracking_section(logs, geometry, identification, track, tracking),
                  models=None if selection is None else model_section(selection))


def command_line() -> str:
    """The running program's command line, for the provenance."""
    return " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])
