"""A command's results as records (dicts keyed by its CSV columns): the CSV file of them
and the printed table, declared as a list of columns."""

from collections.abc import Callable, Sequence
from typing import NamedTuple

from .._runtime._io import write_csv


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


class Shown(NamedTuple):
    """A column of a printed table: its header (a format string, filled in by `table`)
    and the text of its cell for a record (a dict keyed by the command's CSV columns)."""

    header: str
    cell: Callable[[dict], str]


def shown(header: str, key: str, spec: str, unit: float = 1.0) -> Shown:
    """The column that prints `record[key] / unit` with the format `spec` ("-" for
    None)."""

    def cell(record: dict) -> str:
        value = record[key]
        return "-" if value is None else format(value / unit if unit != 1.0 else value, spec)

    return Shown(header, cell)


def table(columns: Sequence[Shown], records: Sequence[dict], **header_values) -> str:
    """The printed table of `records`, one row each, in the `columns` declared."""
    return _format_table([column.header.format(**header_values) for column in columns],
                         [[column.cell(record) for column in columns] for record in records])


def save_records(output, name: str, columns: Sequence[str],
                 records: Sequence[dict]) -> None:
    """`name`, a CSV file in the output folder of `output` (an `_Output`), with a row per
    record: its values in the order `columns`, None as an empty cell."""
    write_csv(output.path(name), columns,
              [["" if record[key] is None else record[key] for key in columns]
               for record in records])


def _format_table(header: list[str], rows: list[list[str]]) -> str:
    """Columns of numbers right-aligned, columns of text left-aligned."""
    columns = list(zip(header, *rows, strict=True))
    widths = [max(len(cell) for cell in column) for column in columns]
    numeric = [all(_is_number(cell) for cell in column[1:]) for column in columns]
    lines = [
        "  ".join(
            cell.rjust(width) if right else cell.ljust(width)
            for cell, width, right in zip(row, widths, numeric, strict=True)
        ).rstrip()
        for row in [header, *rows]
    ]
    lines.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(lines)
