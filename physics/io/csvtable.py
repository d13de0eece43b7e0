"""CSV and MATLAB tables: the file layer under time-series and FRF files.

:func:`read_table` reads a CSV with a header line of column names (dialect sniffed: comma,
semicolon, tab, bar or blank separated; decimal point or comma; UTF-8 with or without BOM,
or Latin-1; LF or CRLF; ``#`` comment lines above the header skipped) or a ``.mat`` file of
vectors into a :class:`Table` of raw columns, naming the line and column of every bad cell.
:func:`write_table` writes columns and a YAML sidecar atomically under the output policy of
:mod:`physics.io.outputs`.
"""
from __future__ import annotations

import csv
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd
import scipy.io
import yaml

from ..errors import InputError, arg
from .fileio import atomic_path, check_regular
from .record import Locate, check_finite


@dataclass
class Table:
    """Columns of a CSV or .mat file before unit conversion.

    ``columns`` maps each name (file order) to its raw values (CSV: text; .mat: array),
    ``locate(i)`` names the line (CSV) or element (.mat) of value ``i``.
    """
    path: Path
    columns: dict[str, np.ndarray]
    locate: Locate

    def floats(self, name: str, label: str | None = None) -> np.ndarray:
        """Column ``name`` as finite floats; errors name line/element and column."""
        raw = self.columns[name]
        label = label or f"column {name!r}"
        if raw.dtype.kind in "biuf":
            values = raw.astype(float, copy=False)
        else:
            values = pd.to_numeric(pd.Series(raw), errors="coerce").to_numpy(dtype=float)
            i = next((i for i in np.flatnonzero(np.isnan(values))
                      if raw[i].strip().lower() != "nan"), None)
            if i is not None:
                text = raw[i].strip()
                what = "empty cell" if not text else f"{text!r} is not a number"
                raise InputError(f"{self.path}, {self.locate(i)}, column {name!r}: {what}; "
                                 "expected a finite number")
        check_finite(values, str(self.path), self.locate, label)
        return values


def check_input_path(path, suffixes: tuple[str, ...]) -> Path:
    """``path`` as a :class:`Path` after checking that it is an existing file with one of
    ``suffixes`` (lower case, with the dot)."""
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise InputError(f"{p}: unsupported file type {p.suffix or '(no extension)'!r}; "
                         f"expected {' or '.join(suffixes)}")
    check_regular(p, "the record")
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    return p


#: Field separators recognised in a CSV header line, in order of preference.
DELIMITERS = (",", ";", "\t", "|")
#: Encodings tried in turn: UTF-8 (with or without BOM), then Latin-1 (never fails).
ENCODINGS = ("utf-8-sig", "latin-1")


#: A line above the header starting with this is a comment (a lab export's notes: instrument,
#: operator, RH): skipped, with blank lines among such lines.
COMMENT = "#"


def _lines(text: str) -> list[str]:
    """``text`` split at LF, CRLF or CR, as a file opened with ``newline=""`` reads its lines (not
    :meth:`str.splitlines`, which also splits at form feeds and Latin-1's NEL, shifting line numbers)."""
    return re.split(r"\r\n|\r|\n", text)


def sniff_dialect(path: Path) -> tuple[str, str, str, int]:
    """(encoding, delimiter, decimal mark, lines above the header) of a CSV from its first 64 kB.

    The lines above the header are the leading comment lines (:data:`COMMENT`) and blank
    lines.  The delimiter is the separator most frequent in the header line (comma,
    semicolon, tab, bar; runs of blanks if none); a decimal comma is recognised when the
    separator is not a comma and data cells look like ``1,5``.
    """
    with path.open("rb") as fh:
        head = fh.read(1 << 16)
    if b"\x00" in head or re.search(rb"[\x01-\x08\x0e-\x1a]", head):
        raise InputError(f"{path}: not a UTF-8 text file (binary content); expected a CSV")
    try:
        text, encoding = head.decode("utf-8-sig"), "utf-8-sig"
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not merely a multi-byte character cut at the chunk end
            text, encoding = head.decode("latin-1"), "latin-1"
        else:
            text, encoding = head[:exc.start].decode("utf-8-sig"), "utf-8-sig"
    lines = _lines(text)
    skip = next((k for k, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith(COMMENT)), len(lines))
    lines = lines[skip:]
    header = lines[0] if lines else ""
    counts = {d: header.count(d) for d in DELIMITERS}
    delim = max(DELIMITERS, key=lambda d: counts[d]) if any(counts.values()) else \
        (r"\s+" if len(header.split()) > 1 else ",")
    decimal = "."
    if delim != ",":
        body = "\n".join(lines[1:50])
        if re.search(r"\d,\d", body) and not re.search(r"\d\.\d", body):
            decimal = ","
    return encoding, delim, decimal, skip


