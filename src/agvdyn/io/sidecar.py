"""YAML sidecars of logs, parsed when first needed.

A sidecar of the simulator holds a few hundred values (settings, tracking figures); parsing them
costs ~3 ms per log, more than reading the log's 35,500 rows, while an identification needs two
entries (``platform``, ``torque_lead``). A sidecar whose text is a plain block mapping (every
line at column 0 a key, a ``- `` item of the key above, blank or a comment; no quotes, anchors or
aliases; brackets balanced on each line) is kept as text: :meth:`LazySidecar.get` parses the one
top-level entry asked for, and the whole text is parsed the first time ``Log.sidecar`` is used.
Any other text is parsed when the log is read, as before.
"""
from __future__ import annotations

import copy
import functools
import re
from pathlib import Path
from typing import Any

import yaml

from agvdyn.io.schema import LogError

__all__ = ["LazySidecar", "parse_sidecar", "sidecar_text"]

#: libyaml's parser when PyYAML has it: ~10x faster than the pure-Python one
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_KEY = re.compile(r"([A-Za-z_][\w.-]*):(?:[ \r\n]|$)")


def parse_sidecar(text: str, where: Path | str) -> dict[str, Any]:
    """The mapping of a sidecar's text; LogError naming ``where`` when it is not YAML or not a mapping."""
    try:
        data = yaml.load(text, Loader=_LOADER)
    except yaml.YAMLError as exc:
        raise LogError(f"{where}: sidecar is not valid YAML: {exc}") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise LogError(f"{where}: sidecar must hold a mapping at the top level, found {type(data).__name__}")
    return data


#: A line at column 0 that starts a top-level entry: not blank, indented, a comment or a ``-`` item.
_TOP_LINE = re.compile(r"^(?!$|[ #]|-(?: |$))[^\n]*", re.M)
#: Characters that end a line for ``str.splitlines`` besides "\n", quotes, anchors, aliases and tabs:
#: a text holding any of them is parsed whole.
_NOT_PLAIN = "\"'&*\t\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"


def _entries(text: str) -> dict[str, str] | None:
    """The text of each top-level entry of a plain block mapping (see the module docstring), None
    for any other text. A regular expression over the whole text finds the entries, not a Python
    loop over its lines (a simulator's sidecar has ~200 lines and is read with every log)."""
    if any(c in text for c in _NOT_PLAIN):
        return None
    lines = text.split("\n")
    for line in (x for x in lines if "[" in x or "]" in x or "{" in x or "}" in x):
        if line.count("[") != line.count("]") or line.count("{") != line.count("}"):
            return None
    starts = [m.start() for m in _TOP_LINE.finditer(text)]
    if not starts or any(line.strip() and not line.startswith("#") for line in text[:starts[0]].split("\n")):
        return None
    entries: dict[str, str] = {}
    for a, e in zip(starts, starts[1:] + [len(text)]):
        match = _KEY.match(text, a)
        if match is None or match.group(1) in entries:
            return None
        entries[match.group(1)] = text[a:e]
    return entries


class LazySidecar:
    """A sidecar kept as text (see the module docstring): :meth:`get` one entry, :meth:`parse` all."""

    def __init__(self, text: str, entries: dict[str, str], where: Path | str) -> None:
        self.text, self.where, self._entries = text, where, entries
        self._scalars: dict[str, Any] = {}  # entries already parsed that hold a number, string or bool

    def parse(self) -> dict[str, Any]:
        return parse_sidecar(self.text, self.where)

    def get(self, key: str, default: Any = None) -> Any:
        """The value of the top-level entry ``key`` (``default`` without it), parsing that entry only."""
        if key in self._scalars:  # asked once per stretch (torque_lead): parsed once
            return self._scalars[key]
        chunk = self._entries.get(key)
        if chunk is None:
            return default
        try:
            data = _entry(chunk)
        except yaml.YAMLError:
            return self.parse().get(key, default)
        if not isinstance(data, dict) or list(data) != [key]:  # e.g. a key YAML reads as a bool
            return self.parse().get(key, default)
        if data[key] is None or isinstance(data[key], (bool, int, float, str)):  # immutable: safe to share
            self._scalars[key] = data[key]
            return data[key]
        return copy.deepcopy(data[key])  # the cached parse is shared between logs


@functools.lru_cache(maxsize=256)
def _entry(chunk: str) -> Any:
    """One entry's text parsed, kept for the next log whose sidecar holds the same text (the logs of
    one vehicle repeat ``platform`` and ``torque_lead``: ~0.1 ms of YAML each, under the GIL)."""
    return yaml.load(chunk, Loader=_LOADER)


def sidecar_text(path: Path) -> dict[str, Any] | LazySidecar:
    """The sidecar at ``path``: ``{}`` when there is none, kept as text when it is a plain block
    mapping, else parsed (errors raised now)."""
    if not path.exists():
        return {}
    text = path.read_text(encoding="utf-8")
    entries = _entries(text)
    if entries is None or not entries:
        return parse_sidecar(text, path)
    return LazySidecar(text, entries, path)
