"""A hunt as the command runs it: the search (:func:`garage_mj.driving.hunt.hunt`), then what a person
watches and reads of it.

The driving stage writes the hunt's results (``hunt.sqlite``, ``failures.csv``, packs, ``.xosc``
files, ``report.html``); :func:`hunt` then draws ``OUT/cruise/regression.png``
(:func:`garage_mj.reporting.cruise.cruise_figure`), records an MP4 of the first failing test of each
of the worst garages into ``OUT/videos/`` (:func:`garage_mj.reporting.video.record_video`, the same
seed as the hunt's test) and writes ``report.html`` again with the videos in it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from garage_mj.core.fsutil import FolderLock
from garage_mj.driving import hunt as driving_hunt
from garage_mj.driving.hunt import HuntResult, read_settings, write_report
from garage_mj.reporting.cruise import cruise_figure
from garage_mj.reporting.video import record_video


def hunt(driver: str, out_dir: str | Path, *, videos: bool = True, **kwargs: Any) -> HuntResult:
    """:func:`garage_mj.driving.hunt.hunt` (same arguments), then the cruise figure and, with ``videos``,
    the MP4s of the worst garages' first failing tests and ``report.html`` with them."""
    result = driving_hunt.hunt(driver, out_dir, **kwargs)
    out = result.out_dir
    with FolderLock(out, "garage-mj hunt"):
        cruise_figure(out / "cruise")
        if videos:
            result.files["videos"] = record_videos(result)
            if result.files["videos"]:
                write_report(out, result.table, result.worst, result.files["packs"], result.files["xosc"],
                             result.files["videos"], driver)
    return result


def record_videos(result: HuntResult) -> list[Path]:
    """``OUT/videos/<hash 12>_<test>.mp4``: the first failing test of each of the worst garages (kept if there)."""
    settings = read_settings(result.out_dir)
    mp4s = []
    for s in result.worst:
        if not s.failures:
            continue
        i = int(s.failures[0]["test"])
        mp4 = result.out_dir / "videos" / f"{s.source.hash[:12]}_{i:05d}.mp4"
        if not mp4.is_file():
            record_video(s.source, mp4, driver=settings["driver"], seed=settings["seed"], test=i,
                         action_type=settings["action_type"], occupancy=settings["occupancy"], env=settings["env"])
        mp4s.append(mp4)
    return mp4s
