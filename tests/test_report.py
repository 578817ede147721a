"""The HTML report: self-contained, every image loads in a real browser, tables are filled, the failures'
reasons are listed per class with links to tests.csv, videos and .xosc files that open after the folder moves,
and numbers are written the same way everywhere."""

from __future__ import annotations

import shutil

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from garage_mj.reporting.failures import group_reasons  # noqa: E402
from garage_mj.reporting.report import (  # noqa: E402
    FailureItem,
    GalleryItem,
    ReasonGroup,
    ReportData,
    RunFailures,
    count_noun,
    fmt_difficulty,
    fmt_percent,
    render_html,
    write_report,
)
from tests.browser import page_facts, table_fit  # noqa: E402


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


def failures_sample(tmp_path) -> ReportData:
    """A report with one driver run's failures: tests.csv, one failure with its MP4 and .xosc, one with a .xosc only."""
    run = tmp_path / "out" / "cruise" / "vision"
    (run / "videos").mkdir(parents=True)
    (run / "xosc").mkdir()
    (run / "tests.csv").write_text("garage,test,outcome\n")
    video = run / "videos" / "abc_00001.mp4"
    video.write_bytes(b"mp4")
    xoscs = [run / "xosc" / "abc_00001.xosc", run / "xosc" / "abc_00003.xosc"]
    for x in xoscs:
        x.write_text("<OpenSCENARIO/>")
    failures = RunFailures(
        label="vision", action_type="continuous", tests_csv=run / "tests.csv", feasible=10,
        counts={"collision": 3, "missed_goal": 1},
        reasons={"collision": [ReasonGroup("hit parked_car at 0.4–1.2 m/s (parkedcar_3_hull)", 3)],
                 "missed_goal": [ReasonGroup("stopped 1.20 m and 0.40 rad from the goal pose", 1)]},
        shown=[FailureItem("tiny#1", 1, "collision", "hit parked_car parkedcar_3_hull at 1.2 m/s", video, xoscs[0]),
               FailureItem("tiny#1", 3, "missed_goal", "stopped 1.20 m and 0.40 rad from the goal pose", None,
                           xoscs[1])])
    return ReportData(title="demo", failures=[failures])


def test_report_lists_reasons_per_class_and_links_files_that_survive_a_move(tmp_path):
    data = failures_sample(tmp_path)
    write_report(data, tmp_path / "out")
    moved = tmp_path / "moved"
    shutil.move(tmp_path / "out", moved)  # links are relative: the folder works anywhere
    facts = page_facts(moved / "report.html")
    text = facts["text"]
    assert "vision · continuous actions" in text
    assert "4 failures in 10 feasible tests" in text
    assert "collision (3)\n3 × hit parked_car at 0.4–1.2 m/s (parkedcar_3_hull)" in text
    assert "missed goal (1)\n1 × stopped 1.20 m and 0.40 rad from the goal pose" in text
    assert "the first 2 of 4 failures (all of them in tests.csv)" in text
    assert sorted(facts["links"]) == ["cruise/vision/tests.csv", "cruise/vision/videos/abc_00001.mp4",
                                      "cruise/vision/xosc/abc_00001.xosc", "cruise/vision/xosc/abc_00003.xosc"]
    for link in facts["links"]:
        assert (moved / link).is_file(), link
    (shown,) = [t for t in facts["tables"] if t["id"] == "" and t["head"][0] == "garage"]
    assert shown["cells"][1][-2:] == ["-", "abc_00003.xosc"]  # no video recorded: said, not a dead link


def test_report_refuses_a_missing_failure_file(tmp_path):
    data = failures_sample(tmp_path)
    data.failures[0].shown[0].video.unlink()
    with pytest.raises(FileNotFoundError, match="abc_00001.mp4"):
        write_report(data, tmp_path / "out")
    assert not (tmp_path / "out" / "report.html").exists()


