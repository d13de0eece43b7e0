"""The self-contained HTML report helper (physics.pages.report)."""
from __future__ import annotations

import base64
import csv
import json
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from physics.errors import InputError  # noqa: E402
from physics.io.fileio import jsonable  # noqa: E402
from physics.pages.report import Report, format_value, png_data_uri, write_csv  # noqa: E402


def _png(tmp_path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    p = tmp_path / "a.png"
    fig.savefig(p)
    plt.close(fig)
    return p


def test_report_embeds_images_and_escapes_text(tmp_path):
    png = _png(tmp_path)
    rep = Report("Title <&>", subtitle="sub")
    rep.heading("Section").paragraph("a < b <script>alert(1)</script>").warning("careful & quick")
    rep.table([{"name": "x<y", "value": 1.234567}, {"name": "z", "extra": None}], caption="cap")
    rep.table({"fit_percent": 97.5})
    rep.image(png, caption="file png")
    fig, ax = plt.subplots()
    rep.figure(fig, caption="in memory")
    rep.json_block({"k": [1, 2]})
    path = rep.write(tmp_path / "r.html")
    html = path.read_text()
    assert "Title &lt;&amp;&gt;" in html and "a &lt; b" in html and "x&lt;y" in html
    # no script at all (user text is escaped, nothing is fetched)
    assert "<script" not in html and "&lt;script&gt;alert(1)" in html and "http" not in html.split("<style>")[0]
    uris = [s.split("'")[0] for s in html.split("src='")[1:]]
    assert len(uris) == 2
    for u in uris:
        assert u.startswith("data:image/png;base64,")
        assert base64.b64decode(u.split(",", 1)[1]).startswith(b"\x89PNG")
    assert base64.b64decode(uris[0].split(",", 1)[1]) == png.read_bytes()
    assert "1.235" in html                               # identified values ('value'): 4 significant digits
    assert "<th class='t'>name</th><th data-unit='per row'>identified</th></tr>" in html
    assert "Not shown (no value in any row): extra." in html   # an empty column is left out, and said
    assert "<th class='t' scope='row' data-unit='%'>fit [%]</th><td>97.5</td>" in html   # a dict: one row per key


def test_tables_name_their_columns_with_units_and_explain_gaps(tmp_path):
    rep = Report("t")
    rep.table([{"model": "ff", "nrmse_heldout_rh_pct": 3.14159, "rmse_m": 3.11e-5, "nrmse_measurement_like_pct":
                float("nan"), "band_Hz": [0.1333333, 1.0]}, {"model": "rbf", "nrmse_measurement_like_pct": 104.2}],
              missing="no measurement-like records")
    html = rep.to_html()
    assert "held-out RH NRMSE [%]" in html and ">3.14<" in html
    assert "RMSE [µm]" in html and ">31.1<" in html            # tips in µm
    assert ">0.13–1<" in html and "band [Hz]" in html             # rounded band edges
    assert "nan" not in html.lower().replace("nanum", "") and "– no measurement-like records" in html
    wide = {f"nrmse_group{k}_pct": 12.3456 for k in range(30)}
    rep2 = Report("t")
    rep2.table([{"model": "a_long_model_name", **wide}], caption="wide")
    parts = rep2.to_html().count("<table>")
    assert parts >= 2 and "(continued, 2/" in rep2.to_html()   # split, never a sideways scroll
    assert rep2.to_html().count("a_long_model_name") == parts   # the first column repeated in each part
    volts = Report("t", output={"name": "level", "unit": "V"})
    volts.table({"rmse_m": 1.2e-3})
    assert "RMSE [mV]" in volts.to_html() and ">1.20<" in volts.to_html()
    level = Report("t", output={"name": "level", "unit": "V", "magnitude": 35.0})   # a level read up to 35 V
    level.table({"rmse_m": 0.52})
    assert "RMSE [V]" in level.to_html() and ">0.520<" in level.to_html()         # not 520 mV beside 35 000 mV


def test_the_reading_unit_follows_the_magnitude_of_the_data():
    from physics.pages.columns import reading_unit
    assert reading_unit("V") == ("mV", 1e3) and reading_unit("V", 0.3) == ("mV", 1e3)   # usual reading kept ...
    assert reading_unit("V", 35.0) == ("V", 1.0) and reading_unit("V", 2e4) == ("kV", 1e-3)   # ... unless off 0.1–1000
    assert reading_unit("m", 3e-5) == ("µm", 1e6) and reading_unit("m", 0.03) == ("mm", 1e3)
    unit, k = reading_unit("mm", 3000.0)                 # a prefixed stored unit: 3000 mm read as 3 m
    assert unit == "m" and abs(k - 1e-3) < 1e-15
    assert reading_unit("level", 1e6) == ("level", 1.0)   # a unit without prefixes is shown as it is


def test_pages_are_index_html_name_final_paths_and_keep_a_redirect(tmp_path):
    d = tmp_path / ".out.eap-tmp-123"
    rep = Report("t")
    rep.paragraph(f"dataset {d}/dataset")
    page = rep.write_index(d)
    assert page.name == "index.html"
    assert f"{tmp_path}/out/dataset" in page.read_text() and ".eap-tmp-" not in page.read_text()
    redirect = (d / "report.html").read_text()
    assert "url=index.html" in redirect and len(redirect) < 2000


def test_image_errors(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        png_data_uri(tmp_path / "missing.png")
    (tmp_path / "x.png").write_text("not a png")
    with pytest.raises(InputError, match="not a PNG"):
        Report("t").image(tmp_path / "x.png", "a figure")


def test_format_and_json():
    assert format_value(float("nan")) == "–" and format_value(math.inf) == "∞"
    assert format_value(None) == "" and format_value(True) == "yes" and format_value([1.0, 2.5]) == "1.00, 2.50"
    assert format_value(3.11e-5) == "3.11×10⁻⁵" and format_value(194.3) == "194" and format_value(12345.6) == "12346"
    obj = jsonable({"a": np.float64(np.nan), "b": np.arange(2), "c": (1, math.inf), "d": 1 + 2j})
    assert obj == {"a": None, "b": [0, 1], "c": [1, None], "d": {"re": 1.0, "im": 2.0}}
    json.dumps(obj, allow_nan=False)


def test_write_csv(tmp_path):
    p = write_csv([{"a": 0.1, "b": [1.0, 2.0]}, {"a": None, "c": "x"}], tmp_path / "t.csv")
    rows = list(csv.reader(p.open()))
    assert rows == [["a", "b", "c"], ["0.1", "1.0;2.0", ""], ["", "", "x"]]
    with pytest.raises(InputError, match="row 0"):
        write_csv([1], tmp_path / "u.csv")


def test_long_lines_are_drawn_as_their_envelope():
    """Time plots of long records draw at most MAX_LINE_POINTS points per line, keeping
    every bucket's extremes (the drawn band equals the full one) in time order."""
    from physics.pages.plotting import envelope
    rng = np.random.default_rng(2)
    t = np.arange(1_000_003) / 1e3
    y = np.sin(2 * np.pi * 0.3 * t) + 0.1 * rng.normal(size=t.size)
    y[777_777] = 9.0                                   # a single spike must survive
    te, ye = envelope(t, y, max_points=2000)
    assert ye.size <= 2000 and np.all(np.diff(te) >= 0)
    assert ye.max() == 9.0 and ye.min() == y.min()
    short_t, short_y = envelope(t[:500], y[:500], max_points=2000)
    assert short_y is y[:500] or np.array_equal(short_y, y[:500])
