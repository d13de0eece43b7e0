"""Self-contained HTML reports (and the CSV tables that go with them).

A :class:`Report` collects headings, paragraphs, warnings, tables (from a list of row
dicts or from one dict), images and collapsible JSON blocks, and renders **one** HTML
page with every PNG embedded as a base64 ``data:`` URI: the page can be mailed or
archived alone, it references no other file and no network resource.  Any command that
evaluates something can use it::

    from physics.report import Report
    rep = Report("eap compare", subtitle="ipmc_pt_eg vs 3 records")
    rep.table([{"record": "a.csv", "fit_percent": 93.1}], caption="time-domain metrics")
    rep.image("bode.png", caption="Bode magnitude and phase")   # a PNG file, or PNG bytes
    rep.figure(fig)                                              # a matplotlib figure
    rep.write("out/report.html")                                 # atomic (physics.fileio)

Every text is HTML-escaped; numbers are formatted with :func:`format_value` (4
significant digits by default).  :func:`write_csv` writes the same rows as a CSV table.
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
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .errors import InputError
from .fileio import atomic_path, write_text

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;
max-width:1100px;color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.6em;border-bottom:2px solid #446;padding-bottom:.2em}
h2{font-size:1.3em;margin-top:1.6em;border-bottom:1px solid #ccd}
h3{font-size:1.1em}
table{border-collapse:collapse;margin:.6em 0 1.2em 0;font-size:.9em}
th,td{border:1px solid #bbc;padding:.25em .6em;text-align:right}
th{background:#eef}
td.t,th.t{text-align:left}
caption{caption-side:top;text-align:left;font-weight:600;padding:.3em 0}
figure{margin:1em 0}
figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}
.warn{background:#fff4e0;border-left:4px solid #e90;padding:.4em .8em;margin:.5em 0}
.note{color:#555;font-size:.9em}
pre{background:#f6f6fa;padding:.6em;overflow-x:auto;font-size:.85em;white-space:pre-wrap;word-break:break-word}
.tw{max-width:100%;overflow-x:auto}
nav{background:#f4f4fa;border:1px solid #dde;padding:.4em .8em;font-size:.9em}
nav a{margin-right:1em}
.prov{font-size:.85em;color:#555;word-break:break-all}
.lead{font-size:1.05em;font-weight:500}
"""

#: Runs in the browser: collects script errors, broken images and elements wider than the
#: viewport into ``<body data-eap-check="{json}">`` (read by the headless-browser tests).
_CHECK_JS = """
(function(){var errs=[];window.addEventListener('error',function(e){errs.push(String(e.message||e));});
window.addEventListener('load',function(){var imgs=[].slice.call(document.images);
var broken=imgs.filter(function(i){return !(i.complete&&i.naturalWidth>0);}).map(function(i){return i.alt;});
var vw=document.documentElement.clientWidth,wide=[];
[].slice.call(document.body.querySelectorAll('*')).forEach(function(el){var r=el.getBoundingClientRect();
if(r.right>vw+1&&!el.closest('.tw')&&!el.closest('pre')){wide.push(el.tagName+(el.id?'#'+el.id:''));}});
document.body.setAttribute('data-eap-check',JSON.stringify({images:imgs.length,broken:broken,errors:errs,
too_wide:wide.slice(0,20),sections:[].slice.call(document.querySelectorAll('h2')).map(function(h){return h.textContent;})}));});})();
"""

#: The same colour for the same name in every figure of every report (matplotlib "tab10").
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
           "#bcbd22", "#17becf")
_NAMED = {"measurement": "#000000", "physics": "#555555"}


def colour(name: str) -> str:
    """A stable colour for a model or series name (same name, same colour, in every report)."""
    import zlib
    if name in _NAMED:
        return _NAMED[name]
    return COLOURS[zlib.crc32(name.encode()) % len(COLOURS)]


