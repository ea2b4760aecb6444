"""Butterworth low-pass designs (second-order sections and ``sosfilt_zi``) kept on disk per order
and normalised cut-off, so that a command whose filter was designed before does not import
scipy.signal: that import (it loads scipy.stats and scipy.interpolate too) was ~0.7 s of every
``agvdyn identify``'s start-up. The values are scipy's own, stored exactly (JSON floats round-trip
float64), in ``$AGVDYN_CACHE_DIR`` or ``$XDG_CACHE_HOME/agvdyn`` (default ``~/.cache/agvdyn``), one
file per scipy version. A cache that cannot be read or written is ignored: the design is then
computed, as without it."""
from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import numpy as np

__all__ = ["butterworth_lowpass", "cache_file"]

_LOCK = threading.Lock()
_LOADED: dict[str, tuple[list, list]] | None = None


def cache_file() -> Path | None:
    """Where the designs are kept (depends on the environment and the installed scipy); None when
    there is no absolute place for it (no home directory): designs are then not kept."""
    import scipy  # the package alone: cheap

    folder = os.environ.get("AGVDYN_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "agvdyn")
    if not os.path.isabs(folder):  # "~" unexpanded, or a relative setting: never write into the working directory
        return None
    return Path(folder) / f"butterworth-scipy-{scipy.__version__}.json"


def butterworth_lowpass(order: int, normalized_cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """``(sos, zi)``: ``scipy.signal.butter(order, normalized_cutoff, output="sos")`` and
    ``scipy.signal.sosfilt_zi(sos)``, from the disk cache when they were designed before."""
    key = f"{int(order)}:{float(normalized_cutoff)!r}"
    with _LOCK:
        found = _designs().get(key)
    if found is not None:
        sos, zi = np.array(found[0], dtype=float), np.array(found[1], dtype=float)
        if sos.shape == ((int(order) + 1) // 2, 6) and zi.shape == (sos.shape[0], 2) and np.isfinite(sos).all():
            return sos, zi
    from scipy import signal

    sos = signal.butter(order, normalized_cutoff, btype="low", output="sos")
    zi = signal.sosfilt_zi(sos)
    with _LOCK:
        _designs()[key] = (sos.tolist(), zi.tolist())
        _store(_designs())
    return sos, zi


def _designs() -> dict[str, tuple[list, list]]:
    global _LOADED
    if _LOADED is None:
        path = cache_file()
        try:
            data = json.loads(path.read_text(encoding="utf-8")) if path is not None else {}
            _LOADED = data if isinstance(data, dict) else {}
        except (OSError, ValueError):
            _LOADED = {}
    return _LOADED


def _store(designs: dict[str, tuple[list, list]]) -> None:
    from agvdyn._files import write_text_atomically

    path = cache_file()
    if path is None:
        return
    try:
        write_text_atomically(path, json.dumps(designs))
    except OSError:  # read-only home, full disk: designed again next time
        pass
