"""The HTML report: self-contained, every image loads in a real browser, tables are filled."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from garage_mj.reporting.report import GalleryItem, ReportData, render_html, write_report  # noqa: E402
from tests.browser import page_facts  # noqa: E402


def png(path, label):
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    ax.set_title(label)
    fig.savefig(path)
    plt.close(fig)
    return path


def sample(tmp_path) -> ReportData:
    figs = tmp_path / "figs"
    figs.mkdir()
    pack = tmp_path / "packs" / "garage-1"
    pack.mkdir(parents=True)
    return ReportData(
        title="garage-mj demo",
        subtitle="tiny_7x11",
        kpis={"usable garages": "12"},
        convergence_png=png(figs / "conv.png", "conv"),
        heatmap_png=png(figs / "heat.png", "heat"),
        gallery=[GalleryItem(1, 0.5, 0.8, 40, png(figs / "p1.png", "p1"), png(figs / "r1.png", "r1"), pack)],
        cruise_columns=["garage", "driver", "success %"],
        cruise_rows=[[1, "waypoint", 100.0], [1, "vision", 60.0]],
        regression_png=png(figs / "reg.png", "reg"),
        regression_text="r = -0.5",
    )


def test_report_opens_in_chromium_with_every_image(tmp_path):
    path = write_report(sample(tmp_path), tmp_path)
    facts = page_facts(path)
    assert facts["title"] == "garage-mj demo"
    assert len(facts["imgs"]) == 5 and all(i["loaded"] for i in facts["imgs"]), facts["imgs"]
    (table,) = facts["tables"]
    assert table["id"] == "cruise-table" and table["rows"] == 2 and table["empty_cells"] == 0
    assert "packs/garage-1/" in facts["links"]
    html = path.read_text()
    assert "http://" not in html and "https://" not in html and "<script" not in html


def test_report_refuses_missing_images(tmp_path):
    data = sample(tmp_path)
    data.heatmap_png.unlink()
    with pytest.raises(FileNotFoundError, match="heat.png"):
        write_report(data, tmp_path)
    assert not (tmp_path / "report.html").exists()


def test_html_escapes_text(tmp_path):
    data = ReportData(title="<b>x</b>", notes=["a & b"])
    html = render_html(data, tmp_path)
    assert "&lt;b&gt;x&lt;/b&gt;" in html and "a &amp; b" in html
