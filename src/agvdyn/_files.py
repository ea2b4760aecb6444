"""Atomic file output shared by every stage that writes files, and the check that no output
overwrites an input (:func:`check_outputs`)."""
from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path


def write_atomically(path: str | os.PathLike, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it over ``path``.

    A reader never sees a half-written file and an interrupted write leaves the old file intact.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        if tmp.is_file():  # mkstemp creates 0600; give the file the permissions of a plain open()
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return target


def write_text_atomically(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


#: Suffixes of logs and recordings (our logs and tables; ROS 2 bag files): only an output that is a log or
#: a table may carry one, so that a parameter file, a plan or a report is never taken for a recording.
LOG_SUFFIXES = (".parquet", ".csv", ".db3", ".mcap")
#: Kinds of output (``check_outputs(kinds=...)``) that are logs or tables and may carry a log's suffix.
LOG_KINDS = frozenset({"log", "table"})


class OutputPathError(ValueError):
    """An output path that would overwrite an input or another output, or a non-log output named like a log."""


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except (OSError, RuntimeError):  # a symlink loop
        return Path(os.path.abspath(path))


def _named(role: str, path: Path) -> str:
    """``--platform p.yaml`` for an option, ``run.parquet (LOG 1)`` for an argument or a derived file."""
    return f"{role} {path}" if role.startswith("-") else f"{path} ({role})"


def _same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` name one file: the same device and inode when both exist (symlinks and
    hard links included), else the same resolved path (an output not written yet)."""
    try:
        sa, sb = os.stat(a), os.stat(b)
    except OSError:
        return _resolved(a) == _resolved(b)
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def check_outputs(
    outputs: Mapping[str, str | os.PathLike | None],
    inputs: Mapping[str, str | os.PathLike | None],
    *,
    kinds: Mapping[str, str] | None = None,
) -> None:
    """Refuse outputs that would overwrite an input or each other, before any work is done.

    Parameters
    ----------
    outputs : role -> path of each file a command will write, derived ones included (``{"--out": ...,
        "sidecar of --out": ...}``); None entries are skipped.
    inputs : role -> path of each file or directory the command reads (``{"LOG 1": ..., "--platform":
        ...}``); None entries are skipped. A directory input (a ROS 2 bag) also covers every path inside it.
    kinds : role -> what the output is (``"parameter file"``, ``"log"``, ...; default ``"output"``). Only
        the kinds of ``LOG_KINDS`` may carry a suffix of ``LOG_SUFFIXES``.

    Raises
    ------
    OutputPathError
        Naming the output, its path and the input (or other output) it would overwrite, or the log's
        suffix a non-log output has.

    Examples
    --------
    >>> check_outputs({"--out": "run.parquet"}, {"LOG": "run.parquet"},
    ...               kinds={"--out": "parameter file"})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    agvdyn._files.OutputPathError: --out run.parquet: the parameter file would overwrite the input run.parquet (LOG); ...
    """
    kinds = kinds or {}
    given_outputs = [(role, Path(p)) for role, p in outputs.items() if p is not None]
    given_inputs = [(role, Path(p)) for role, p in inputs.items() if p is not None]
    for k, (role, out) in enumerate(given_outputs):
        kind, name = kinds.get(role, "output"), _named(role, out)
        for in_role, inp in given_inputs:
            if _same_file(out, inp):
                via = "" if str(out) == str(inp) else ", the same file under another name"
                raise OutputPathError(f"{name}: the {kind} would overwrite the input {_named(in_role, inp)}{via}; "
                                      f"choose another {role.split()[-1]}")
            if inp.is_dir() and _resolved(out).is_relative_to(_resolved(inp)):
                raise OutputPathError(f"{name}: the {kind} would be written inside the input directory "
                                      f"{_named(in_role, inp)}; expected a path outside it")
        for other_role, other in given_outputs[:k]:
            if _same_file(out, other):
                raise OutputPathError(f"{name}: the same file as {_named(other_role, other)}; expected two "
                                      "different files")
        if kind not in LOG_KINDS and out.suffix.lower() in LOG_SUFFIXES:
            raise OutputPathError(f"{name}: the {kind} would be written to a path with a log's suffix "
                                  f"{out.suffix!r}; expected a name not ending in {', '.join(LOG_SUFFIXES)}")
