"""A module imported on first use of one of its attributes (``pd.DataFrame``), for libraries that
only some commands need: pandas costs ~0.4 s of start-up, and identifying logs in our own
schema never touches it (they are read with pyarrow straight into numpy)."""
from __future__ import annotations

import importlib
from typing import Any

__all__ = ["LazyModule", "pandas"]


class LazyModule:
    """Stands for the module ``name``: any attribute access imports it (once) and returns its attribute."""

    def __init__(self, name: str) -> None:
        self._name = name

    def __getattr__(self, attribute: str) -> Any:
        return getattr(importlib.import_module(self._name), attribute)

    def __repr__(self) -> str:
        return f"<lazy module {self._name!r}>"


pandas: Any = LazyModule("pandas")