def format_value(v: Any, digits: int = 4) -> str:
    """Text for a table cell: floats to ``digits`` significant digits (``inf``/``nan``
    spelled out), ``None`` as an empty cell, lists joined by commas, the rest ``str``."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float) or (hasattr(v, "dtype") and getattr(v, "ndim", 1) == 0):
        x = float(v)
        if math.isnan(x):
            return "nan"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return f"{x:.{digits}g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(format_value(x, digits) for x in v)
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

    def __init__(self, title: str, subtitle: str | None = None, provenance: Mapping[str, Any] | None = None):
        self.title = str(title)
        self.subtitle = subtitle
        self.provenance = dict(provenance or {})
        self._blocks: list[str] = []
        self._sections: list[tuple[str, str]] = []

    # --- blocks --------------------------------------------------------------------------
    def heading(self, text: str, level: int = 2) -> "Report":
        level = min(max(int(level), 2), 4)
        anchor = ""
        if level == 2:
            sid = f"s{len(self._sections) + 1}"
            self._sections.append((sid, str(text)))
            anchor = f" id='{sid}'"
        self._blocks.append(f"<h{level}{anchor}>{html.escape(str(text))}</h{level}>")
        return self

    def lead(self, text: str) -> "Report":
        """The one sentence that opens a section (computed from the results)."""
        self._blocks.append(f"<p class='lead'>{html.escape(str(text))}</p>")
        return self

    def paragraph(self, text: str, note: bool = False) -> "Report":
        cls = " class='note'" if note else ""
        self._blocks.append(f"<p{cls}>{html.escape(str(text))}</p>")
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
              digits: int = 4, headers: Mapping[str, str] | None = None) -> "Report":
        """A table from a list of row dicts (columns: union of keys, first-seen order, or
        ``columns``) or from one dict (two columns, quantity and value).  ``headers``
        renames columns for display."""
        rows = _rows(data)
        cols = _columns(rows, columns)
        headers = dict(headers or {})
        out = ["<table>"]
        if caption:
            out.append(f"<caption>{html.escape(caption)}</caption>")
        out.append("<tr>" + "".join(
            f"<th class='{'t' if i == 0 else ''}'>{html.escape(str(headers.get(c, c)))}</th>"
            for i, c in enumerate(cols)) + "</tr>")
        for r in rows:
            cells = []
            for i, c in enumerate(cols):
                v = r.get(c)
                cls = " class='t'" if (i == 0 or isinstance(v, str)) else ""
                cells.append(f"<td{cls}>{html.escape(format_value(v, digits))}</td>")
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</table>")
        self._blocks.append("<div class='tw'>" + "\n".join(out) + "</div>")
        return self

    def image(self, image: str | os.PathLike | bytes, caption: str | None = None,
              width: int | None = None) -> "Report":
        """Embed a PNG (file path or bytes) as a base64 data URI."""
        uri = png_data_uri(image)
        alt = html.escape(caption or (Path(image).name if not isinstance(image, (bytes, bytearray)) else "figure"))
        w = f" width='{int(width)}'" if width else ""
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self._blocks.append(f"<figure><img src='{uri}' alt='{alt}'{w}>{cap}</figure>")
        return self

    def figure(self, fig, caption: str | None = None, dpi: int = 110) -> "Report":
        """Embed a matplotlib figure (rendered to PNG in memory; the figure is closed)."""
        import matplotlib.pyplot as plt
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        return self.image(buf.getvalue(), caption)

    def json_block(self, obj: Any, summary: str = "JSON") -> "Report":
        """A collapsible block with ``obj`` as indented JSON."""
        text = json.dumps(obj, indent=2, default=str)
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
                f"<title>{html.escape(self.title)}</title><style>{_CSS}</style>"
                f"<script>{_CHECK_JS}</script></head><body>\n"
                f"<h1>{html.escape(self.title)}</h1>{sub}{prov}{nav}\n{body}\n"
                f"<p class='note'>Generated {stamp} by eap-model.</p>\n</body></html>\n")

    def write(self, path: str | os.PathLike) -> Path:
        """Write the page atomically (temporary file, then rename)."""
        return write_text(path, self.to_html())


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


def jsonable(obj: Any) -> Any:
    """``obj`` with numpy types converted and non-finite floats replaced by ``None`` (JSON
    has no NaN/inf); tuples become lists, paths strings."""
    import numpy as np
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, complex):
        return {"re": jsonable(obj.real), "im": jsonable(obj.imag)}
    if isinstance(obj, os.PathLike):
        return str(obj)
    return obj
