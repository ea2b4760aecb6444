"""The model options of ``agvdyn identify`` (issue 30): ``--model paper|auto|FILE``, ``--compare-models``,
``--delay-range``, ``--stribeck-range``, ``--validation``; parsing them and calling the library's
search (:func:`agvdyn.identification.model_search.identify_model`) and comparison
(:func:`agvdyn.identification.selection.compare_models`), and the comparison's table.

Nothing here runs for ``--model paper`` without ``--compare-models``: that path stays the paper's.
"""
from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from agvdyn.cli import _defaults as D
from agvdyn.cli._app import fail
from agvdyn.cli._tables import Column, print_items, print_table

ModelOpt = Annotated[str, typer.Option(
    "--model", help="paper (the paper's model, default), auto (each extension kept only when it lowers both BIC "
                    "and the held-out error; docs/identification.md) or FILE: a YAML/JSON file (or a parameter file) "
                    "with a model: block (friction paper|stribeck, delay SECONDS|auto, com_offset true|false).")]
CompareOpt = Annotated[bool, typer.Option(
    "--compare-models", help="Also fit the paper model, each extension alone and all together and print residual "
                             "RMS, held-out NRMSE, validation NRMSE (--validation), BIC and auto's choice.")]
DelayRangeOpt = Annotated[Optional[str], typer.Option(
    "--delay-range", metavar="LO,HI",
    help=f"Seconds within which a delay 'auto' is searched (default {D.DELAY_RANGE[0]:g},{D.DELAY_RANGE[1]:g}).")]
StribeckRangeOpt = Annotated[Optional[str], typer.Option(
    "--stribeck-range", metavar="LO,HI",
    help=f"rad/s within which unknown Stribeck velocities are searched (default "
         f"{D.STRIBECK_RANGE[0]:g},{D.STRIBECK_RANGE[1]:g}).")]
ValidationOpt = Annotated[Optional[Path], typer.Option(
    "--validation", help="Validation log not used for the fit (e.g. the lane change): its NRMSE is one more score of "
                         "--compare-models and --model auto.")]


def parse_range(option: str, text: Optional[str]) -> Optional[tuple[float, float]]:
    """``LO,HI`` as two finite numbers with LO < HI; None when not given."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise fail(f"{option} {text!r}: expected LO,HI (two numbers)") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise fail(f"{option} {text!r}: expected finite LO < HI")
    return lo, hi


def model_choice(value: str, delay_range: Optional[str], stribeck_range: Optional[str]):
    """``(spec, auto)``: the ModelSpec of ``--model`` (``paper``, or read from FILE) with the ranges
    given, and whether ``auto`` asked for the data's choice."""
    from agvdyn.model_spec import PAPER_MODEL, model_from_mapping

    ranges = {k: v for k, v in (("delay_range", parse_range("--delay-range", delay_range)),
                                ("stribeck_range", parse_range("--stribeck-range", stribeck_range))) if v is not None}
    key = value.strip().lower()
    try:
        if key in ("paper", "auto"):
            return PAPER_MODEL.replace(**ranges), key == "auto"
        return model_from_mapping(_model_block(Path(value)), f"{value}: model").replace(**ranges), False
    except ValueError as exc:
        raise fail(str(exc)) from exc


def _model_block(path: Path) -> Any:
    import yaml

    if not path.is_file():
        raise ValueError(f"--model {str(path)!r}: expected paper, auto or a YAML/JSON file with a model: block")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))  # JSON is YAML
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: cannot be read as YAML/JSON: {exc}") from None
    if not isinstance(data, dict) or "model" not in data:
        raise ValueError(f"{path}: no model: block (expected model: {{friction: ..., delay: ..., com_offset: ...}})")
    return data["model"]


def validation_score(path: Optional[Path], mapping: Optional[Path], platform: Optional[Path], settings):
    """The score of a fit on the ``--validation`` log: the mean over coordinates of
    :func:`agvdyn.validation.validate`'s NRMSE without stiction rows (the rows the fit models); None
    without the option."""
    if path is None:
        return None
    from agvdyn.identification import load_logs
    from agvdyn.validation import validation_score as score_on

    try:
        (log,) = load_logs([path], mapping=mapping, platform=platform)
    except (ValueError, OSError) as exc:
        raise fail(f"--validation: {exc}") from exc
    return functools.partial(score_on, log, settings=settings)


def search_of(model: str, compare: bool, delay_range: Optional[str], stribeck_range: Optional[str],
              validation: Optional[Path], mapping: Optional[Path], platform: Optional[Path], settings):
    """What ``identify`` runs instead of the paper's fit (:func:`modelled` with the options), or None for
    ``--model paper`` without ``--compare-models`` (the paper's path, unchanged)."""
    spec, auto = model_choice(model, delay_range, stribeck_range)
    if spec.is_paper and not (auto or compare):
        if validation is not None:
            raise fail("--validation: only with --compare-models or --model auto (validate a parameter file with "
                       "agvdyn validate)")
        return None
    score = validation_score(validation, mapping, platform, settings)
    return functools.partial(modelled, spec=spec, auto=auto, compare=compare, validation=score)