def test_reasons_are_grouped_per_class_with_number_ranges():
    rows = [
        {"outcome": "missed_goal", "hit_geom": "", "reason": "stopped 1.59 m and 0.30 rad from the goal pose"},
        {"outcome": "missed_goal", "hit_geom": "", "reason": "stopped 1.01 m and 0.02 rad from the goal pose"},
        {"outcome": "collision", "hit_geom": "parkedcar_36_hull", "reason": "hit parked_car parkedcar_36_hull at 0.5 m/s"},
        {"outcome": "collision", "hit_geom": "parkedcar_48_hull", "reason": "hit parked_car parkedcar_48_hull at 1.2 m/s"},
        {"outcome": "collision", "hit_geom": "obstacle_5", "reason": "hit obstacle obstacle_5 at 2.9 m/s"},
        {"outcome": "deadlock", "hit_geom": "", "reason": "no progress for 8.1 s"},
        {"outcome": "success", "hit_geom": "", "reason": "stopped at the goal (0.20 m, 0.01 rad)"},
    ]
    groups = group_reasons(rows)
    assert set(groups) == {"missed_goal", "collision", "deadlock"}  # failures only
    assert groups["missed_goal"] == [ReasonGroup("stopped 1.01–1.59 m and 0.02–0.30 rad from the goal pose", 2)]
    # digits inside a geom name are not numbers; the geoms are named apart
    assert groups["collision"] == [ReasonGroup("hit parked_car at 0.5–1.2 m/s (parkedcar_36_hull, parkedcar_48_hull)", 2),
                                   ReasonGroup("hit obstacle at 2.9 m/s (obstacle_5)", 1)]
    assert groups["deadlock"] == [ReasonGroup("no progress for 8.1 s", 1)]


def test_numbers_are_written_one_way():
    # summary.csv rounds a difficulty to 4 decimals; formatting that again gave 0.766 where the gallery said 0.765
    assert fmt_difficulty(0.76549) == "0.765" and fmt_difficulty(1) == "1.000"
    assert fmt_percent(100.0) == "100.0%" and fmt_percent(33.333) == "33.3%" and fmt_percent(None) == "n/a"
    assert count_noun(1, "pedestrian") == "1 pedestrian" and count_noun(2, "moving car") == "2 moving cars"
    assert count_noun(0, "clutter object") == "0 clutter objects"


@pytest.mark.parametrize("width", [1400, 1920])
def test_the_cruise_table_fits_the_window(tmp_path, width):
    """The demo's cruise table, long names and all: its last column (success of feasible) is in view, no
    sideways scrolling (it was cut off at 1400 and 1920 px)."""
    from garage_mj.driving.results import COUNT_COLUMNS
    from garage_mj.reporting.demo import _failure_cells

    columns = ["garage", "driver", "actions", "difficulty", "route difficulty", "E[X]", "E[Y]", "tests", "infeasible",
               *_failure_cells({k: c.replace("_", " ") for k, c in COUNT_COLUMNS.items()}, "what was hit"),
               "success of feasible"]
    row = ["tiny_7x11-3_b9bef0599e78", "my_driver:MyCarefulDriver + actors", "continuous", "0.553", "n/a", 4.667,
           2.0, 50, 3, *_failure_cells({k: 12 for k in COUNT_COLUMNS}, "parked_car 3, wall 2, pillar 1, pedestrian 1"),
           "88.0%"]
    path = write_report(ReportData(title="t", cruise_columns=columns, cruise_rows=[row] * 3), tmp_path)
    (fit,) = table_fit(path, width)
    assert fit["id"] == "cruise-table" and fit["last_right"] <= fit["inner"], fit
    assert fit["box_scroll"] <= 1 and fit["page_scroll"] == 0, fit


# -- a cruise run's own report (garage-mj cruise --report): the park table and the failures' pictures ----------------
STAND_STILL = "tests._crashing:_Stop"  # a driver that never moves: every park test fails


@pytest.fixture(scope="module")
def tiny_garage():
    from garage_mj.grid.painters import paint_garage

    return paint_garage("tiny_7x11", seed=1)


