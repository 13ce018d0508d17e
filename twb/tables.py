"""Tables that fit the terminal: optional columns are left out, least important first, until the
table is as wide as the console (``--wide`` keeps every column)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Sequence

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table

__all__ = ["console", "natural_width", "print_fitted"]

#: columns of a table that is not a terminal's when COLUMNS does not say (rich's own default)
DEFAULT_WIDTH = 80


def console(wide: bool = False) -> "Console":
    """A console for stdout: the terminal's width (or ``$COLUMNS``, else 80); ``wide``: no limit."""
    from rich.console import Console

    con = Console(soft_wrap=False)
    return Console(soft_wrap=False, width=100_000) if wide else con


def natural_width(con: "Console", table: "Table") -> int:
    """Characters ``table`` takes when nothing is wrapped or squeezed."""
    from rich.measure import Measurement

    return Measurement.get(con, con.options.update(max_width=100_000), table).maximum


def print_fitted(con: "Console", build: Callable[[list[str]], "Table"], columns: Sequence[str],
                 optional: Sequence[str], wide: bool = False) -> list[str]:
    """Print ``build(kept_columns)``, leaving out ``optional`` columns (least important first) while the
    table is wider than ``con``; returns the columns left out (with a note under the table)."""
    kept, dropped = list(columns), []
    table = build(kept)
    if not wide:
        for col in optional:
            if natural_width(con, table) <= con.width:
                break
            kept.remove(col)
            dropped.append(col)
            table = build(kept)
    con.print(table)
    if dropped:
        names = ", ".join(" ".join(d.split()) for d in dropped)
        what = "1 column" if len(dropped) == 1 else f"{len(dropped)} columns"
        con.print(f"({what} left out to fit {con.width} characters: {names}; --wide shows every column)",
                  highlight=False, style="dim")
    return dropped
