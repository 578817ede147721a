"""DQN runs trained on other machines, kept on this one: the library and the run folders stay here.

A protocol on Ray (:func:`garage_mj.generation.protocol.run_protocol`, ``backend="ray"``) trains
each (map, seed) run as one Ray task, on any node, with :func:`train_remote`; the process that
started the protocol (the head) owns ``library.sqlite`` and every run folder, and nothing on a
worker node needs either path:

- the worker trains in a scratch folder of its own (under ``$GARAGE_MJ_WORK_DIR``, else the
  node's temp folder; removed at the end) and streams back, as it goes: each usable garage with
  its provenance (map, run, seed, episode, timestep), the files of each checkpoint (model,
  counters, ``monitor.csv``, ``run.json``), the manifest's ``live`` progress and, at the end, the
  final model (:func:`garage_mj.core.backends.stream_unordered`);
- the head alone writes: each garage into the library with
  :meth:`~garage_mj.generation.library.Library.credit` (the lowest seed that met a garage keeps
  it, so the rows do not depend on the order runs report in: a local pool fills the same
  library), each file into the run folder, atomically, in the order it was written;
- a run whose worker or node is lost is submitted again with the newest checkpoint the head
  holds (:class:`RunKeeper`); each attempt is listed in the run's ``run.json`` (``attempts``:
  where it ran, the timesteps it started from, why it was lost).

A run folder on the head is what a local run leaves, so a protocol started on one backend can be
resumed on the other.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import socket
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from garage_mj.core.backends import Compute, stream_unordered
from garage_mj.core.fsutil import atomic_write, write_json
from garage_mj.generation.library import Library
from garage_mj.generation.runs import checkpoint_files, latest_checkpoint, prune_checkpoints
from garage_mj.generation.training import (
    MANIFEST,
    MONITOR,
    TrainingError,
    load_dqn_config,
    new_run_id,
    read_manifest,
    train,
)
from garage_mj.grid.garage import Garage
from garage_mj.grid.map_io import load_map

#: Where a worker trains its run (a scratch folder per run, removed at the end); default: the node's temp folder.
WORK_DIR_ENV = "GARAGE_MJ_WORK_DIR"
MAX_LOST = 3  # [attempts] a run may lose its worker this many times per session, then the protocol stops


@dataclass(frozen=True)
class Met:
    """A usable garage a run met, with its provenance (the arguments of :meth:`Library.credit`)."""

    garage: Garage
    map: str
    run: str
    seed: int
    episode: int
    timestep: int


@dataclass(frozen=True)
class RemoteJob:
    """What a worker needs to train or resume a run: no path of the head's.

    ``files``: the run folder's files to resume from (``run.json``, ``monitor.csv``, the newest
    checkpoint), relative POSIX path -> bytes; empty for a new run.
    """

    map: str
    seed: int
    timesteps: int
    config: dict[str, Any]
    run_id: str
    files: dict[str, bytes]


# -- worker ---------------------------------------------------------------------------------------
class _Stopped(Exception):
    """The head closed the stream: training stops where it is."""


class _StopWhen(BaseCallback):
    def __init__(self, stop: threading.Event) -> None:
        super().__init__()
        self.stop = stop

    def _on_step(self) -> bool:
        if self.stop.is_set():
            raise _Stopped
        return True


class _QueueSink:
    """A :class:`~garage_mj.generation.training.GarageSink` that passes each garage on to the stream."""

    def __init__(self, events: queue.Queue) -> None:
        self.events = events

    def credit(self, garage: Garage, *, map: str, run: str, seed: int, episode: int, timestep: int) -> None:
        self.events.put(("garage", Met(garage, map, run, seed, episode, timestep)))


def _where() -> dict[str, Any]:
    """This worker: host, process, Ray node (when in Ray)."""
    node = None
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        node = ray.get_runtime_context().get_node_id()
    return {"host": socket.gethostname(), "pid": os.getpid(), "node": node}


def train_remote(job: RemoteJob) -> Iterator[tuple[str, Any]]:
    """Worker: train ``job`` in a scratch folder; yield what the head keeps, as it is made.

    Events, in the order things happen: ``("started", where)`` once; ``("garages", [Met, ...])``;
    ``("files", {relative path: bytes})`` for each group of files written (a checkpoint, a ``live``
    refresh, the end); ``("finished", manifest)`` last. An error of the run is raised as it is.
    """
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    base = os.environ.get(WORK_DIR_ENV) or None
    if base is not None:
        Path(base).mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f"garage_mj_{Path(job.map).stem}_s{job.seed}_", dir=base))
    folder = scratch / "run"
    for rel, data in job.files.items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_bytes(data)
    events: queue.Queue = queue.Queue()
    stop = threading.Event()
    done = object()

    def ship(paths: list[Path]) -> None:
        events.put(("files", {p.relative_to(folder).as_posix(): p.read_bytes() for p in paths if p.exists()}))

    def work() -> None:
        try:
            resume = MANIFEST in job.files
            manifest = train(job.map, job.timesteps, job.seed, folder,
                             config=None if resume else load_dqn_config(job.config), resume=resume, progress=False,
                             callbacks=[_StopWhen(stop)], sink=_QueueSink(events), run_id=job.run_id, on_files=ship)
            events.put(("finished", manifest))
        except BaseException as exc:  # noqa: BLE001  (handed to the stream, raised there)
            events.put(("error", exc))
        finally:
            events.put(done)

    thread = threading.Thread(target=work, name="garage-mj-train", daemon=True)
    try:
        yield "started", _where()
        thread.start()
        while True:
            event, batch = events.get(), []
            while event is not done and event[0] == "garage":  # the garages met since the last event, together
                batch.append(event[1])
                try:
                    event = events.get_nowait()
                except queue.Empty:
                    event = None
                    break
            if batch:
                yield "garages", batch
            if event is None:
                continue
            if event is done:
                return
            if event[0] == "error":
                raise event[1]
            yield event
    finally:
        stop.set()
        if thread.is_alive():
            thread.join()
        shutil.rmtree(scratch, ignore_errors=True)


# -- head -----------------------------------------------------------------------------------------
def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


class RunKeeper:
    """The head's side of one run: its folder, the job that trains or resumes it, what arrives.

    Args:
        folder: the run folder on the head.
        map, seed, timesteps, config: the run (as :func:`~garage_mj.generation.training.train` takes them).
        library: the head's library path (recorded in ``run.json``; only the head opens it).
    """

    def __init__(self, folder: Path, map: str, seed: int, timesteps: int, config: dict[str, Any],
                 library: Path) -> None:
        self.folder, self.map, self.seed, self.timesteps, self.config = folder, map, seed, timesteps, config
        self.library = library
        self.stored = 0  # garages the current attempt stored or credited
        self.attempts: list[dict[str, Any]] = []
        self.run_id = ""
        self.finished = False

    def job(self) -> RemoteJob:
        """The job for the next attempt: a new run, or the newest checkpoint this folder holds."""
        files: dict[str, bytes] = {}
        if (self.folder / MANIFEST).exists():
            manifest = read_manifest(self.folder)
            self.run_id, self.attempts = manifest["run"], list(manifest.get("attempts", []))
            paths = [self.folder / MANIFEST, self.folder / MONITOR, *checkpoint_files(self.folder)]
            files = {p.relative_to(self.folder).as_posix(): p.read_bytes() for p in paths if p.exists()}
        elif not self.run_id:
            self.run_id = new_run_id(load_map(self.map).name, self.seed, self.folder)
        return RemoteJob(self.map, self.seed, self.timesteps, self.config, self.run_id, files)

    def resumes_from(self) -> int:
        """The timesteps of the newest checkpoint held here (0: none; a new attempt starts afresh)."""
        found = latest_checkpoint(self.folder) if (self.folder / MANIFEST).exists() else None
        return int(found[1]["timesteps"]) if found else 0

    def take(self, event: str, payload: Any, lib: Library) -> dict[str, Any] | None:
        """Keep one event of :func:`train_remote`: garages into ``lib``, files into the folder; the final
        manifest when the run ended, else None."""
        if event == "garages":
            for m in payload:
                self.stored += lib.credit(m.garage, map=m.map, run=m.run, seed=m.seed, episode=m.episode,
                                          timestep=m.timestep) is not None
        elif event == "files":
            self.write(payload)
        elif event == "started":
            self.started(payload)
        elif event == "finished":
            return self.finish(payload, lib)
        return None

    def started(self, where: dict[str, Any]) -> None:
        self.attempts.append({**where, "from_timesteps": self.resumes_from(), "started_at": _now()})
        self.stored = 0

    def write(self, files: dict[str, bytes]) -> None:
        """Write the files a worker sent, each atomically, in order; ``run.json`` gets the head's fields."""
        self.folder.mkdir(parents=True, exist_ok=True)
        for rel, data in files.items():
            path = PurePosixPath(rel)
            if path.is_absolute() or ".." in path.parts:
                raise TrainingError(f"a worker sent a file outside its run folder: {rel!r}")
            target = self.folder.joinpath(*path.parts)
            target.parent.mkdir(parents=True, exist_ok=True)
            if rel == MANIFEST:
                data = self._manifest(data)
            atomic_write(target, data)
        prune_checkpoints(self.folder)

    def _manifest(self, data: bytes) -> bytes:
        manifest = json.loads(data)
        manifest["library"] = str(self.library)
        manifest["attempts"] = self.attempts
        if isinstance(manifest.get("live"), dict):
            manifest["live"]["updated_at"] = _now()  # the head's clock, which the progress view compares with
        return (json.dumps(manifest, indent=2) + "\n").encode()

    def finish(self, manifest: dict[str, Any], lib: Library) -> dict[str, Any]:
        """The run ended on its worker: ``run.json`` gets the garages the head stored for it."""
        manifest = json.loads(self._manifest((json.dumps(manifest)).encode()))
        manifest["garages_stored"] = lib.count(run=self.run_id)
        if isinstance(manifest.get("last_session"), dict):
            manifest["last_session"]["garages_stored"] = self.stored
        write_json(self.folder / MANIFEST, manifest)
        self.finished = True
        return manifest

    def lost(self, why: str) -> None:
        """The worker is gone: ``run.json`` notes why; the next :meth:`job` resumes from the newest checkpoint here."""
        if self.attempts:
            self.attempts[-1]["lost"] = why
        if (self.folder / MANIFEST).exists():
            self.write({MANIFEST: (self.folder / MANIFEST).read_bytes()})

    def interrupted(self) -> None:
        """The head stops before the run ended: ``run.json`` says so (a re-run resumes it)."""
        if self.finished or not (self.folder / MANIFEST).exists():
            return
        manifest = read_manifest(self.folder)
        if manifest.get("status") == "running":
            manifest["status"] = "interrupted"
            if manifest.get("attempts"):
                manifest["attempts"][-1]["stopped"] = "the head stopped (Ctrl-C or an error)"
            write_json(self.folder / MANIFEST, manifest)