def test_a_park_run_report_has_the_park_table_and_a_picture_per_failure_shown(tiny_garage, tmp_path):
    from garage_mj.cli import main
    from garage_mj.driving.results import PARK_SUMMARY_COLUMNS
    from garage_mj.export.pack import export_pack
    from garage_mj.reporting.park import PICTURES, SUCCESS_NOTE, column_label
    from garage_mj.reporting.run_report import REPORT_FAILURES

    export_pack(tiny_garage, tmp_path / "packs")
    out = tmp_path / "park"
    assert main(["cruise", "--packs", str(tmp_path / "packs"), "--tests", str(REPORT_FAILURES + 1), "--driver",
                 STAND_STILL, "--task", "park", "--out", str(out), "--quiet", "--report"]) == 0
    pictures = sorted((out / PICTURES).glob("*.png"))
    assert len(pictures) == REPORT_FAILURES  # one per failure shown, not one per failure
    facts = page_facts(out / "report.html")
    assert "Park tests" in facts["headings"]
    park = next(t for t in facts["tables"] if t["id"] == "park-table-1")
    labels = [column_label(c) for c in PARK_SUMMARY_COLUMNS]
    assert park["head"] == ["garage", "tests", "infeasible", "success of feasible", *labels]
    assert "mean position error [m]" in labels and "collision %" in labels
    assert park["rows"] == 2 and park["cells"][-1][0] == "all garages" and park["cells"][0][3] == "0.0%"
    assert SUCCESS_NOTE in facts["text"] and "0.6 m lateral" in SUCCESS_NOTE
    failures = next(t for t in facts["tables"] if t["head"][:2] == ["garage", "test"])
    assert failures["head"][-1] == "top-down" and failures["rows"] == REPORT_FAILURES
    shown = [i for i in facts["imgs"] if PICTURES in i["src"]]
    assert sorted(i["src"].rsplit("/", 1)[1] for i in shown) == [p.name for p in pictures]
    assert facts["imgs"] and all(i["loaded"] for i in facts["imgs"]), facts["imgs"]
    assert all(f"{PICTURES}/{p.name}" in facts["links"] for p in pictures)


def test_an_oracle_park_run_report_shows_its_success_and_no_picture(tiny_garage, tmp_path):
    from garage_mj.core.backends import Compute
    from garage_mj.driving.sources import CruiseSettings
    from garage_mj.reporting.cruise import run_cruise
    from garage_mj.reporting.park import PICTURES
    from garage_mj.reporting.run_report import cruise_report

    out = tmp_path / "oracle"
    run_cruise([tiny_garage], 2, CruiseSettings("oracle", 0, task="park"), out, compute=Compute(progress=False))
    facts = page_facts(cruise_report(out, [tiny_garage]))
    park = next(t for t in facts["tables"] if t["id"] == "park-table-1")
    assert [row[3] for row in park["cells"]] == ["100.0%", "100.0%"]
    assert not (out / PICTURES).exists() and all(i["loaded"] for i in facts["imgs"])


def test_a_cruise_run_report_has_no_park_table(tiny_garage, tmp_path):
    from garage_mj.core.backends import Compute
    from garage_mj.driving.sources import CruiseSettings
    from garage_mj.reporting.cruise import run_cruise
    from garage_mj.reporting.park import PICTURES, park_table
    from garage_mj.reporting.run_report import cruise_report

    out = tmp_path / "cruise"
    env = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits: a quick failure
    run_cruise([tiny_garage], 1, CruiseSettings(STAND_STILL, 0, env=env), out, compute=Compute(progress=False))
    assert park_table(out) is None
    path = cruise_report(out, [tiny_garage])
    facts = page_facts(path)
    assert "Park tests" not in facts["headings"] and not any(t["id"].startswith("park") for t in facts["tables"])
    assert not any("top-down" in t["head"] for t in facts["tables"]) and not (out / PICTURES).exists()
    assert "park-table" not in path.read_text()
