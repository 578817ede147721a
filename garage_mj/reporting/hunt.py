"""A hunt as the command runs it: the search (:func:`garage_mj.driving.hunt.hunt`), then what a person
watches and reads of it.

The driving stage writes the hunt's results (``hunt.sqlite``, ``failures.csv``, packs, ``.xosc``
files); :func:`hunt` then draws ``OUT/cruise/regression.png``
(:func:`garage_mj.reporting.cruise.cruise_figure`), records an MP4 of the first failing test of each
of the worst garages into ``OUT/videos/`` (:func:`record_videos`, the same seed as the hunt's test, the
outcome in the file name)
and writes ``OUT/report.html`` (:func:`write_hunt_report`): the ranking, then per worst garage its
preview, failures, files and video.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

from garage_mj.core.fsutil import FolderLock, atomic_write
from garage_mj.driving import hunt as driving_hunt
from garage_mj.driving.hunt import HuntResult, Scored, add_file, read_settings
from garage_mj.driving.sim.outcomes import RUNNER_KINDS
from garage_mj.driving.sources import CruiseSettings
from garage_mj.export.artefacts import PREVIEW
from garage_mj.reporting.cruise import cruise_figure
from garage_mj.reporting.video import record_video


def hunt(settings: CruiseSettings, out_dir: str | Path, *, videos: bool = True, **kwargs: Any) -> HuntResult:
    """:func:`garage_mj.driving.hunt.hunt` (same arguments), then the cruise figure, with ``videos`` the MP4s
    of the worst garages' first failing tests, and ``report.html`` (``files["report"]``, named in hunt.json)."""
    result = driving_hunt.hunt(settings, out_dir, **kwargs)
    out = result.out_dir
    with FolderLock(out, "garage-mj hunt", remove=True):
        cruise_figure(out / "cruise")
        mp4s = record_videos(result) if videos else []
        report = write_hunt_report(out, result.table, result.worst, result.files["packs"], result.files["xosc"],
                                   mp4s, settings.driver)
        add_file(out, "report", report)
    result.files.update(report=report, videos=mp4s)
    return result


def record_videos(result: HuntResult) -> list[Path]:
    """``OUT/videos/<hash 12>_<test>_<outcome>.mp4``: the first failing test of each of the worst garages (kept
    if there); not a test whose driver crashed or hung (driven again, it would again)."""
    settings = CruiseSettings.from_stored(read_settings(result.out_dir))
    unwatchable = {k.value for k in RUNNER_KINDS}
    mp4s = []
    for s in result.worst:
        first = next((r for r in s.failures if r["outcome"] not in unwatchable), None)
        if first is None:
            continue
        i = int(first["test"])
        mp4 = result.out_dir / "videos" / f"{s.source.hash[:12]}_{i:05d}_{first['outcome']}.mp4"
        if not mp4.is_file():
            record_video(s.source, mp4, settings, test=i)
        mp4s.append(mp4)
    return mp4s


def write_hunt_report(out: Path, rows: list[dict], worst: list[Scored], packs: list[Path], xoscs: list[Path],
                      mp4s: list[Path], driver: str) -> Path:
    """``report.html``: the ranking, then per worst garage its preview, failures, files and videos (``mp4s``)."""
    e = html.escape
    head = ["rank", "garage", "difficulty", "tests", "feasible", "failures", "failure_pct", "hit",
            "failure_progress"]
    table = "".join("<tr>" + "".join(f"<td>{e(str(r[c]))}</td>" for c in head) + "</tr>" for r in rows[:50])
    cards = []
    for s, pack in zip(worst, packs, strict=True):
        rel = pack.relative_to(out)
        mine = [p for p in xoscs if p.name.startswith(s.source.hash[:12])]
        vid = [p for p in mp4s if p.name.startswith(s.source.hash[:12])]
        fails = "".join(f"<li>test {e(r['test'])} (seed {e(r['seed'])}): {e(r['outcome'])}"
                        f"{' (' + e(r['hit']) + ')' if r['hit'] else ''}: {e(r['reason'])}</li>" for r in s.failures)
        files = " ".join(f'<a href="{e(str(p.relative_to(out)))}">{e(p.name)}</a>' for p in mine)
        video = "".join(f'<p><video src="{e(str(p.relative_to(out)))}" controls width="480"></video></p>' for p in vid)
        preview = rel / PREVIEW
        cards.append(f'<section><h3>{e(s.source.name)}: {len(s.failures)} of {len(s.feasible)} feasible tests '
                     f'failed</h3><p><a href="{e(str(rel))}">asset pack</a></p>'
                     f'<img src="{e(str(preview))}" alt="preview of {e(s.source.name)}" width="360">'
                     f'<ul>{fails}</ul><p>OpenSCENARIO: {files}</p>{video}</section>')
    page = (f"<!doctype html><html><head><meta charset='utf-8'><title>hunt: {e(driver)}</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{border:1px solid #ccc;padding:2px 6px}"
            "table{border-collapse:collapse}</style></head><body>"
            f"<h1>Hunt: where {e(driver)} fails</h1><p>{len(rows)} garages tested; ranked by failure rate on "
            "feasible tests (failures.csv has them all).</p><table><tr>"
            + "".join(f"<th>{e(c)}</th>" for c in head) + f"</tr>{table}</table><h2>The worst garages</h2>"
            + "".join(cards) + "</body></html>")
    path = out / "report.html"
    atomic_write(path, page)
    return path