def modelled(logs: list, geometry, fixed, settings, experiment: str, workers, check_rows: bool = False, *, spec,
             auto: bool, compare: bool, validation):
    """``(identification, selection)``: the comparison (``auto`` or ``compare``; None otherwise) and
    the fit of ``spec`` (``auto``: the comparison's choice); ``check_rows``: the fit's model (resolved)
    refitted on the stick-slip rows (:func:`agvdyn.identification.pipeline.row_checked`)."""
    from agvdyn.identification.model_search import identify_model
    from agvdyn.identification.pipeline import row_checked
    from agvdyn.identification.selection import compare_models

    selection = None
    options = dict(fixed=fixed, settings=settings, experiment=experiment, workers=workers)
    if auto or compare:
        selection = compare_models(logs, geometry, validation=validation, delay_range=spec.delay_range,
                                   stribeck_range=spec.stribeck_range, **options)
    ident = selection.identification if auto else identify_model(logs, geometry, model=spec, keep_blocks=False,
                                                                 **options)
    if check_rows:
        ident = row_checked(ident, logs, geometry, fixed, None, experiment, workers, ident.model)
    return ident, selection


def with_selection(data: dict, selection) -> dict:
    """The JSON of ``identify`` with ``model_selection`` (when compared)."""
    if selection is not None:
        data["model_selection"] = selection.to_list()
    return data


def _cell(x: Optional[float], digits: int = 4) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _added(names) -> str:
    groups = {"d_s": ("d_sl", "d_sr", "d_sw"), "w_s": ("w_sl", "w_sr", "w_sw")}
    out = []
    for n in names:
        short = next((g for g, members in groups.items() if n in members), n)
        if short not in out:
            out.append(short)
    return ",".join(out) or "-"


def print_selection(console, selection) -> None:
    """The comparison's table (80 columns: the parameters added are left out first) and the choice."""
    from agvdyn.identification.selection_rows import comparison_note

    validated = any(s.nrmse_validation is not None for s in selection.scores)
    columns = [Column("model", "left"), Column("added", "left", drop=1), Column("residual RMS"),
               Column("held-out")] + ([Column("validation", drop=2)] if validated else []) + \
              [Column("BIC"), Column("chosen", "left")]
    rows = []
    for s in selection.scores:
        cells = [s.label, _added(s.parameters_added), _cell(s.residual_rms), _cell(s.nrmse_holdout)]
        cells += [_cell(s.nrmse_validation)] if validated else []
        mark = "yes" if s.chosen else ("not kept" if s.error else ("undetermined" if s.undetermined else ""))
        rows.append(cells + ["-" if not math.isfinite(s.bic) else f"{s.bic:.1f}", mark])
    print_items(console, "Model comparison", [f"(NRMSE held out: {selection.parts} parts of each segment in turn"
                + (", and on the validation log;" if validated else ";"),
                f"BIC on {selection.n_effective:,.0f} effective rows, residual correlation "
                f"{selection.correlation_steps:.3g} steps; {selection.fits} fits)"], sep=" ")
    print_table(console, "", columns, rows)
    for s in selection.scores:
        if comparison_note(s.versus_paper):
            print_items(console, f"{s.label}:", [comparison_note(s.versus_paper)])
        if s.error:
            print_items(console, f"{s.label}: not kept:", [s.error.splitlines()[0]])
        elif s.undetermined:
            print_items(console, f"{s.label}: not determined by the data:", list(s.undetermined))


def print_model(console, ident, selection=None) -> None:
    """The model line and the extension's parameters (nothing for the paper's model), then the
    comparison (when there is one)."""
    spec = getattr(ident, "model", None)
    if spec is not None and not spec.is_paper:
        from agvdyn.model_spec import EXTRA_UNITS

        delay = float(spec.delay)
        print_items(console, "model:", [f"friction {spec.friction}", f"delay {1e3 * delay:.3g} ms" + (
            f" +- {_ms(ident.delay_std_s)}" if ident.delay_std_s is not None else ""),
            f"com_offset {str(spec.com_offset).lower()}"])
        if ident.extra:
            print_items(console, "model parameters:", [f"{n} = {v:.5g} +- {_cell(ident.extra_std.get(n), 3)} "
                                                       f"{EXTRA_UNITS[n]}" for n, v in ident.extra.items()])
        gained = getattr(ident, "search_std", {})
        if gained:
            most = sorted(gained, key=lambda n: -gained[n] / max(ident.std.get(n, ident.extra_std.get(n, 0.0)), 1e-300))
            print_items(console, "std include the searched values' uncertainty (its share, largest first):",
                        [f"{n} {_cell(gained[n], 2)}" for n in most[:4]])
    if selection is not None:
        print_selection(console, selection)
        chosen = selection.scores[selection.chosen]
        if chosen.fitted != spec:
            print_items(console, "auto would keep:", [f"{chosen.label};", "the parameter file holds the model of "
                                                      f"--model ({spec.label})"])


def _ms(std: Optional[float]) -> str:
    return "inf" if std is None or not math.isfinite(std) else f"{1e3 * std:.2g} ms"
