"""Self-contained HTML reports (and the CSV tables that go with them).

A :class:`Report` collects headings, paragraphs, warnings, tables (from a list of row
dicts or from one dict), images and collapsible JSON blocks, and renders **one** HTML
page with every PNG embedded as a base64 ``data:`` URI: the page can be mailed or
archived alone, it references no other file and no network resource.  Any command that
evaluates something can use it::

    from physics.pages.report import Report
    rep = Report("eap compare", subtitle="ipmc_pt_eg vs 3 records")
    rep.table([{"record": "a.csv", "fit_percent": 93.1, "rmse_m": 3.1e-5}])  # fit [%], RMSE [µm]
    rep.why("The measurement-like records carry physics absent from training ...")
    rep.image("bode.png", caption="|H| [mm/V] and phase [°] of ...")   # a PNG file, or PNG bytes
    rep.figure(fig, caption="...")                                     # a matplotlib figure
    rep.write_index("out")     # out/index.html, atomic (physics.io.fileio); out/report.html redirects

Tables read like a paper's: every stored key is shown by :mod:`physics.pages.columns` as a name
with its unit, values in the unit that reads best (µm for tips, mV for volt outputs, %),
missing values as an en dash with a footnote, and a table too wide for a 1280 px window is
split into parts.  Pages name final paths, never the temporary folder of an atomic write.
Text is HTML-escaped.  :func:`write_csv` writes the same rows as a CSV table (SI, full
precision).
"""
from __future__ import annotations

