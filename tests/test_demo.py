"""The main job end to end at toy scale: every stage runs, the report opens in Chromium."""

from __future__ import annotations

import json

from garage_mj.reporting.demo import DemoConfig, run_demo
from tests.browser import page_facts


def test_demo_end_to_end_report_in_chromium(tmp_path):
    cfg = DemoConfig(timesteps=2500, train_seeds=(0, 1), garages=2, tests=1, workers=1, out=str(tmp_path / "demo"))
    report = run_demo(cfg)
    assert report == tmp_path / "demo" / "report.html"
    facts = page_facts(report)
    assert facts["imgs"] and all(i["loaded"] for i in facts["imgs"]), facts["imgs"]
    # convergence + heatmap + (preview + MuJoCo render) per garage + regression
    garages = len([link for link in facts["links"] if link.startswith("packs/")])
    assert garages >= 1
    assert len(facts["imgs"]) == 2 + 2 * garages + 1
    (table,) = facts["tables"]
    # every driver, then the actor drivers again with adverse events (pedestrians, moving cars, clutter)
    assert table["rows"] == garages * (len(cfg.drivers) + len(cfg.actor_drivers)) and table["empty_cells"] == 0
    text = report.read_text()
    assert "vision + actors" in text and "collisions by what was hit" in text
    for link in facts["links"]:
        assert (report.parent / link / "manifest.json").is_file()
    index = json.loads((tmp_path / "demo" / "packs" / "index.json").read_text())
    assert len(index["packs"]) == garages
    # a second run resumes every stage and rewrites the same report
    before = (tmp_path / "demo" / "cruise" / "vision" / "tests.csv").read_text()
    run_demo(cfg)
    assert (tmp_path / "demo" / "cruise" / "vision" / "tests.csv").read_text() == before