def run_remote(keepers: list[RunKeeper], *, compute: Compute,
               say: Callable[[str], None] | None = None) -> Iterator[dict[str, Any]]:
    """Train the runs of ``keepers`` on Ray, ``compute.workers`` at a time (``compute.backend="local"``: here,
    one after another, the same stream); yields each run's final manifest as it ends. Only this process
    writes the library (``keepers[i].library``) and the run folders. ``say(text)`` gets a line when a run loses its worker.
    """
    def resume(index: int, why: str) -> int:
        k = keepers[index]
        k.lost(why)
        if say is not None:
            say(f"{Path(k.map).stem} seed {k.seed}: worker lost ({why}); resuming from timestep {k.resumes_from()}")
        return index

    if not keepers:
        return
    ok = False
    with Library(keepers[0].library) as lib:
        try:  # a job is a keeper's index; what it sends is read from the run folder right before it is sent
            stream = stream_unordered(train_remote, range(len(keepers)), compute=compute,
                                      prepare=lambda i: keepers[i].job(), resume=resume, max_retries=MAX_LOST,
                                      name=lambda i: f"{Path(keepers[i].map).stem} seed {keepers[i].seed}")
            for index, (event, payload) in stream:
                manifest = keepers[index].take(event, payload, lib)
                if manifest is not None:
                    yield manifest
            ok = True
        finally:
            if not ok:
                for k in keepers:
                    k.interrupted()
