"""What a park or AVP run is judged by, as a figure: success by level and by maneuver (``park_success.png``).

A cruise run's figures regress success on the paper's difficulty (:mod:`garage_mj.reporting.cruise`); a park run's
tests are judged by docs/spec.md section 9 instead, and its ``summary.json`` breaks success down by level
(``by_level``: normal, complex, extreme), maneuver (``by_maneuver``) and stall angle
(:data:`~garage_mj.driving.results.BREAKDOWNS`). :func:`park_figure` draws level, maneuver and the park difficulty
bands (the failure probability the run's park model predicts, ``park_difficulty``: success should fall from band to
band) as bars of success %
over the feasible tests of each group, each bar labelled with its count (``9/10``); a group without a feasible
test is named with what it had (``0 feasible``, its unproven tests), never drawn as a 0% bar, and every level has
its place, ``no tests`` where the run had none.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from garage_mj.core.fsutil import atomic_write  # noqa: E402
from garage_mj.reporting.plots import DPI  # noqa: E402
from garage_mj.reporting.report import task_noun  # noqa: E402
from garage_mj.scene.park_levels import LEVELS  # noqa: E402

PARK_FIGURE = "park_success.png"  # a park or AVP run's figure, in its folder
#: The breakdowns of summary.json the figure draws, one panel each, and the panel's title.
PANELS = {"by_level": "by level", "by_maneuver": "by maneuver", "by_park_difficulty": "by park difficulty"}
LEVEL_COLOURS = {"normal": "#16a34a", "complex": "#d97706", "extreme": "#dc2626"}
BAR_COLOUR = "#2563eb"  # a group that is not a level
FIGURE_SIZE = (10.5, 3.4)  # [in] at plots' DPI


def group_label(group: dict[str, Any]) -> str:
    """A bar's count: ``9/10`` (successes of feasible), with its unproven tests; ``0 feasible`` without any."""
    count = f"{group['successes']}/{group['feasible']}" if group["feasible"] else "0 feasible"
    return count + (f", {group['unproven']} unproven" if group.get("unproven") else "")


def _panel(ax, title: str, groups: dict[str, dict[str, Any]], always: tuple[str, ...] = (),
           empty: str = "no tests") -> None:
    """One breakdown's bars; the groups of ``always`` (the levels) stand in their place even without a test."""
    names = [*always, *(n for n in groups if n not in always)] or [empty]
    for k, name in enumerate(names):
        g = groups.get(name)
        if g is None:  # a level without a test (its place is kept), or the panel's only tick saying it is empty
            if name in always:
                ax.text(k, 2.0, "no tests", ha="center", va="bottom", fontsize=8, color="0.45")
            continue
        pct = g["success_pct"]
        if pct is not None:
            ax.bar(k, pct, width=0.6, color=LEVEL_COLOURS.get(name, BAR_COLOUR), alpha=0.85)
        ax.text(k, (pct or 0.0) + 2.0, group_label(g), ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(names)), [n or "n/a" for n in names])
    ax.set(ylim=(0, 115), xlim=(-0.6, max(len(names), 2) - 0.4), title=title)
    ax.set_yticks(range(0, 101, 25))
    ax.grid(axis="y", alpha=0.3)


def park_figure(out_dir: str | Path) -> Path | None:
    """``park_success.png`` of the park or AVP run in ``out_dir``: success % of the feasible tests by level and by
    maneuver (``summary.json``'s breakdowns), each bar with its count; None (nothing drawn) for a cruise run, whose
    summary has no breakdown."""
    out = Path(out_dir)
    stats = json.loads((out / "summary.json").read_text())
    if not all(key in stats for key in ("by_level", "by_maneuver")):
        return None
    fig, axes = plt.subplots(1, len(PANELS), figsize=FIGURE_SIZE, sharey=True)
    for ax, (key, title) in zip(axes, PANELS.items(), strict=True):
        _panel(ax, title, stats.get(key, {}), LEVELS if key == "by_level" else (),
               "no park model" if key == "by_park_difficulty" else "no tests")
    axes[0].set_ylabel("success of feasible tests [%]")
    task = stats.get("task", "park")
    fig.suptitle(f"{task_noun(task)} success ({stats.get('driver', '?')}, {stats['feasible']} feasible of "
                 f"{stats['tests']} tests)", fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    plt.close(fig)
    return atomic_write(out / PARK_FIGURE, buf.getvalue())
