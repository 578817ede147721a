"""The failures of a cruise run as a report shows them: the reasons grouped per failure class, and the
first few failing tests with their MP4, OpenSCENARIO file and (park or AVP) top-down picture.

A class's reasons are grouped by their wording with the numbers taken out, so eight "stopped 1.01 m
..." to "stopped 1.59 m ..." lines read as one line with the range, "stopped 1.01–1.59 m ...", and
its count; a collision's geom name is taken out of its reason and listed apart. The tests shown
are the first failures in garage order (the run's sources) and test index, so a re-run shows the
same ones: the ones :func:`garage_mj.reporting.cruise.record_cruise_videos` records first.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path

from garage_mj.driving.cruise import xosc_name
from garage_mj.driving.results import FAILURE_KINDS, driven_tests, failed_tests, failure_counts
from garage_mj.driving.sources import CruiseSource
from garage_mj.reporting.report import FailureItem, ReasonGroup, RunFailures

#: A number standing alone in a reason ("1.2 m", "8.0 s"), not a digit inside a name ("parkedcar_36_hull").
_NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d+)?(?![\w.])")
GEOMS_NAMED = 3  # geom names listed per reason group before "+N more"


def group_reasons(rows: Sequence[dict[str, str]]) -> dict[str, list[ReasonGroup]]:
    """Failure class -> its reasons, grouped by wording (numbers become their range), most frequent first."""
    out: dict[str, list[ReasonGroup]] = {}
    for kind in FAILURE_KINDS:
        groups: dict[str, list[tuple[list[str], str]]] = {}
        for r in rows:
            if r["outcome"] != kind:
                continue
            reason = r.get("reason", "") or "(no reason recorded)"
            geom = r.get("hit_geom", "") or ""
            if geom:
                reason = " ".join(reason.replace(geom, " ").split())
            groups.setdefault(_NUMBER.sub("#", reason), []).append((_NUMBER.findall(reason), geom))
        found = [_group(template, members) for template, members in groups.items()]
        if found:
            out[kind] = sorted(found, key=lambda g: (-g.count, g.text))
    return out


def _group(template: str, members: list[tuple[list[str], str]]) -> ReasonGroup:
    """One line for the reasons sharing ``template``: each number slot as its range over the members."""
    pieces = template.split("#")
    text = pieces[0]
    for slot, rest in enumerate(pieces[1:]):
        values = sorted({m[0][slot] for m in members}, key=float)
        text += values[0] if len(values) == 1 else f"{values[0]}–{values[-1]}"
        text += rest
    geoms = sorted({g for _, g in members if g})
    if geoms:
        named = ", ".join(geoms[:GEOMS_NAMED])
        text += f" ({named}{f', +{len(geoms) - GEOMS_NAMED} more' if len(geoms) > GEOMS_NAMED else ''})"
    return ReasonGroup(text, len(members))


def first_failures(rows: Sequence[dict[str, str]], sources: Sequence[CruiseSource], n: int) -> list[dict[str, str]]:
    """The first ``n`` failing tests in the order of ``sources`` and then of the test index."""
    order = {s.hash: i for i, s in enumerate(sources)}
    failed = [r for r in failed_tests(rows) if r["garage_hash"] in order]
    return sorted(failed, key=lambda r: (order[r["garage_hash"]], int(r["test"])))[:n]


def run_failures(label: str, run_dir: Path, rows: Sequence[dict[str, str]], sources: Sequence[CruiseSource],
                 shown: int = 3, pictures: dict[tuple[str, int], Path] | None = None) -> RunFailures:
    """What the report shows of the cruise run in ``run_dir``: counts and reasons per class, and the first
    ``shown`` failures with their ``.xosc`` (``run_cruise(..., xosc=True)`` wrote them) and their MP4
    (:func:`garage_mj.reporting.cruise.record_cruise_videos` wrote them into ``videos/``) and, for a park or AVP
    run, their top-down picture (``pictures``: (garage hash, test) -> PNG, as
    :func:`garage_mj.reporting.park.record_park_pictures` returns them), each when there."""
    from garage_mj.reporting.cruise import video_name  # matplotlib: deferred, so garage-mj --help stays light

    run_dir = Path(run_dir)
    settings = json.loads((run_dir / "run.json").read_text())
    by_hash = {s.hash: s for s in sources}
    items = []
    for r in first_failures(rows, sources, shown):
        test = int(r["test"])
        xosc = run_dir / "xosc" / xosc_name(by_hash[r["garage_hash"]], test)
        mp4 = run_dir / "videos" / video_name(r)
        png = (pictures or {}).get((r["garage_hash"], test))
        items.append(FailureItem(r["garage"], test, r["outcome"], r["reason"], mp4 if mp4.is_file() else None,
                                 xosc if xosc.is_file() else None, png))
    feasible = driven_tests(rows)
    counts = failure_counts(feasible)
    return RunFailures(label=label, action_type=settings["action_type"], tests_csv=run_dir / "tests.csv",
                       feasible=len(feasible), counts={k: v for k, v in counts.items() if v},
                       reasons=group_reasons(feasible), shown=items)