#: Longest header line read (characters): thousands of column names fit in it.
MAX_HEADER = 1 << 20


def csv_header(path: Path) -> list[str]:
    """Column names of a CSV's header line (dialect sniffed as by :func:`read_table`)."""
    encoding, delim, _, skip = sniff_dialect(path)
    with open(path, encoding=encoding, errors="replace", newline="") as fh:
        for _ in range(skip):
            fh.readline(MAX_HEADER + 1)
        header_line = fh.readline(MAX_HEADER + 1)
    if len(header_line) > MAX_HEADER:
        raise InputError(f"{path}, line {skip + 1}: longer than {MAX_HEADER} characters; expected a header line "
                         "of column names")
    if delim == r"\s+":
        return header_line.split()
    try:
        return [n.strip() for n in next(csv.reader([header_line], delimiter=delim), [])]
    except csv.Error as exc:
        raise InputError(f"{path}: the header line cannot be read as CSV ({exc})") from None


def _check_field_counts(path: Path, encoding: str, delim: str, n: int, hint: str, skip: int) -> None:
    """Refuse a line of the first 64 kB whose number of fields differs from the header's (on
    line ``skip`` + 1), naming the line (a later one is caught by the parser, without its number)."""
    with path.open("rb") as fh:
        head = fh.read(1 << 16).decode(encoding, errors="replace")
    lines = _lines(head)[skip + 1:-1]   # the last line of the head may be cut
    rows = (ln.split() for ln in lines) if delim == r"\s+" else csv.reader(lines, delimiter=delim)
    k = -1
    try:
        for k, fields in enumerate(rows):
            if fields and len(fields) != n and any(f.strip() for f in fields):
                raise InputError(f"{path}, line {skip + k + 2}: {len(fields)} fields but the header has {n} "
                                 f"(separator {delim!r}){hint}")
    except csv.Error as exc:
        raise InputError(f"{path}, line {skip + k + 3}: cannot be read as CSV ({exc})") from None


def _count_rows(path: Path, head: int) -> int:
    """Data rows of a CSV: its lines after the first ``head`` (the comment lines and the header),
    a last line without a newline included."""
    n, last = 0, b"\n"
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 22), b""):
            n += block.count(b"\n")
            last = block[-1:]
    return n - head + (last != b"\n")


def _parse(path: Path, opts: dict, rows: int | None = None) -> tuple[list | None, np.ndarray | None]:
    """(float values, one array per column, or None; text cells or None): the numeric values
    of a CSV (filled chunk by chunk into columns counted beforehand, 8 bytes per value, each
    column its own array so that one not kept is freed), or its cells as text when one is
    not a number (re-read to name it).  ``rows``: at most that many rows after
    ``opts["skiprows"]``."""
    try:
        reader = pd.read_csv(path, dtype=float, chunksize=1 << 18, nrows=rows, **opts)
        total = _count_rows(path, opts["skiprows"]) if rows is None else rows
        values = [np.empty(max(total, 0)) for _ in opts["names"]]
        n = 0
        for chunk in reader:
            c = chunk.to_numpy()
            if n + c.shape[0] > values[0].size:     # more rows than counted (odd line ends)
                values = [np.concatenate([col[:n], np.empty(c.shape[0])]) for col in values]
            for col, new in zip(values, c.T):
                col[n:n + c.shape[0]] = new
            n += c.shape[0]
        values = [col[:n] for col in values]
        if n and any(np.isnan(col).any() for col in values):
            blank = np.isnan(values[0])
            for col in values[1:]:
                blank &= np.isnan(col)
            nonblank = np.flatnonzero(~blank)
            end = nonblank[-1] + 1 if nonblank.size else 0
            if end == 0 or any(np.isnan(col[:end]).any() for col in values):
                raise ValueError("NaN or empty cell")
            values = [col[:end] for col in values]
        return values, None
    except ValueError as exc:
        if isinstance(exc, UnicodeDecodeError):
            raise
    df = pd.read_csv(path, dtype=str, keep_default_na=False, nrows=rows, **opts)
    return None, df.to_numpy(dtype=object).copy()


def _numbers_only(names: list[str]) -> bool:
    """Whether a header line split into ``names`` holds only numbers (digits, signs, exponents,
    decimal marks and separators: a data row, whatever separator its split assumed)."""
    text = "".join(names)
    return bool(re.search(r"\d", text)) and re.fullmatch(r"[\d.,;|+\-eE\s]*", text) is not None


