"""Command-line interface: parses arguments and calls the library; no numerics here."""
from __future__ import annotations

from agvdyn.cli._app import app

# Each command module registers itself on ``app`` when imported.
from agvdyn.cli import model_commands  # noqa: E402,F401
from agvdyn.cli import io_commands  # noqa: E402,F401
from agvdyn.cli import identify_commands  # noqa: E402,F401
from agvdyn.cli import sim_commands  # noqa: E402,F401
from agvdyn.cli import inspect_command  # noqa: E402,F401
from agvdyn.cli import study_commands  # noqa: E402,F401
from agvdyn.cli import batch_commands  # noqa: E402,F401
from agvdyn.cli import plan_commands  # noqa: E402,F401
from agvdyn.cli import export_commands  # noqa: E402,F401
from agvdyn.cli import track_commands  # noqa: E402,F401


def main() -> None:
    from agvdyn._memory import keep_freed_memory

    keep_freed_memory(trim=256 << 20, top_pad=64 << 20)  # before anything is allocated; the library's call then keeps it
    app()
