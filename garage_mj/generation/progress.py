"""Where each run of a protocol stands, read from its folder: ``generation/run.py CONFIG --status``.

For every (map, seed) of a protocol: its status, timesteps done of its total, the garages the
library holds from it, and its timesteps/s. Everything comes from disk (``run.json`` with its
``live`` progress, the checkpoints, the library opened read-only), so the view works from any
shell while the protocol runs, locally or on Ray (where the head keeps the run folders), or after
it stopped. Statuses:

- ``new``: not started;
- ``running``: a process holds the protocol folder's lock (:func:`~garage_mj.core.fsutil.lock_holder`:
  the kernel drops it when the process dies, even by ``kill -9``) and the run's ``live`` progress is
  younger than :data:`STALE_S` (refreshed every :data:`~garage_mj.generation.training.HEARTBEAT_S`
  and at each checkpoint);
- ``resume``: started and stopped (Ctrl-C, a killed process, a lost node): a re-run of the same
  command continues it from its newest checkpoint, whose timesteps are shown (the total line then
  says "stopped (not running; run the same command to resume)");
- ``finished``: nothing left to do.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from garage_mj.core.fsutil import lock_holder
from garage_mj.generation.library import Library, LibraryError
from garage_mj.generation.protocol import LIBRARY, Protocol, run_dir, run_status
from garage_mj.generation.runs import latest_checkpoint
from garage_mj.generation.training import HEARTBEAT_S, TrainingError, read_manifest

STALE_S = 4 * HEARTBEAT_S  # [s] a run whose live progress is older than this is not running any more


@dataclass(frozen=True)
class RunProgress:
    """One run's line of the progress view."""

    map: str
    seed: int
    status: str  # new, running, resume, finished
    timesteps: int  # done: live while running, the newest checkpoint's when stopped
    target: int
    garages: int  # rows of the library credited to this run
    timesteps_per_s: float | None  # the current session's while running, else the last session's
    where: str  # the host (and Ray node) of the last attempt, when it ran on Ray


def _age_s(stamp: str | None) -> float:
    try:
        t = datetime.fromisoformat(str(stamp))
    except ValueError:
        return float("inf")
    return (datetime.now(timezone.utc) - t).total_seconds()


def _run_progress(folder: Path, map: str, seed: int, target: int, lib: Library | None, held: bool) -> RunProgress:
    status = run_status(folder, target)
    if status == "new":
        return RunProgress(map, seed, "new", 0, target, 0, None, "")
    try:
        m: dict[str, Any] = read_manifest(folder)
    except TrainingError:
        return RunProgress(map, seed, "resume", 0, target, 0, None, "")
    live = m.get("live") if isinstance(m.get("live"), dict) else {}
    garages = lib.count(run=m["run"]) if lib is not None and "run" in m else 0
    attempts = m.get("attempts") or []
    where = ""
    if attempts:
        a = attempts[-1]
        where = f"{a.get('host', '?')} {str(a.get('node') or '')[:8]}".strip()
    if status == "finished":
        rate = (m.get("last_session") or {}).get("timesteps_per_s")
        return RunProgress(map, seed, status, int(m.get("timesteps", 0)), target, garages, rate, where)
    if held and m.get("status") == "running" and _age_s(live.get("updated_at")) < STALE_S:
        return RunProgress(map, seed, "running", int(live.get("timesteps", m.get("timesteps", 0))), target, garages,
                           live.get("timesteps_per_s"), where)
    found = latest_checkpoint(folder)
    done = int(found[1]["timesteps"]) if found else 0
    return RunProgress(map, seed, "resume", done, target, garages, live.get("timesteps_per_s"), where)


def protocol_progress(protocol: Protocol, out: str | Path) -> list[RunProgress]:
    """Every (map, seed) run of ``protocol`` in ``out``, in the protocol's order."""
    out = Path(out)
    held = lock_holder(out) is not None  # a process runs the protocol now (a killed one holds nothing)
    lib = None
    if (out / LIBRARY).exists():
        try:
            lib = Library(out / LIBRARY, create=False)
        except LibraryError:
            lib = None
    try:
        return [_run_progress(run_dir(out, m, s), Path(m).stem, s, protocol.timesteps, lib, held)
                for m in protocol.maps for s in protocol.seeds]
    finally:
        if lib is not None:
            lib.close()


def format_progress(rows: list[RunProgress], title: str = "") -> str:
    """The progress view as a text table with a total line (and, while runs run, the time left at their rate)."""
    head = ("map", "seed", "status", "timesteps", "garages", "timesteps/s", "where")
    lines = [head] + [
        (r.map, str(r.seed), r.status, f"{r.timesteps:,} / {r.target:,}", f"{r.garages:,}",
         "-" if r.timesteps_per_s is None else f"{r.timesteps_per_s:,.0f}", r.where)
        for r in rows
    ]
    widths = [max(len(line[i]) for line in lines) for i in range(len(head))]
    right = {1, 3, 4, 5}
    text = [title] if title else []
    text += ["  ".join(c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(line, widths))).rstrip()
             for line in lines]
    counts = {s: sum(r.status == s for r in rows) for s in ("finished", "running", "resume", "new")}
    done, total = sum(r.timesteps for r in rows), sum(r.target for r in rows)
    summary = ", ".join(f"{n} {s}" for s, n in counts.items() if n)
    summary += f"; {done:,} / {total:,} timesteps ({100 * done / total:.1f}%) and {sum(r.garages for r in rows):,} garages"
    rate = sum(r.timesteps_per_s or 0.0 for r in rows if r.status == "running")
    if rate > 0:
        summary += f"; about {(total - done) / rate / 3600:.1f} h left at the running runs' {rate:,.0f} timesteps/s"
    elif counts["resume"] and not counts["running"]:
        summary += "; stopped (not running; run the same command to resume)"
    text.append("total: " + summary)
    return "\n".join(text)
