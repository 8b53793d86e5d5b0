"""Reading a table of measurements: CSV, whitespace-separated text with a header line, or ``.npz``.

    table = read_table("pendulum.csv")          # Table: names, values (rows, columns), where
    table.column("x", "--q")                    # one column (rows,), or one error: line naming the fix

Text (``.csv``, ``.txt``, anything not ``.npz``): the first non-blank line names the columns,
optionally after a leading ``%`` or ``#`` (as MATLAB and gnuplot write them); the cells are
separated by commas if the header has one, else by whitespace. Later lines starting with ``%``
or ``#`` are comments. A header that names neither ``trial`` nor ``t`` is read as Schmidt &
Lipson's archive (``invar_datasets.zip``) writes its files, when the rows hold two more cells than
it names (``% x v`` over trial, t, x, v: the two unnamed leading columns are ``trial`` and ``t``),
or two more and then as many again (``% o v`` over trial, t, o, v, do/dt, dv/dt: the unnamed
trailing columns are the archive's own finite-difference derivatives of the named ones, in order,
named ``d<name>/dt``; ``Table.notes`` says so, and nothing uses them unless ``--dxdt`` names
them). Any other count of cells is refused with the header line to write. ``.npz``: every array
of the archive is a column, all 1-D and of one length.

Every malformed input raises ``ValueError`` with one line: the file, the line (text) or row
(npz), the column, the value and what to do; a value too large for the arithmetic (its square summed
over the column overflows float64) is one too.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ARCHIVE_COLUMNS = ("trial", "t")     # the unnamed leading columns of Schmidt & Lipson's files
COMMENTS = ("%", "#")


@dataclass
class Table:
    """A table read from ``path``: column ``names`` and float64 ``values`` ``(rows, columns)``;
    ``lines`` ``(rows,)`` are where each row sits in the file, counted in ``unit`` ("line" or "row");
    ``notes``: one line each about how the file was read (the archive's unnamed columns)."""
    path: str
    names: list[str]
    values: np.ndarray
    lines: np.ndarray
    unit: str = "line"
    notes: list[str] = field(default_factory=list)

    def where(self, row: int) -> str:
        """Where data row ``row`` (0-based) is in the file, e.g. ``'line 12'``."""
        return f"{self.unit} {int(self.lines[row])}"

    def column(self, name: str, flag: str) -> np.ndarray:
        """Column ``name`` ``(rows,)``, finite everywhere; ``flag`` is the option that named it (for the fix)."""
        if name not in self.names:
            close = difflib.get_close_matches(name, self.names, n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ValueError(f"{self.path}: {flag} names the column {name!r}, which the file does not have (its "
                             f"columns: {', '.join(self.names)}){hint} Fix the name in {flag}")
        values = self.values[:, self.names.index(name)]
        bad = np.flatnonzero(~np.isfinite(values))
        if len(bad):
            row = bad[0]
            raise ValueError(f"{self.path}: {self.where(row)}, column {name!r}: the value is {values[row]} (NaN or "
                             f"infinite; {len(bad)} such cells in that column); remove or fill those rows")
        # the scaling sums the squares of a column (its RMS): past this size they overflow float64
        largest = float(np.sqrt(np.finfo(np.float64).max / max(len(values), 1)))
        huge = np.flatnonzero(np.abs(values) > largest)
        if len(huge):
            row = huge[0]
            raise ValueError(f"{self.path}: {self.where(row)}, column {name!r}: the value {values[row]:g} is too large "
                             f"for the arithmetic (the sum of the squares of the column's {len(values)} values "
                             f"overflows float64 past {largest:.3g}; {len(huge)} such cells in that column); fix or "
                             "drop those rows")
        return values


def _number(cell: str, path, line: int, name: str) -> float:
    try:
        return float(cell)
    except ValueError:
        raise ValueError(f"{path}: line {line}, column {name!r}: {cell[:40]!r} is not a number; every cell "
                         "after the header must be a number (mark comment lines with % or #)") from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _header(line: str) -> tuple[list[str], str | None]:
    """The column names of a header line and its separator (``','`` or None for whitespace)."""
    text = line.lstrip("".join(COMMENTS)).strip()
    sep = "," if "," in text else None
    return [name.strip() for name in text.split(sep)], sep


def _archive_names(path, header_line: int, names: list[str], width: int, line: int,
                   sep: str | None) -> tuple[list[str], list[str]]:
    """The names of a row of ``width`` cells under the header's ``names``, and the notes on them: the
    header's own, or the archive's layouts (see the module's docstring); any other width is refused."""
    if width == len(names):
        return names, []
    named = len(names)
    if not set(ARCHIVE_COLUMNS) & set(names):
        if width == named + len(ARCHIVE_COLUMNS):
            return list(ARCHIVE_COLUMNS) + names, []
        derived = [f"d{name}/dt" for name in names]
        if width == 2 * named + len(ARCHIVE_COLUMNS) and not set(derived) & set(names):
            return list(ARCHIVE_COLUMNS) + names + derived, [
                f"{path}: the rows hold {width} cells under a header naming {named}: read as Schmidt & Lipson's "
                f"archive writes them, trial, t, the named columns, then d/dt of each ({', '.join(derived)}; the "
                "archive's own estimates, used only if --dxdt names them)"]
    lead = [] if set(ARCHIVE_COLUMNS) & set(names) or width < named + 2 else list(ARCHIVE_COLUMNS)
    write = (lead + names + [f"c{i}" for i in range(len(lead) + named + 1, width + 1)])[:width]
    header = ",".join(write) if sep == "," else "% " + " ".join(write)
    raise ValueError(f"{path}: line {line}: {width} cells, but the header (line {header_line}) names {named} columns "
                     f"({', '.join(names)}); write a header naming every column in order, e.g. {header!r}")


def _read_text(path: Path) -> Table:
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise ValueError(f"{path}: not a UTF-8 text file ({err}); give a CSV, whitespace-separated text with a "
                         "header line, or an .npz") from None
    numbered = [(i + 1, line.strip()) for i, line in enumerate(text.splitlines()) if line.strip()]
    if not numbered:
        raise ValueError(f"{path}: the file is empty; expected a header line naming the columns (e.g. 't,x,v'), "
                         "then one row of numbers per sample")
    header_line, header = numbered[0]
    names, sep = _header(header)
    if all(_is_number(name) for name in names):
        raise ValueError(f"{path}: line {header_line}: the first line {header[:60]!r} holds numbers, not column "
                         "names; add a header line naming the columns (e.g. '% t x v')")
    if len(set(names)) != len(names) or not all(names):
        raise ValueError(f"{path}: line {header_line}: the header {header[:60]!r} has an empty or repeated column "
                         "name; name every column once")
    body = [(n, line) for n, line in numbered[1:] if not line.startswith(COMMENTS)]
    if not body:
        raise ValueError(f"{path}: the file has a header and no rows of numbers; expected one row per sample")
    names, notes = _archive_names(path, header_line, names, len(body[0][1].split(sep)), body[0][0], sep)
    rows, lines = [], []
    for number, line in body:
        cells = [cell.strip() for cell in line.split(sep)]
        if len(cells) != len(names):
            raise ValueError(f"{path}: line {number}: {len(cells)} cells, but the header names {len(names)} columns "
                             f"({', '.join(names)}); every row needs one cell per column")
        rows.append([_number(cell, path, number, name) for cell, name in zip(cells, names)])
        lines.append(number)
    return Table(str(path), names, np.asarray(rows, dtype=np.float64), np.asarray(lines), "line", notes)


def _read_npz(path: Path) -> Table:
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: not a readable .npz archive ({err}); save it with numpy.savez") from None
    with archive:
        names = list(archive.files)
        if not names:
            raise ValueError(f"{path}: the file is empty (an .npz with no arrays); save one 1-D array per column")
        arrays = [np.asarray(archive[name]) for name in names]
    for name, array in zip(names, arrays):
        if array.ndim != 1 or len(array) != len(arrays[0]) or not np.issubdtype(array.dtype, np.number):
            raise ValueError(f"{path}: array {name!r} has shape {array.shape} and dtype {array.dtype}; every array "
                             f"must be a 1-D column of numbers of one length ({len(arrays[0])} rows, as "
                             f"{names[0]!r}): save one 1-D array per column")
    if not len(arrays[0]):
        raise ValueError(f"{path}: the file is empty (its columns have no rows); expected one row per sample")
    values = np.stack([a.astype(np.float64) for a in arrays], axis=1)
    return Table(str(path), names, values, np.arange(1, len(values) + 1), "row")


def read_table(path) -> Table:
    """The table in ``path`` (see the module's docstring); ``FileNotFoundError`` if there is none."""
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file; pass the measurements with --data FILE (.csv, text with a "
                                "header line, or .npz)")
    return _read_npz(path) if path.suffix.lower() == ".npz" else _read_text(path)


def names(text: str | None) -> list[str]:
    """The column names of a comma-separated flag value ('x1,x2' -> ['x1', 'x2']); [] for none."""
    return [name.strip() for name in (text or "").split(",") if name.strip()]

