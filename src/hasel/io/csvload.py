"""Columns out of CSV and MATLAB (.mat v5) files, tolerant of how real datasets are written.

CSV: the delimiter (comma, tab, semicolon or whitespace) and whether the first row is a
header are detected; quoted names, a trailing delimiter and an unnamed index column are
fine. A column is named by its header text (case-insensitive if unambiguous) or by its
0-based position (the only way for a file without a header). Only the requested
columns are parsed; an empty or non-numeric cell in one of them is an error that names
its line and column.

MAT: variables are read with :func:`scipy.io.loadmat`; an ``N x 1`` (or ``1 x N``)
numeric variable is a column.
"""
from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hasel.errors import BadInputError, DataFileError

__all__ = ["Table", "read_csv_table", "read_mat_table"]


@dataclass
class Table:
    """Named numeric columns of a file.

    Attributes
    ----------
    source : Path
        The file.
    names : list of str
        Column names (``"0"``, ``"1"``... for a file without a header).
    has_header : bool
        Whether names came from a header row.
    """

    source: Path
    names: list[str]
    has_header: bool
    _columns: dict[str, np.ndarray]
    label: str = "column"

    def resolve(self, spec: str) -> str | None:
        """The column name ``spec`` refers to (exact, case-insensitive, or 0-based index), or None."""
        s = str(spec).strip()
        if s in self.names:
            return s
        low = [n for n in self.names if n.lower() == s.lower()]
        if len(low) == 1:
            return low[0]
        if s.lstrip("-").isdigit():
            i = int(s)
            if 0 <= i < len(self.names):
                return self.names[i]
        return None

    def describe(self) -> str:
        """The available columns, for error messages."""
        if self.has_header:
            return f"{self.label}s: " + ", ".join(self.names)
        return f"no header row; columns are numbered 0..{len(self.names) - 1}"

    def column(self, spec: str, what: str | None = None) -> tuple[str, np.ndarray]:
        """``(name, values)`` of column ``spec``.

        Raises
        ------
        BadInputError
            If there is no such column (lists the available ones).
        """
        name = self.resolve(spec)
        if name is None:
            raise BadInputError(f"{self.source}: no {what or self.label} {spec!r}; {self.describe()}")
        return name, self._columns[name]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _sniff(path: Path) -> tuple[str | None, list[str], bool, int]:
    """Delimiter, names, whether there is a header, lines to skip before the data."""
    skip = 0
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            for line in f:
                if line.strip():
                    break
                skip += 1
            else:
                raise DataFileError(f"{path}: empty file")
    except UnicodeDecodeError as err:
        raise DataFileError(f"{path}: not a text (UTF-8) CSV file") from err
    except OSError as err:
        raise DataFileError(f"cannot read {path}: {err.strerror or err}") from err
    first = line.rstrip("\r\n")
    delim = next((d for d in (",", "\t", ";") if d in first), None)
    cells = next(csv.reader([first], delimiter=delim)) if delim else first.split()
    cells = [c.strip() for c in cells]
    numeric = any(cells) and all(_is_number(c) for c in cells if c)
    if numeric:
        return delim, [str(i) for i in range(len(cells))], False, skip
    names: list[str] = []
    for i, c in enumerate(cells):
        name = c or str(i)
        while name in names:
            name += "_"
        names.append(name)
    return delim, names, True, skip + 1


def _parse_columns(path: Path, delim: str | None, skip: int, idx: Sequence[int], names: Sequence[str]) -> list[np.ndarray]:
    if not idx:
        return []
    try:
        data = np.loadtxt(path, delimiter=delim, skiprows=skip, usecols=list(idx), ndmin=2, dtype=float,
                          quotechar='"' if delim else None, encoding="utf-8-sig", comments=None)
        return [data[:, k].copy() for k in range(len(idx))]
    except (ValueError, IndexError):
        pass
    # slow path: find the first bad cell and name it
    cols: list[list[float]] = [[] for _ in idx]
    with open(path, encoding="utf-8-sig", newline="") as f:
        rows = csv.reader(f, delimiter=delim) if delim else (line.split() for line in f)
        for lineno, row in enumerate(rows, start=1):
            if lineno <= skip or not row or not any(c.strip() for c in row):
                continue
            for k, i in enumerate(idx):
                cell = row[i].strip() if i < len(row) else ""
                try:
                    cols[k].append(float(cell))
                except ValueError:
                    what = "an empty cell" if not cell else f"{cell!r} is not a number"
                    raise DataFileError(f"{path}: line {lineno}, column {names[k]!r}: {what}") from None
    return [np.asarray(c, dtype=float) for c in cols]


def read_csv_table(path: str | os.PathLike[str], columns: Sequence[str]) -> Table:
    """Read the columns ``columns`` (names or 0-based indices) of a CSV file.

    Unknown names are not an error here (the table lists what exists and
    :meth:`Table.column` raises); only cells of the requested columns are parsed.

    Raises
    ------
    DataFileError
        If the file cannot be read, or a requested column has an empty or non-numeric cell.
    """
    p = Path(path)
    try:
        delim, names, header, skip = _sniff(p)
        probe = Table(p, names, header, {})
        wanted = list(dict.fromkeys(n for n in (probe.resolve(c) for c in columns) if n is not None))
        idx = [names.index(n) for n in wanted]
        values = _parse_columns(p, delim, skip, idx, wanted)
    except UnicodeDecodeError as err:
        raise DataFileError(f"{p}: not a text (UTF-8) CSV file: undecodable byte at offset {err.start}") from None
    probe._columns = dict(zip(wanted, values))
    return probe


def first_value(path: str | os.PathLike[str], name: str) -> float | None:
    """The first non-empty value of column ``name`` of a CSV file (e.g. a ``Ts`` given once)."""
    p = Path(path)
    try:
        delim, names, _header, skip = _sniff(p)
    except UnicodeDecodeError:
        return None
    if name not in names:
        return None
    i = names.index(name)
    with open(p, encoding="utf-8-sig", errors="replace", newline="") as f:
        rows = csv.reader(f, delimiter=delim) if delim else (line.split() for line in f)
        for lineno, row in enumerate(rows, start=1):
            if lineno <= skip or i >= len(row) or not row[i].strip():
                continue
            try:
                return float(row[i])
            except ValueError:
                return None
    return None


def read_mat_table(path: str | os.PathLike[str]) -> Table:
    """The numeric vector variables of a MATLAB v5 ``.mat`` file as columns.

    Raises
    ------
    DataFileError
        If the file is not a readable MATLAB v4/v5 file (v7.3 is HDF5: not supported).
    """
    import scipy.io

    p = Path(path)
    try:
        raw = scipy.io.loadmat(p)
    except NotImplementedError as err:
        raise DataFileError(f"{p}: MATLAB v7.3 (HDF5) files are not supported; save with -v7 or export CSV") from err
    except (ValueError, TypeError, OSError, EOFError, IndexError, KeyError) as err:
        raise DataFileError(f"{p}: not a readable MATLAB .mat file ({err})") from err
    cols: dict[str, np.ndarray] = {}
    for name, value in raw.items():
        if name.startswith("__"):
            continue
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf" or arr.size == 0:
            continue
        arr = arr.squeeze()
        if arr.ndim == 1:
            cols[name] = arr.astype(float)
    if not cols:
        raise DataFileError(f"{p}: no numeric vector variables in this .mat file")
    names = list(cols)
    return Table(p, names, True, cols, label="variable")
