"""Figures: the numbers behind them and that each writes a real PNG."""

from __future__ import annotations

import json

import numpy as np
import pytest

from garage_mj.reporting.plots import (
    PlotError,
    convergence,
    garage_png,
    heatmap,
    heatmap_counts,
    mean_ci,
    read_monitor,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _fake_run(folder, map_name, returns):
    folder.mkdir(parents=True)
    rows = "".join(f"{r},{10 + i},{0.1 * i}\n" for i, r in enumerate(returns))
    (folder / "monitor.csv").write_text('#{"t_start": 0, "env_id": "x"}\nr,l,t\n' + rows)
    (folder / "run.json").write_text(json.dumps({"map": map_name}))
    return folder


def _is_png(path) -> bool:
    data = path.read_bytes()
    return data.startswith(PNG_MAGIC) and len(data) > 5_000


def test_mean_ci_is_a_t_interval():
    mean, half = mean_ci([np.array([1.0, 2.0, 3.0, 9.0]), np.array([3.0, 4.0, 5.0])])
    assert np.allclose(mean, [2, 3, 4])  # cut to the shortest run
    assert np.allclose(half, 12.7062, atol=1e-3)  # t(0.975, 1) * sd / sqrt(2) with sd = sqrt(2)
    mean1, half1 = mean_ci([np.array([1.0, 2.0])])
    assert np.allclose(mean1, [1, 2]) and not half1.any()


def test_heatmap_counts_bins():
    pts = np.array([[0.05, 0.95], [1.0, 1.0], [0.0, 0.0], [0.15, 0.0], [0.19, 0.01]])
    c = heatmap_counts(pts)
    assert c.shape == (10, 10) and c.sum() == 5
    assert c[9, 0] == 1  # difficulty 0.05 (x, column 0), coverage 0.95 (y, row 9)
    assert c[9, 9] == 1  # 1.0 falls in the last bin
    assert c[0, 0] == 1 and c[0, 1] == 2


def test_convergence_png(tmp_path):
    runs = [_fake_run(tmp_path / f"s{i}", "tiny_7x11", np.linspace(-50, 100, 40) + i) for i in range(3)]
    runs.append(_fake_run(tmp_path / "m5", "m5_13x13_aligned", np.linspace(0, 10, 25)))
    out = convergence(runs, tmp_path / "figs" / "conv.png", smooth=5)
    assert _is_png(out)
    assert len(read_monitor(runs[0])) == 40


def test_convergence_errors(tmp_path):
    with pytest.raises(PlotError, match="no monitor.csv"):
        convergence([tmp_path], tmp_path / "c.png")
    (tmp_path / "monitor.csv").write_text("hello\n")
    with pytest.raises(PlotError, match="not an SB3 monitor log"):
        convergence([tmp_path], tmp_path / "c.png")
    run = _fake_run(tmp_path / "r", "tiny_7x11", [1.0, 2.0])
    with pytest.raises(PlotError, match="cannot write"):
        convergence([run], tmp_path / "c.nosuchformat")


def test_heatmap_and_garage_png(tmp_path, painted_tiny):
    rng = np.random.default_rng(0)
    assert _is_png(heatmap(rng.random((50, 2)), tmp_path / "h.png", title="tiny_7x11"))
    assert _is_png(garage_png(painted_tiny, tmp_path / "g.png"))


def test_a_flat_success_rate_is_said_in_the_figure_not_drawn_as_a_fit(tmp_path, monkeypatch):
    from garage_mj.reporting import analysis

    figs = []
    monkeypatch.setattr(analysis.plt, "close", figs.append)  # keep the figure to read it
    diff = [0.55, 0.58, 0.70, 0.73, 0.77, 0.83, 0.88, 0.70]
    assert analysis.regression_plot(diff, [100.0] * 8, tmp_path / "flat.png").read_bytes()[:8] == PNG_MAGIC
    ax = figs[-1].axes[0]
    assert len(ax.lines) == 1  # the paper's line only: no flat "fit" of this run
    note = " ".join(t.get_text() for t in ax.texts)
    assert "every garage at 100% (all its tests succeeded)" in note and "no line and no r" in note
    assert "no r, no line" in ax.get_legend().get_texts()[1].get_text()
    analysis.regression_plot(diff, [100.0, 80, 100, 60, 100, 40, 80, 100], tmp_path / "varies.png")
    assert len(figs[-1].axes[0].lines) == 2 and not figs[-1].axes[0].texts  # the paper's line and this run's


def test_the_demo_figure_shows_a_run_whose_success_varies():
    from garage_mj.reporting.demo import figure_run

    flat, varies = [100.0] * 8, [80.0, 40.0, 40.0, 80.0, 0.0, 20.0, 20.0, 40.0]
    runs = {"oracle": flat, "vision": flat, "learned": [80.0, 100.0] * 4, "vision + actors": varies}
    assert figure_run("vision", runs) == "vision + actors"  # the main driver with actors first
    assert figure_run("vision", {**runs, "vision + actors": flat}) == "learned"
    assert figure_run("vision", {"vision": varies, "learned": flat}) == "vision"
    assert figure_run("vision", {"vision": flat, "oracle": flat}) == "vision"  # nothing varies: its honest figure