import base64
import csv
import datetime as _dt
import html
import io
import json
import math
import os
import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .columns import Column, band, column, number
from ..errors import InputError
from ..io.fileio import atomic_path, write_text
from ..io.outputs import final_text

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;
max-width:1100px;color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.6em;border-bottom:2px solid #446;padding-bottom:.2em}
h2{font-size:1.3em;margin-top:1.6em;border-bottom:1px solid #ccd}
h3{font-size:1.1em}
table{border-collapse:collapse;margin:.6em 0 .3em 0;font-size:.9em;max-width:100%}
th,td{border:1px solid #bbc;padding:.25em .5em;text-align:right;vertical-align:top}
th{background:#eef;font-weight:600;vertical-align:bottom}
th[scope=row]{vertical-align:top}
td{white-space:nowrap}
td.t,th.t{text-align:left;white-space:normal;overflow-wrap:break-word}
td.b{overflow-wrap:anywhere}
p.cap{font-weight:600;margin:.8em 0 0 0}
figure{margin:1em 0}
figure img{max-width:100%;height:auto;border:1px solid #ddd}
figcaption{font-size:.9em;color:#444;max-width:100%}
.warn{background:#fff4e0;border-left:4px solid #e90;padding:.4em .8em;margin:.5em 0}
.note{color:#555;font-size:.9em}
.foot{color:#555;font-size:.85em;margin:.1em 0 1.2em 0}
.why{background:#f3f7ff;border-left:4px solid #68a;padding:.4em .8em;margin:.5em 0}
pre{background:#f6f6fa;padding:.6em;overflow-x:auto;font-size:.85em;white-space:pre-wrap;word-break:break-word}
.tw{max-width:100%;overflow-x:auto}
nav{background:#f4f4fa;border:1px solid #dde;padding:.4em .8em;font-size:.9em}
nav a{margin-right:1em}
.prov{font-size:.85em;color:#555;overflow-wrap:anywhere}
.lead{font-size:1.05em;font-weight:500}
p,li{overflow-wrap:anywhere}
"""

#: The width a table may take before it is split into parts [px] (the page is 1100 px wide
#: with 1 em padding; :func:`_min_width` estimates a column's narrowest layout).
TABLE_BUDGET_PX = 1040

#: The same colour for the same name in every figure of every report (matplotlib "tab10").
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf")
_NAMED = {"measurement": "#000000", "physics": "#555555", "linear": "#999999"}   # references in greys


def colour(name: str) -> str:
    """A stable colour for a model or series name (same name, same colour, in every report)."""
    import zlib
    if name in _NAMED:
        return _NAMED[name]
    return COLOURS[zlib.crc32(name.encode()) % len(COLOURS)]


def format_value(v: Any, digits: int = 3) -> str:
    """Text for a value in running text or a cell: numbers by :func:`physics.pages.columns.number`
    (a missing number is an en dash), ``None`` empty, lists joined by commas, the rest ``str``."""
    if v is None:
        return ""
    if isinstance(v, (list, tuple)):
        return ", ".join(format_value(x, digits) for x in v)
    if isinstance(v, (bool, int, float)) or hasattr(v, "dtype"):
        return number(v, digits)
    return str(v)


def _rows(data: Sequence[Mapping[str, Any]] | Mapping[str, Any]) -> list[dict]:
    """Rows from a list of dicts, or from one dict (shown as a two-column table)."""
    if isinstance(data, Mapping):
        return [{"quantity": k, "value": v} for k, v in data.items()]
    rows = []
    for i, r in enumerate(data):
        if not isinstance(r, Mapping):
            raise InputError(f"table row {i}: expected a mapping of column names to values, got {type(r).__name__}")
        rows.append(dict(r))
    return rows


def _columns(rows: list[dict], columns: Sequence[str] | None) -> list[str]:
    if columns is not None:
        return list(columns)
    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    return cols


def _missing(v: Any) -> bool:
    """None, NaN, or a cell a caller wrote as a hyphen or a dash for "no value"."""
    return v is None or (isinstance(v, float) and math.isnan(v)) or (isinstance(v, str) and v.strip() in ("-", "–"))


#: A number a caller already wrote as text ("51,415", "0.9"): right-aligned like a number.
_NUMBER_TEXT = re.compile(r"^[-−+]?[\d,.\s]*\d(?:[eE][-+]?\d+)?$")


def _cell(v: Any, col: Column, digits: int | None) -> str:
    """The text of a cell: numbers scaled to the column's unit; a pair of numbers in a
    column of frequencies is a band (``0.13–1``)."""
    d = digits or col.digits
    if _missing(v):
        return "–"
    if isinstance(v, str):
        return v
    if isinstance(v, (list, tuple)):
        if len(v) == 2 and col.unit == "Hz" and all(isinstance(x, (int, float)) for x in v):
            return band(float(v[0]), float(v[1]))[:-3]
        return ", ".join(_cell(x, col, digits) for x in v)
    if isinstance(v, bool) or not isinstance(v, (int, float)) and not hasattr(v, "dtype"):
        return format_value(v, d)
    if isinstance(v, int) or (hasattr(v, "dtype") and v.dtype.kind in "iu"):
        return number(int(v) if col.scale == 1 else int(v) * col.scale, d)
    return number(float(v) * col.scale, d)


def _numeric(v: Any) -> bool:
    if isinstance(v, str):
        return bool(_NUMBER_TEXT.match(v.strip()))
    return not isinstance(v, (bool, list, tuple, dict)) and v is not None


def _words(text: str) -> list[int]:
    """Lengths of the pieces a browser may not break (split at spaces and after hyphens)."""
    return [len(w) for w in re.split(r"\s+|(?<=-)", text) if w] or [1]


def _min_width(label: str, cells: Sequence[str], numeric: Sequence[bool]) -> int:
    """Estimated narrowest width of a column [px]: its longest header word, its longest
    number (numbers never wrap) and its longest text word (text wraps, long words break);
    about 7.5 px per character at the table's font size, 16 px of padding and border."""
    widths = [len(c) if n else min(max(_words(c)), LONG_WORD) for c, n in zip(cells, numeric)]
    return int(7.5 * max(max(_words(label)), max(widths, default=1))) + 16


_T, _ROW = " class='t'", " scope='row'"
#: Words longer than this in a text cell may break anywhere (paths, hashes); shorter ones never do.
LONG_WORD = 24


def _text_class(text: str) -> str:
    return " class='t b'" if any(len(w) > LONG_WORD for w in text.split()) else _T


def _th(col: Column, cls: str = "", scope: str = "") -> str:
    unit = "" if col.unit is None else f" data-unit='{html.escape(col.unit or '1')}'"
    return (f"<th{cls}{scope}{unit}>{html.escape(col.header)}</th>")


def header(provenance: Mapping[str, Any] | None) -> dict:
    """The report header's "what was run": command and package version of a provenance dict."""
    p = dict(provenance or {})
    out = {k: p[k] for k in ("command", "version") if p.get(k)}
    if p.get("data_sha256"):
        out["data"] = ", ".join(f"{name} (sha256 {h[:12]})" for name, h in p["data_sha256"].items())
    return out


def png_data_uri(image: str | os.PathLike | bytes) -> str:
    """A ``data:image/png;base64,...`` URI from a PNG file path or PNG bytes."""
    if isinstance(image, (bytes, bytearray)):
        data = bytes(image)
        where = "image bytes"
    else:
        p = Path(image)
        if not p.is_file():
            raise InputError(f"report image {p} does not exist")
        data = p.read_bytes()
        where = str(p)
    if not data.startswith(b"\x89PNG"):
        raise InputError(f"{where}: not a PNG image")
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


class Report:
    """An HTML page built block by block (see the module doc)."""

    def __init__(self, title: str, subtitle: str | None = None, provenance: Mapping[str, Any] | None = None,
                 output: Mapping[str, Any] | None = None):
        self.title = str(title)
        self.subtitle = subtitle
        self.provenance = dict(provenance or {})
        #: The plant's output (``{"name", "unit"}``; default a deflection in metres): tables
        #: show output quantities (errors, noise floors) in its reading unit.
        self.output = dict(output or {})
        self._blocks: list[str] = []
        self._sections: list[tuple[str, str]] = []

    # --- blocks --------------------------------------------------------------------------
    @staticmethod
    def anchor(title: str) -> str:
        """The id of the section headed ``title`` (to link to it before it is written)."""
        return "s-" + (re.sub(r"[^a-z0-9]+", "-", str(title).lower()).strip("-") or "section")

    def heading(self, text: str, level: int = 2) -> "Report":
        level = min(max(int(level), 2), 4)
        anchor = ""
        if level == 2:
            sid = self.anchor(text)
            if any(sid == s for s, _ in self._sections):
                sid += f"-{len(self._sections) + 1}"
            self._sections.append((sid, str(text)))
            anchor = f" id='{sid}'"
        self._blocks.append(f"<h{level}{anchor}>{html.escape(str(text))}</h{level}>")
        return self

    @staticmethod
    def _text(text: str, links: Mapping[str, str] | None) -> str:
        """Escaped text; ````literal```` becomes code; each key of ``links`` found in it becomes
        a link to its value."""
        out = re.sub(r"``([^`]+)``", r"<code>\1</code>", html.escape(str(text)))
        for words, href in (links or {}).items():
            w = html.escape(words)
            out = out.replace(w, f"<a href='{html.escape(href)}'>{w}</a>", 1)
        return out

    def lead(self, text: str, links: Mapping[str, str] | None = None) -> "Report":
        """The one sentence that opens a section (computed from the results)."""
        self._blocks.append(f"<p class='lead'>{self._text(text, links)}</p>")
        return self

    def paragraph(self, text: str, note: bool = False, links: Mapping[str, str] | None = None) -> "Report":
        """A paragraph; ``links`` maps words of ``text`` to the address they link to
        (``{"the diagnosis": "#" + Report.anchor("The diagnosis")}``)."""
        cls = " class='note'" if note else ""
        self._blocks.append(f"<p{cls}>{self._text(text, links)}</p>")
        return self

    def why(self, text: str, links: Mapping[str, str] | None = None) -> "Report":
        """The sentence beside a number a reader would stop at: why it is what it is."""
        self._blocks.append(f"<p class='why'>{self._text(text, links)}</p>")
        return self

    def warning(self, text: str) -> "Report":
        self._blocks.append(f"<div class='warn'>&#9888; {html.escape(str(text))}</div>")
        return self

    def bullets(self, items: Iterable[str]) -> "Report":
        lis = "".join(f"<li>{html.escape(str(i))}</li>" for i in items)
        self._blocks.append(f"<ul>{lis}</ul>")
        return self

    def table(self, data: Sequence[Mapping[str, Any]] | Mapping[str, Any], *,
              columns: Sequence[str] | None = None, caption: str | None = None,
              digits: int | None = None, headers: Mapping[str, str | Column] | None = None,
              missing: str | None = None, notes: Sequence[str] = ()) -> "Report":
        """A table from a list of row dicts (columns: union of keys, first-seen order, or
        ``columns``) or from one dict (one row per key: its name and unit, its value).

        Every key is shown through :func:`physics.pages.columns.column` (a name, a unit, the
        display scale; ``headers`` gives another name or :class:`Column` for a key); a
        missing value (None, NaN) is an en dash explained under the table by ``missing``;
        ``notes`` are further footnotes.  A table too wide for the page is split into parts
        that repeat its first column."""
        headers = dict(headers or {})

        def col(key):
            h = headers.get(key, key)
            return h if isinstance(h, Column) else column(h, self.output)
        foot = list(notes)
        if isinstance(data, Mapping):
            body, gap = [], False
            for key, v in data.items():
                c = col(key)
                text = _cell(v, c, digits)
                gap |= text == "–"
                cls = _text_class(text) if not _numeric(v) else ""
                body.append(f"<tr>{_th(c, _T, _ROW)}<td{cls}>{html.escape(text)}</td></tr>")
            if gap:
                foot.insert(0, f"– {missing or 'no value (not applicable, or not measured)'}")
            self._table_block(caption, "", body, foot)
            return self
        rows = _rows(data)
        keys = _columns(rows, columns)
        gone = [k for k in keys[1:] if all(_missing(r.get(k)) for r in rows)]
        if gone and rows:   # a column with no value at all is left out, and said
            foot.append("Not shown (no value in any row): " + ", ".join(col(k).header for k in gone) + ".")
            keys = [k for k in keys if k not in gone]
        cols = [col(k) for k in keys]
        cells = [[_cell(r.get(k), c, digits) for k, c in zip(keys, cols)] for r in rows]
        numeric = [[_numeric(r.get(k)) and not _missing(r.get(k)) for k in keys] for r in rows]
        right = [any(n[j] for n in numeric) for j in range(len(keys))]   # a column of numbers: right-aligned
        if any(t == "–" for row in cells for t in row):
            foot.insert(0, f"– {missing or 'no value (not applicable, or not measured)'}")
        widths = [_min_width(c.header, [row[j] for row in cells], [n[j] for n in numeric]) for j, c in enumerate(cols)]
        parts, cur = [], [0]
        for j in range(1, len(keys)):
            if sum(widths[i] for i in cur) + widths[j] > TABLE_BUDGET_PX and len(cur) > 1:
                parts.append(cur)
                cur = [0]
            cur.append(j)
        parts.append(cur)
        for n, part in enumerate(parts):
            head = "<tr>" + "".join(_th(cols[j], _T if j == 0 else "") for j in part) + "</tr>"
            body = ["<tr>" + "".join(f"<td{'' if right[j] else _text_class(row[j])}>{html.escape(row[j])}</td>"
                                     for j in part) + "</tr>" for row in cells]
            cap = caption if n == 0 else f"{caption or 'table'} (continued, {n + 1}/{len(parts)})"
            self._table_block(cap, head, body, foot if n == len(parts) - 1 else [])
        return self

    def _table_block(self, caption, head, body, foot) -> None:
        cap = f"<p class='cap'>{html.escape(caption)}</p>" if caption else ""
        notes = "".join(f"<p class='foot'>{html.escape(f)}</p>" for f in foot)
        self._blocks.append(f"{cap}<div class='tw'><table>{head}\n" + "\n".join(body) + f"</table></div>{notes}")

    def image(self, image: str | os.PathLike | bytes, caption: str, width: int | None = None) -> "Report":
        """Embed a PNG (file path or bytes) as a base64 data URI, with a caption that says
        what is shown (also the image's alternative text)."""
        uri = png_data_uri(image)
        w = f" width='{int(width)}'" if width else ""
        cap = html.escape(str(caption))
        self._blocks.append(f"<figure><img src='{uri}' alt='{cap}'{w}><figcaption>{cap}</figcaption></figure>")
        return self

    def figure(self, fig, caption: str, dpi: int = 110) -> "Report":
        """Embed a matplotlib figure (rendered to PNG in memory; the figure is closed)."""
        import matplotlib.pyplot as plt
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        return self.image(buf.getvalue(), caption)

    def json_block(self, obj: Any, summary: str = "JSON") -> "Report":
        """A collapsible block with ``obj`` as indented JSON."""
        text = json.dumps(obj, indent=2, default=str, ensure_ascii=False)
        self._blocks.append(f"<details><summary>{html.escape(summary)}</summary>"
                            f"<pre>{html.escape(text)}</pre></details>")
        return self

    def raw(self, markup: str) -> "Report":
        """Trusted HTML written by the package itself (never user text: use the other blocks)."""
        self._blocks.append(str(markup))
        return self

    def preformatted(self, text: str) -> "Report":
        self._blocks.append(f"<pre>{html.escape(str(text))}</pre>")
        return self

    # --- output --------------------------------------------------------------------------
    def to_html(self) -> str:
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        sub = f"<p class='note'>{html.escape(self.subtitle)}</p>" if self.subtitle else ""
        prov = ""
        if self.provenance:
            prov = "<p class='prov'>" + " · ".join(f"{html.escape(str(k))}: {html.escape(format_value(v))}"
                                                  for k, v in self.provenance.items()) + "</p>"
        nav = ""
        if len(self._sections) > 1:
            nav = "<nav>" + "".join(f"<a href='#{sid}'>{html.escape(t)}</a>" for sid, t in self._sections) + "</nav>"
        body = "\n".join(self._blocks)
        return (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
                f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
                f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>\n"
                f"<h1>{html.escape(self.title)}</h1>{sub}{prov}{nav}\n{body}\n"
                f"<p class='note'>Generated {stamp} by eap-model.</p>\n</body></html>\n")

    def write(self, path: str | os.PathLike) -> Path:
        """Write the page atomically (temporary file, then rename).  Paths through the
        temporary folder of an output being written are shown as their final paths
        (:func:`physics.io.outputs.final_text`)."""
        return write_text(path, final_text(self.to_html()))

    def write_index(self, folder: str | os.PathLike, old_name: str = "report.html") -> Path:
        """Write the page as ``folder/index.html`` (every command's page has this name) and
        ``folder/OLD_NAME``, a redirect to it under the name the page had before (kept for
        one release); returns the page's path."""
        d = Path(folder)
        page = self.write(d / PAGE)
        write_text(d / old_name, _REDIRECT.replace("OLD", html.escape(old_name)))
        return page


#: The name of every command's page (the name it had before is a redirect, :meth:`Report.write_index`).
PAGE = "index.html"
_REDIRECT = ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
             "<meta http-equiv='refresh' content='0; url=index.html'><title>moved to index.html</title></head>"
             "<body><p>This page is now <a href='index.html'>index.html</a> (OLD is kept as this "
             "redirect for one release).</p></body></html>\n")


def write_csv(rows: Sequence[Mapping[str, Any]] | Mapping[str, Any], path: str | os.PathLike, *,
              columns: Sequence[str] | None = None) -> Path:
    """Write rows (list of dicts, or one dict as quantity/value) as a CSV, atomically;
    floats at full precision, lists joined by ``;``."""
    rows = _rows(rows)
    cols = _columns(rows, columns)
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(cols)
            for r in rows:
                out = []
                for c in cols:
                    v = r.get(c)
                    if v is None:
                        out.append("")
                    elif isinstance(v, (list, tuple)):
                        out.append(";".join(repr(x) if isinstance(x, float) else str(x) for x in v))
                    elif isinstance(v, float):
                        out.append(repr(v))
                    else:
                        out.append(str(v))
                w.writerow(out)
    return Path(path)


