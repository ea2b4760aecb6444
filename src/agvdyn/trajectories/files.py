"""User trajectories from files: CSV sample by sample, YAML segment by segment (docs/simulation.md)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agvdyn._lazy import pandas as pd  # trajectory files only: the built-in experiments need neither pandas
# nor scipy.interpolate (imported where a file is read), ~0.4 s of every simulate's start-up

from agvdyn.kinematics import (
    MODE_TOLERANCE,
    Mode,
    check_mode,
    max_virtual_angle,
    nominal_steering,
    steering_from_virtual,
    virtual_from_steering,
)
from agvdyn.platform import PROTOTYPE, SAMPLE_TIME, Geometry
from agvdyn.trajectories.errors import TrajectoryError
from agvdyn.trajectories.experiments import lane_change
from agvdyn.trajectories.fourier import FourierSeries
from agvdyn.trajectories.segments import CONTINUITY_TOLERANCE, Segment, Trajectory, _grid, alignment, fourier_segment

__all__ = ["read_trajectory"]


_CSV_COORD = {Mode.CAR_LIKE: "x_ch", Mode.STRAIGHT: "x_ch", Mode.LATERAL: "y_ch", Mode.ROTATION: "gamma_ch"}


def read_trajectory(path: str | os.PathLike, geom: Geometry = PROTOTYPE, *, dt: float = SAMPLE_TIME,
                    tolerance: float = MODE_TOLERANCE) -> Trajectory:
    """Read a user trajectory (CSV sample by sample, or YAML segment by segment); see docs/simulation.md.

    CSV columns: ``t`` (s, increasing), ``mode`` (1, 2, 3, 4 or 2s/straight), ``alpha_l``, ``alpha_r``
    (rad), and the chassis coordinate the mode needs: ``x_ch`` (modes 2 and straight, m),
    ``y_ch`` (mode 3, m), ``gamma_ch`` (mode 4, rad); optional ``segment``. Consecutive rows of one
    mode and segment form a segment; each is interpolated by cubic splines onto the grid of ``dt``,
    which gives the derivatives. The file is never modified.

    YAML: ``segments:`` a list of ``{name, mode, fourier: {base_frequency, a, b}}`` (mode 1:
    ``fourier: {alpha_l: {...}, alpha_r: {...}}``; mode 2: ``fourier: {alpha_v: {...}, x_ch: {...}}``), ``{name: align, to: [alpha_l, alpha_r]}`` or
    ``{name: lane_change, speed, offset, length, ...}`` (the arguments of :func:`lane_change`).
    """
    path = Path(path)
    if not path.exists():
        raise TrajectoryError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _read_csv_trajectory(path, geom, dt, tolerance)
    if suffix in (".yaml", ".yml"):
        return _read_yaml_trajectory(path, geom, dt)
    raise TrajectoryError(f"{path}: unknown trajectory format {suffix!r}: expected .csv, .yaml or .yml")


def _read_csv_trajectory(path: Path, geom: Geometry, dt: float, tolerance: float) -> Trajectory:
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise TrajectoryError(f"{path}: cannot be read as CSV: {exc}") from exc
    for col in ("t", "mode", "alpha_l", "alpha_r"):
        if col not in frame.columns:
            raise TrajectoryError(f"{path}: missing column {col!r}: expected t, mode, alpha_l, alpha_r "
                                  "and x_ch / y_ch / gamma_ch as the modes need")
    try:
        modes = [Mode.from_label(m) for m in frame["mode"].astype(str)]
    except ValueError as exc:
        bad = next(i for i, m in enumerate(frame["mode"].astype(str)) if not _is_mode(m))
        raise TrajectoryError(f"{path}: column 'mode', row {bad + 2}: {exc}") from exc
    names = frame["segment"].astype(str).tolist() if "segment" in frame.columns else [
        {Mode.PARKING: "align", Mode.CAR_LIKE: "lane_change", Mode.LATERAL: "lateral",
         Mode.ROTATION: "rotation", Mode.STRAIGHT: "straight"}[m] for m in modes]
    t = _csv_numbers(path, frame, "t")
    if np.any(np.diff(t) <= 0):
        row = int(np.argmax(np.diff(t) <= 0)) + 1
        raise TrajectoryError(f"{path}: column 't', row {row + 2}: t = {t[row]} is not after {t[row - 1]}: "
                              "expected strictly increasing times")
    alpha = np.stack([_csv_numbers(path, frame, "alpha_l"), _csv_numbers(path, frame, "alpha_r")], axis=1)
    keys = list(zip(modes, names))
    starts = [0] + [i for i in range(1, len(keys)) if keys[i] != keys[i - 1]] + [len(keys)]
    segs = []
    for a, b in zip(starts[:-1], starts[1:]):
        mode, name = keys[a]
        if b - a < 4:
            raise TrajectoryError(f"{path}: rows {a + 2}-{b + 1} (segment {name!r}, mode {mode.label}): "
                                  "expected at least 4 rows per segment for the spline")
        try:
            check_mode(geom, mode, alpha[a:b], tolerance)
        except ValueError as exc:
            raise TrajectoryError(f"{path}: rows {a + 2}-{b + 1}: {exc}") from exc
        tt = t[a:b] - t[a]
        grid = _grid(tt[-1] + dt, dt)
        grid = grid[grid <= tt[-1] + 1e-12]
        if mode is Mode.PARKING:
            coords = alpha[a:b]
        elif mode is Mode.CAR_LIKE:
            coords = np.column_stack([virtual_from_steering(geom, alpha[a:b]), _csv_numbers(path, frame, "x_ch")[a:b]])
        else:
            coords = _csv_numbers(path, frame, _CSV_COORD[mode])[a:b, None]
        from scipy.interpolate import CubicSpline

        spline = CubicSpline(tt, coords, axis=0)
        s, sd, sdd = spline(grid), spline(grid, 1), spline(grid, 2)
        if mode is Mode.PARKING:
            al = s
        elif mode is Mode.CAR_LIKE:
            al = steering_from_virtual(geom, np.clip(s[:, 0], -max_virtual_angle(geom), max_virtual_angle(geom)))
        else:
            al = np.tile(nominal_steering(geom, mode), (len(grid), 1))
        try:
            segs.append(Segment(name, mode, grid, al, s, sd, sdd))
        except TrajectoryError as exc:
            raise TrajectoryError(f"{path}: rows {a + 2}-{b + 1}: {exc}") from exc
    return Trajectory(tuple(segs), geom, dt, path.stem)


def _is_mode(label: str) -> bool:
    try:
        Mode.from_label(label)
        return True
    except ValueError:
        return False


def _csv_numbers(path: Path, frame: pd.DataFrame, col: str) -> np.ndarray:
    if col not in frame.columns:
        raise TrajectoryError(f"{path}: missing column {col!r}, needed by the modes in the file")
    values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad))
        raise TrajectoryError(f"{path}: column {col!r}, row {row + 2}: {frame[col].iloc[row]!r}: expected a finite number")
    return values


def _series_from(path: Path, where: str, spec: Any) -> FourierSeries:
    if not isinstance(spec, dict) or "base_frequency" not in spec or "a" not in spec or "b" not in spec:
        raise TrajectoryError(f"{path}: {where}: expected a mapping with base_frequency, a, b")
    try:
        return FourierSeries.at_rest(float(spec["base_frequency"]), spec["a"], spec["b"], float(spec.get("start", 0.0)),
                                     peak_velocity=spec.get("peak_velocity"))
    except (TypeError, ValueError) as exc:
        raise TrajectoryError(f"{path}: {where}: {exc}") from exc


def _read_yaml_trajectory(path: Path, geom: Geometry, dt: float) -> Trajectory:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise TrajectoryError(f"{path}: cannot be read as YAML: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get("segments"), list) or not data["segments"]:
        raise TrajectoryError(f"{path}: expected a mapping with a non-empty list 'segments'")
    segs: list[Segment] = []
    alpha_now = np.zeros(2)
    for i, spec in enumerate(data["segments"]):
        where = f"segments[{i}]"
        if not isinstance(spec, dict) or "name" not in spec:
            raise TrajectoryError(f"{path}: {where}: expected a mapping with a 'name'")
        name = str(spec["name"])
        try:
            if name == "align":
                target = np.asarray(spec.get("to", alpha_now), dtype=float)
                seg = alignment(alpha_now, target, pause=float(spec.get("pause", 0.5)),
                                rate=float(spec.get("rate", 0.8)),
                                acceleration=float(spec.get("acceleration", 2.0)), dt=dt)
            elif name == "lane_change" and "fourier" not in spec:
                keys = {"speed", "offset", "length", "acceleration", "straight_before", "straight_after"}
                unknown = set(spec) - keys - {"name", "mode"}
                if unknown:
                    raise TrajectoryError(f"unknown keys {sorted(unknown)}: expected some of {sorted(keys)}")
                seg = lane_change(geom, dt=dt, **{k: float(v) for k, v in spec.items() if k in keys}).segments[0]
            else:
                mode = Mode.from_label(spec.get("mode", ""))
                four = spec.get("fourier")
                if mode is Mode.PARKING:
                    if not isinstance(four, dict):
                        raise TrajectoryError("mode 1 needs fourier: {alpha_l: {...}, alpha_r: {...}}")
                    parts = []
                    for side, j in (("alpha_l", 0), ("alpha_r", 1)):
                        parts.append(_series_from(path, f"{where}.fourier.{side}", four[side]) if side in four else None)
                    ref = next(p for p in parts if p is not None)
                    parts = [p or FourierSeries(ref.base_frequency, (0.0,) * len(ref.a), (0.0,) * len(ref.a),
                                                float(alpha_now[j])) for j, p in enumerate(parts)]
                    seg = fourier_segment(name, mode, (parts[0], parts[1]), geom=geom, dt=dt)
                elif mode is Mode.CAR_LIKE:
                    if not isinstance(four, dict) or set(four) != {"alpha_v", "x_ch"}:
                        raise TrajectoryError("mode 2 needs fourier: {alpha_v: {...}, x_ch: {...}} (the virtual "
                                              "steering angle from where the previous segment ends, and the travel)")
                    av = _series_from(path, f"{where}.fourier.alpha_v", four["alpha_v"])
                    av = FourierSeries(av.base_frequency, av.a, av.b, float(virtual_from_steering(geom, alpha_now)[0]))
                    seg = fourier_segment(name, mode, (av, _series_from(path, f"{where}.fourier.x_ch", four["x_ch"])),
                                          geom=geom, dt=dt)
                else:
                    seg = fourier_segment(name, mode, _series_from(path, f"{where}.fourier", four), geom=geom, dt=dt)
        except (TrajectoryError, ValueError, KeyError, StopIteration) as exc:
            raise TrajectoryError(f"{path}: {where} ({name}): {exc}") from exc
        if np.max(np.abs(seg.alpha[0] - alpha_now)) > CONTINUITY_TOLERANCE:
            raise TrajectoryError(
                f"{path}: {where} ({name}) starts at alpha = ({seg.alpha[0, 0]:.6g}, {seg.alpha[0, 1]:.6g}) but the "
                f"previous segment ends at ({alpha_now[0]:.6g}, {alpha_now[1]:.6g}): insert an 'align' segment")
        alpha_now = seg.alpha[-1].copy()
        segs.append(seg)
    return Trajectory(tuple(segs), geom, dt, path.stem)

