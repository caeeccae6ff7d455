"""The shared result-file writers (posekit.report)."""

import json

import numpy as np

from posekit.report import (
    html_figure,
    html_table,
    pyplot,
    save_figure,
    to_jsonable,
    write_csv,
    write_html,
    write_json,
)


def test_csv_floats_nan_and_missing_keys(tmp_path):
    path = write_csv(tmp_path / "t.csv", [{"a": 1.0 / 3.0, "b": "x"}, {"a": float("nan")}], ["a", "b"])
    assert path.read_text().splitlines() == ["a,b", "0.333333,x", "nan,"]


def test_json_converts_numpy_and_non_finite(tmp_path):
    data = {"v": np.array([1.5, np.nan]), "i": np.int64(3), "b": np.bool_(True), 4: (np.float32(2.0), np.inf)}
    assert to_jsonable(data) == {"v": [1.5, None], "i": 3, "b": True, "4": [2.0, None]}
    assert json.loads(write_json(tmp_path / "d.json", data).read_text()) == to_jsonable(data)


def test_html_table_escapes_and_formats():
    text = html_table([{"name": "<a&b>", "v": 1234.5678}, {"name": "nan", "v": float("nan")}], ["name", "v"],
                      headers=["Name", "Value"])
    assert "<th>Name</th><th>Value</th>" in text
    assert "<td>&lt;a&amp;b&gt;</td><td>1235</td>" in text
    assert "<td>nan</td><td>–</td>" in text
    assert html_table([{"v": 2.0}], ["v"], cell=lambda v, c: f"{c}={v:.1f}").count("<td>v=2.0</td>") == 1


def test_report_embeds_figure(tmp_path):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    png = save_figure(fig, tmp_path / "f.png", dpi=50)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    page = write_html(tmp_path, "T <1>", "<p>intro</p>", [("Figures", html_figure(png, "a & b"))]).read_text()
    assert "<title>T &lt;1&gt;</title>" in page and "<h2>Figures</h2>" in page
    assert 'src="data:image/png;base64,iVBORw0KGgo' in page and "a &amp; b" in page and 'href="f.png"' in page