def _setup(path: Path) -> tuple[list[str], dict, str, str]:
    """(column names, pandas options, the hint on a field-count error, decimal mark) of a CSV,
    its dialect sniffed and its first lines' field counts checked; ``opts["skiprows"]`` is the
    header's line number (the comment lines above it and the header itself)."""
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file; expected a header line of column names "
                         "followed by data rows")
    encoding, delim, decimal, skip = sniff_dialect(path)
    names = csv_header(path)
    if skip and not any(names):
        raise InputError(f"{path}: only comment ('#') or blank lines, no header line of column names (time_s, "
                         "voltage_V, …) followed by data rows")
    if skip and _numbers_only(names):
        raise InputError(f"{path}, line {skip + 1}: numbers where the header line of column names (time_s, "
                         f"voltage_V, …) should be, after {skip} comment ('#') or blank line(s) skipped; if the header "
                         "is among them, remove its '#'")
    if not any(names):
        raise InputError(f"{path}: empty file; expected a header line of column names "
                         "followed by data rows")
    hint = ("; a decimal comma needs another field separator (';' or tab) — in a comma-separated file "
            "write numbers with a decimal point") if delim == "," else ""
    _check_field_counts(path, encoding, delim, len(names), hint, skip)
    opts = dict(sep=delim, header=None, skiprows=skip + 1, names=list(range(len(names))), decimal=decimal,
                encoding=encoding, skip_blank_lines=False, engine="c", index_col=False)
    return names, opts, hint, decimal


