"""Rich tables that never cut a number.

Rich fits a table to the terminal by wrapping its cells and, when that is not enough, by
cutting them with an ellipsis (``0.004…``): a reader then sees a wrong number. A
:class:`WholeTable` chooses, at render time and for the width it is given (a terminal's, or
80 columns when piped), the first layout whose cells all fit whole:

1. the table as built;
2. a narrower layout of the same numbers, where its builder gives one (Table 2 transposed: a
   row per parameter);
3. one record per row: the row's first cell as a heading, then each other column as a
   ``header  value`` line, values folded over lines only if a single value is wider than the
   whole width (folded, never cut).
"""

from __future__ import annotations

from rich.console import Console, ConsoleOptions, RenderResult
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text

#: wide enough for any table bcad builds: a table's natural width is measured within it
UNBOUNDED = 1 << 16


def natural_width(table: Table, console: Console, options: ConsoleOptions) -> int:
    """The width a table takes with every cell on one line (rich's maximum measurement)."""
    return Measurement.get(console, options.update(width=UNBOUNDED, max_width=UNBOUNDED), table).maximum


def _plain(cell: object) -> str:
    return cell.plain if isinstance(cell, Text) else str(cell)


def records(table: Table, keys: int = 1) -> Table:
    """The rows of ``table`` as records: a heading per row (its first ``keys`` cells, an empty
    one standing for the one above it), then a ``header  value`` line per other column."""
    columns = table.columns
    cells = [list(column.cells) for column in columns]
    headers = [_plain(column.header) for column in columns]
    out = Table(title=table.title, caption=table.caption, show_header=False, box=table.box, show_lines=False)
    out.add_column("field", no_wrap=True)
    out.add_column("value", overflow="fold")
    heading = [""] * keys
    for row in range(table.row_count):
        for k in range(keys):
            text = _plain(cells[k][row]).strip()
            if text:
                heading[k] = text
        out.add_row(Text(" ".join(part for part in heading if part), style="bold"), "")
        for k in range(keys, len(columns)):
            out.add_row(Text(headers[k]), cells[k][row])
        out.add_section()
    return out


class WholeTable:
    """A table rendered in the first layout whose every cell fits whole (module docstring)."""

    def __init__(self, table: Table, narrow: Table | None = None, keys: int = 1):
        self.table = table
        self.narrow = narrow
        #: the leading columns that name a row of the narrowest table (the records' headings)
        self.keys = keys

    def layouts(self) -> list[Table]:
        return [t for t in (self.table, self.narrow) if t is not None]

    def choose(self, console: Console, options: ConsoleOptions) -> Table:
        """The layout for ``options.max_width`` columns."""
        for table in self.layouts():
            if natural_width(table, console, options) <= options.max_width:
                return table
        return records(self.narrow or self.table, self.keys)

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        yield self.choose(console, options)

    def __rich_measure__(self, console: Console, options: ConsoleOptions) -> Measurement:
        return Measurement.get(console, options, self.choose(console, options))
