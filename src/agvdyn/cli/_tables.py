"""Console tables and lists that fit the terminal (issue 26): values are never cut or wrapped.

The width is the console's (rich: ``COLUMNS`` when set, else the width of the terminal of stdin,
stdout or stderr, else 80: a pipe from a shell gets the terminal's width). A table that
is too wide leaves out its optional columns, in the order the caller ranks them, and says which;
when even its essential columns do not fit, each row is printed as a block of ``header  value``
lines. Full precision is in ``--json`` and the files, never here.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from rich import box
from rich.console import Console
from rich.cells import cell_len
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text

__all__ = ["Column", "print_items", "print_parameters", "print_table"]


@dataclass(frozen=True)
class Column:
    """A column: ``drop`` 0 is always shown; 1, 2, ... are left out in that order when too wide."""

    header: str
    justify: str = "right"
    drop: int = 0


def _table(columns: Sequence[Column], rows: Sequence[Sequence[str]], keep: Sequence[int]) -> Table:
    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, header_style="bold")
    for j in keep:
        table.add_column(columns[j].header, justify=columns[j].justify, no_wrap=True)  # type: ignore[arg-type]
    for row in rows:
        table.add_row(*(row[j] for j in keep))
    return table


def print_table(console: Console, title: str, columns: Sequence[Column], rows: Sequence[Sequence[str]]) -> None:
    """Print ``rows`` (cells as strings, rich markup allowed) under ``title`` within the console's width.

    Tries all columns, then without the optional ones (``drop`` 1 first, then 2, ...); the first
    layout that fits is printed, with a line naming the columns left out. When none fits, every
    row is a block: its first cell, then a ``header  value`` line per other non-empty cell.
    """
    width = console.width
    if title:
        console.print(Text(title, style="bold"))
    ranks = sorted({c.drop for c in columns if c.drop > 0})
    for n_dropped in range(len(ranks) + 1):
        gone = set(ranks[:n_dropped])
        keep = [j for j, c in enumerate(columns) if c.drop not in gone]
        table = _table(columns, rows, keep)
        # measured unconstrained: rich measures a table no wider than the width it is given
        if Measurement.get(console, console.options.update_width(1 << 16), table).maximum <= width:
            console.print(table)
            if gone:
                left_out = ", ".join(c.header for c in columns if c.drop in gone)
                console.print(Text(f"(not shown at {width} columns: {left_out}; a wider terminal shows them)",
                                   style="dim"))
            return
    label = max(len(c.header) for c in columns[1:]) if len(columns) > 1 else 0
    for row in rows:
        console.print(Text.from_markup(row[0], style="bold"))
        for c, cell in zip(columns[1:], row[1:]):
            if cell:
                console.print(Text("  " + c.header.ljust(label) + "  ") + Text.from_markup(cell))


def lines(head: str, items: Sequence[str], width: int, *, sep: str = ", ", indent: int = 2) -> list[str]:
    """``head`` and ``items`` packed into lines of at most ``width`` cells, never breaking inside an
    item (an item longer than a line gets a line of its own); continuation lines are indented."""
    out: list[str] = []
    line = head
    for k, item in enumerate(items):
        piece = item + (sep.rstrip() if k + 1 < len(items) else "")
        if not line.strip():
            line += piece
        elif cell_len(line) + 1 + cell_len(piece) <= width:
            line += " " + piece
        else:
            out.append(line)
            line = " " * indent + piece
    if line.strip():
        out.append(line)
    return out


def print_items(console: Console, head: str, items: Sequence[str], *, sep: str = ", ", indent: int = 2) -> None:
    """Print ``head item, item, ...`` within the console's width: lines break between items only."""
    for line in lines(head, items, console.width, sep=sep, indent=indent):
        console.print(line, markup=False, highlight=False)  # rich wraps only an item wider than the console


def print_parameters(console: Console, ident) -> None:
    """The parameter table of ``agvdyn identify`` (value 6, std 3, interval 5 significant digits).

    The comparison with Table 2 only for the paper's prototype; at 80 columns Table 2 itself and
    then the std of eq. 25 are left out before anything else.
    """
    import math

    from agvdyn.platform import PAPER_PARAMETERS, PARAMETER_NAMES, PARAMETER_UNITS, PROTOTYPE

    paper = ident.geometry.same_shape(PROTOTYPE)  # Table 2 belongs to the paper's prototype only
    columns = [Column("parameter", "left"), Column("value"), Column("std"), Column("95 % interval"),
               Column("std eq. 25", drop=2), Column("unit", "left")]
    if paper:
        columns += [Column("Table 2", drop=1), Column("deviation", drop=3)]
    rows = []
    for name in PARAMETER_NAMES:
        value = getattr(ident.parameters, name)
        if name in ident.fixed:
            cells = [name, f"{value:.6g}", "fixed", "", "", PARAMETER_UNITS[name]]
        else:
            low, high = ident.ci95(name)
            cells = [name, f"{value:.6g}", f"{ident.std[name]:.3g}", f"{low:.5g} .. {high:.5g}",
                     f"{ident.std_classic.get(name, math.nan):.3g}", PARAMETER_UNITS[name]]
        if paper:
            ref = getattr(PAPER_PARAMETERS, name)
            cells += [f"{ref:.6g}", f"{100 * (value / ref - 1):+.2f} %"]
        rows.append(cells)
    unc = ident.uncertainty.method if ident.uncertainty is not None else "classic"
    print_items(console, "Identified parameters", [f"({ident.estimator}, std by {unc};",
                f"cond(Theta_1w^T Theta_1w) = {ident.condition_number:.4g},", f"{ident.n_rows:,} rows)"], sep="")
    print_table(console, "", columns, rows)