def _parsed(path: Path, names, opts, hint, rows: int | None = None):
    """:func:`_parse` with the package's errors (and Latin-1 after a UTF-8 head)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)   # a line with extra fields
            try:
                return _parse(path, opts, rows)
            except UnicodeDecodeError:   # a Latin-1 byte after the sniffed head: the file is Latin-1
                return _parse(path, dict(opts, encoding="latin-1"), rows)
    except pd.errors.EmptyDataError:
        raise InputError(f"{path}: empty file; the header is not followed by any data row") from None
    except (pd.errors.ParserError, pd.errors.ParserWarning) as exc:
        raise InputError(f"{path}: cannot be parsed as CSV ({' '.join(str(exc).split())}); "
                         f"every line must have the {len(names)} fields of the header "
                         f"(separator {opts['sep']!r}){hint}") from None


def _table(path: Path, names, values, raw, decimal: str, first_line: int) -> Table:
    """The :class:`Table` of parsed values (or text cells) of a CSV's rows from its line ``first_line``
    (1-based) on."""
    if raw is not None:
        raw[pd.isna(raw)] = ""
        end = raw.shape[0]
        while end and not any(str(v).strip() for v in raw[end - 1]):
            end -= 1  # drop trailing blank lines
        raw = raw[:end]
        if decimal == ",":
            raw = np.vectorize(lambda v: str(v).replace(",", "."), otypes=[object])(raw) if raw.size else raw
    n = len(values[0]) if raw is None else raw.shape[0]
    if n == 0:
        raise InputError(f"{path}: empty file; the header is not followed by any data row")
    columns: dict[str, np.ndarray] = {}
    for k, name in enumerate(names):
        col = values[k] if raw is None else raw[:, k].astype(str)
        if not name:
            if (np.isnan(col).all() if raw is None else (np.char.strip(col) == "").all()):
                continue  # trailing separator: nameless, empty column
            raise InputError(f"{path}: column {k + 1} has data but no name in the header")
        if name in columns:
            raise InputError(f"{path}: column {name!r} appears twice in the header")
        columns[name] = col
    return Table(path, columns, lambda i: f"line {first_line + i}")


def read_table(path: Path) -> Table:
    """Read a CSV (header line of names) or .mat file into a :class:`Table`.

    CSV dialects are sniffed (:func:`sniff_dialect`): comma, semicolon, tab or blank
    separated, decimal point or comma, UTF-8 (BOM allowed) or Latin-1, LF or CRLF.  Numeric
    files are parsed straight to floats (8 bytes per value, no second copy); a file with a
    non-numeric, empty or NaN cell is re-read as text to name the line and column.
    """
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    names, opts, hint, decimal = _setup(path)
    values, raw = _parsed(path, names, opts, hint)
    return _table(path, names, values, raw, decimal, opts["skiprows"] + 1)


def iter_table(path: Path, rows: int = 1 << 20) -> Iterator[Table]:
    """The rows of a CSV as consecutive :class:`Table` pieces of at most ``rows`` rows (the
    same dialect, checks and messages as :func:`read_table`; ``locate`` names the file's
    lines), so that a long file is never held whole."""
    names, opts, hint, decimal = _setup(path)
    head = opts["skiprows"]                     # the header's line number
    total, first = _count_rows(path, head), 0
    while total > rows and total % rows == 1:   # no last piece of one row (a record needs two)
        rows += 1
    reader = pd.read_csv(path, dtype=float, chunksize=rows, **opts)
    while first < total:
        n = min(rows, total - first)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", pd.errors.ParserWarning)
                values = next(reader).to_numpy().T.copy()
            if np.isnan(values).any():
                raise ValueError("NaN or empty cell")
            raw = None
        except (ValueError, StopIteration, pd.errors.ParserError, pd.errors.ParserWarning):
            values, raw = _parsed(path, names, dict(opts, skiprows=head + first), hint, n)   # names the fault
        table = _table(path, names, values, raw, decimal, head + first + 1)
        got = len(next(iter(table.columns.values()))) if table.columns else 0
        if got < n and first + n < total:   # blank lines, then more data: as read_table says
            raise InputError(f"{path}, line {head + first + got + 1}: empty line inside the data; remove it")
        yield table
        first += n


def _read_mat(path: Path) -> Table:
    try:
        data = scipy.io.loadmat(path)
    except NotImplementedError:
        raise InputError(f"{path}: MATLAB v7.3 (HDF5) files are not supported; save with "
                         "-v7 or export a CSV") from None
    except Exception as exc:  # scipy raises various types for corrupt files
        raise InputError(f"{path}: cannot be read as a MATLAB file ({exc})") from None
    columns = {}
    for name, value in data.items():
        if name.startswith("__"):
            continue
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf" or arr.ndim > 2 or (arr.ndim == 2 and min(arr.shape) != 1):
            raise InputError(f"{path}: variable {name!r} must be a real numeric vector, got "
                             f"{arr.dtype} array of shape {arr.shape}")
        columns[name] = arr.ravel()
    if not columns or all(c.size == 0 for c in columns.values()):
        raise InputError(f"{path}: empty file; expected vectors named like the CSV columns")
    return Table(path, columns, lambda i: f"element {i + 1}")


def write_table(columns: dict[str, np.ndarray], meta: dict, path, *, overwrite: bool,
                protect) -> Path:
    """Atomically write ``columns`` as CSV (shortest round-trip float repr) to ``path``
    (``.csv``) and ``meta`` to the sidecar ``NAME.yaml`` (removing a stale sidecar when
    ``meta`` is empty).  Inputs in ``protect`` (and their sidecars) are never targets."""
    target = Path(path)
    if target.suffix.lower() != ".csv":
        raise InputError(f"{target}: output must be a .csv file")
    side = target.with_suffix(".yaml")
    protect = tuple(Path(p) for p in protect)
    protect = protect + tuple(p.with_suffix(".yaml") for p in protect)
    for p in (target, side):  # check both before writing either
        if any(p.resolve() == q.resolve() for q in protect):
            raise InputError(f"refusing to overwrite the input file {p}; choose another output path")
        if p.exists() and not overwrite:
            raise InputError(f"{p} already exists; choose another output path or pass {arg('overwrite')}")
    write_sidecar(meta, side)
    with atomic_path(target, overwrite=True) as tmp, open(tmp, "w", encoding="utf-8", newline="") as fh:
        append_rows(fh, columns, header=True)
    return target


def append_rows(fh, columns: dict[str, np.ndarray], *, header: bool) -> None:
    """Write the rows of ``columns`` to the open text file ``fh`` as CSV (the header line
    first when ``header``), floats in their shortest round-trip form: a long table can be
    written piece by piece with the same text as in one go."""
    pd.DataFrame(columns).to_csv(fh, index=False, header=header, lineterminator="\n")


def write_sidecar(meta: dict, side: Path) -> None:
    """Atomically write ``meta`` as the YAML sidecar ``side`` (remove it when ``meta`` is empty)."""
    if meta:
        text = yaml.safe_dump(plain(meta), sort_keys=False, allow_unicode=True)
        with atomic_path(side, overwrite=True) as tmp:
            tmp.write_text(text, encoding="utf-8")
    elif side.exists():
        side.unlink()


def plain(obj, key: str = "meta"):
    """``obj`` converted to plain YAML/JSON types (numpy scalars and arrays, tuples, paths)."""
    if isinstance(obj, dict):
        return {str(k): plain(v, f"{key}.{k}") for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v, f"{key}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist(), key)
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, os.PathLike):
        return str(obj)
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    raise InputError(f"{key}: cannot store a {type(obj).__name__} in metadata; use numbers, "
                     "strings, lists or mappings")
