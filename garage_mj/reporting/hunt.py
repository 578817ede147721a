"""A hunt as the command runs it: the search (:func:`garage_mj.driving.hunt.hunt`), then what a person
watches and reads of it.

The driving stage writes the hunt's results (``hunt.sqlite``, ``failures.csv``, packs, ``.xosc``
files); :func:`hunt` then draws ``OUT/cruise/regression.png`` (a park or AVP hunt: ``park_success.png`` in each
geometry's ``OUT/cruise/<geometry>``; :func:`garage_mj.reporting.cruise.run_figures`), records an MP4 of the first failing test of each
of the worst garages into ``OUT/videos/`` (:func:`record_videos`, the same seed as the hunt's test, named
by garage, test and outcome as cruise names its videos)
and writes ``OUT/report.html`` (:func:`write_hunt_report`): the ranking, then per worst garage its
preview, failures, files and video.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any
from urllib.parse import quote

from garage_mj.core.fsutil import FolderLock, atomic_write
from garage_mj.driving import hunt as driving_hunt
from garage_mj.driving.hunt import HuntResult, Scored, add_file, hunt_settings, run_dirs, variant_label
from garage_mj.driving.sim.outcomes import RUNNER_KINDS
from garage_mj.driving.sources import CruiseSettings
from garage_mj.export.artefacts import PREVIEW
from garage_mj.reporting.cruise import run_figures, video_name
from garage_mj.reporting.report import CSS
from garage_mj.reporting.video import record_video


def hunt(settings: CruiseSettings, out_dir: str | Path, *, videos: bool = True, **kwargs: Any) -> HuntResult:
    """:func:`garage_mj.driving.hunt.hunt` (same arguments), then the run's figures (``run_figures``), with ``videos`` the MP4s
    of the worst garages' first failing tests, and ``report.html`` (``files["report"]``, named in hunt.json)."""
    result = driving_hunt.hunt(settings, out_dir, **kwargs)
    out = result.out_dir
    with FolderLock(out, "garage-mj hunt", remove=True):
        for run in run_dirs(out):  # a park hunt's: success by level and maneuver, not the cruise regression
            run_figures(run)
        mp4s = record_videos(result) if videos else []
        report = write_hunt_report(out, result.table, result.worst, result.files["packs"], result.files["xosc"],
                                   mp4s, settings.driver)
        add_file(out, "report", report)
    result.files.update(report=report, videos=mp4s)
    return result


def record_videos(result: HuntResult) -> list[Path]:
    """``OUT/videos/<garage>_<test>_<outcome>.mp4`` (:func:`~garage_mj.reporting.cruise.video_name`, as cruise
    names its videos): the first failing test of each of the worst garages (kept if there); not a test whose
    driver crashed or hung (driven again, it would again)."""
    mp4s = []
    for s in result.worst:
        first = _watchable(s)
        if first is None:
            continue
        mp4 = result.out_dir / "videos" / s.geometry / video_name(first)  # a park hunt's: a folder per geometry
        if not mp4.is_file():
            record_video(s.source, mp4, hunt_settings(result.out_dir, s.geometry), test=int(first["test"]))
        mp4s.append(mp4)
    return mp4s


def _watchable(s: Scored) -> dict[str, str] | None:
    """The first failing test of ``s`` worth a video (a park hunt's: one the oracle parks): not one whose driver
    crashed or hung."""
    unwatchable = {k.value for k in RUNNER_KINDS}
    return next((r for r in s.confirmed if r["outcome"] not in unwatchable), None)


#: The ranking's columns in the report (failures.csv has them all).
REPORT_COLUMNS = ("rank", "garage", "difficulty", "tests", "feasible", "failures", "failure_pct", "hit",
                  "failure_progress")
#: A park or AVP hunt's: its geometry, the stall its tests were aimed at (if any), and the failures the oracle parks.
PARK_REPORT_COLUMNS = ("rank", "garage", "geometry", "stall", "difficulty", "tests", "feasible", "failures", "oracle_parks",
                       "confirmed_pct", "hit", "failure_progress")


def _href(path: Path, out: Path) -> str:
    """``path`` as a link relative to ``out`` (URL-quoted: a ``#`` in a garage's name stays part of the path)."""
    return html.escape(quote(path.relative_to(out).as_posix()))


def _card(s: Scored, pack: Path, xoscs: list[Path], mp4s: list[Path], out: Path) -> str:
    """One of the worst garages: preview, failures, its asset pack, OpenSCENARIO files and video."""
    e = html.escape
    def own(p: Path) -> bool:  # a park hunt's files lie in a folder per geometry
        return not s.geometry or p.parent.name == s.geometry

    mine = [p for p in xoscs if p.name.startswith(s.source.hash[:12]) and own(p)]
    names = {video_name(r) for r in s.confirmed}
    videos = "".join(f'<p><video src="{_href(p, out)}" controls width="480"></video><br>'
                     f'<a href="{_href(p, out)}">{e(p.name)}</a></p>' for p in mp4s if p.name in names and own(p))
    fails = "".join(f"<li>test {e(r['test'])} (seed {e(r['seed'])}): {e(r['outcome'].replace('_', ' '))}"
                    f"{' (' + e(r['hit']) + ')' if r['hit'] else ''}: {e(r['reason'])}</li>" for r in s.confirmed)
    files = " ".join(f'<a href="{_href(p, out)}">{e(p.name)}</a>' for p in mine) or "-"
    where = f" ({e(variant_label(s.geometry))}; failures the oracle parks)" if s.geometry else ""
    return (f"<h3>{e(s.source.name)}{where}: {len(s.confirmed)} of {len(s.feasible)} feasible tests failed</h3>"
            f'<div class=card><img src="{_href(pack / PREVIEW, out)}" alt="preview of {e(s.source.name)}" '
            f'style="max-width:360px"><p><a href="{_href(pack, out)}/">asset pack</a></p>'
            f"<ul class=reasons>{fails}</ul><p>OpenSCENARIO: {files}</p>{videos}</div>")


def write_hunt_report(out: Path, rows: list[dict], worst: list[Scored], packs: list[Path], xoscs: list[Path],
                      mp4s: list[Path], driver: str) -> Path:
    """``report.html`` in the demo report's style (:data:`~garage_mj.reporting.report.CSS`): the ranking, then
    per worst garage its preview, failures, files and video (``mp4s``, named as cruise names them)."""
    e = html.escape
    columns = PARK_REPORT_COLUMNS if rows and "geometry" in rows[0] else REPORT_COLUMNS
    table = "".join("<tr>" + "".join(f"<td>{e(str(r[c]))}</td>" for c in columns) + "</tr>" for r in rows[:50])
    cards = "".join(_card(s, pack, xoscs, mp4s, out) for s, pack in zip(worst, packs, strict=True))
    page = (f"<!doctype html><html lang=en><head><meta charset=utf-8>"
            "<meta name=viewport content='width=device-width,initial-scale=1'>"
            f"<title>hunt: {e(driver)}</title><style>{CSS}</style></head><body>"
            f"<h1>Hunt: where {e(driver)} fails</h1><p class=muted>{len(rows)} garages tested; ranked by failure rate "
            "on feasible tests (failures.csv has them all).</p><h2 id=ranking>Ranking</h2>"
            "<div class=wide><table id=hunt-table><thead><tr>" + "".join(f"<th>{e(c)}</th>" for c in columns)
            + f"</tr></thead><tbody>{table}</tbody></table></div><h2 id=worst>The worst garages</h2>"
            + cards + "</body></html>")
    path = out / "report.html"
    atomic_write(path, page)
    return path
