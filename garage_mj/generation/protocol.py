"""The generation protocol: every (map, seed) run of a protocol, into one library.

A protocol TOML (``generation/paper.toml``) names the maps, the seeds, the timesteps per run,
optionally the learner (``fast`` or ``paper``) and a ``[dqn]`` table of hyper-parameters. :func:`run_protocol` trains the runs in
a process pool or on a Ray cluster (:mod:`garage_mj.core.backends`), each in
``out/runs/<map>/seed_<s>/``; a finished run is skipped and an interrupted one resumed, so the
command can simply be started again after a crash.

All runs fill one ``out/library.sqlite``; the UNIQUE hash keeps a garage two runs both found
once, credited to the lower seed (:meth:`~garage_mj.generation.library.Library.credit`), so the
library does not depend on which run met it first. Locally the pool's processes insert
themselves (SQLite in WAL mode: tiny transactions, writers wait on a busy timeout). On Ray the
runs train on any node of the cluster and stream their garages and checkpoints back to this
process, which alone writes the library and the run folders (:mod:`garage_mj.generation.remote`);
a run whose node is lost resumes from the newest checkpoint held here. Either way the same
seeds give the same rows. One protocol at a time may use ``out`` (a :class:`FolderLock`). The
figures are drawn a stage later, by :func:`garage_mj.reporting.experiment.run_experiment`.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from garage_mj.core.backends import DEFAULT_COMPUTE, Compute, check_backend, map_unordered
from garage_mj.core.config import ConfigError, read_toml
from garage_mj.core.fsutil import FolderLock
from garage_mj.generation.library import Library
from garage_mj.generation.remote import RunKeeper, run_remote
from garage_mj.generation.training import (
    DEFAULT_LEARNER,
    LEARNERS,
    MANIFEST,
    DQNConfig,
    load_dqn_config,
    read_manifest,
    train,
)
from garage_mj.grid.map_io import load_map

LIBRARY = "library.sqlite"
MIN_TIMESTEPS = 100  # a scaled run never gets fewer


@dataclass(frozen=True)
class Protocol:
    """Which runs an experiment makes (``[experiment]`` table) and their DQN config (``[dqn]``)."""

    maps: tuple[str, ...]
    seeds: tuple[int, ...]
    timesteps: int
    dqn: DQNConfig = field(default_factory=DQNConfig)
    name: str = "experiment"

    def scaled(self, scale: float) -> Protocol:
        """The same protocol with ``timesteps * scale`` per run (at least :data:`MIN_TIMESTEPS`)."""
        if not 0 < scale <= 1:
            raise ConfigError(f"--scale must be in (0, 1], got {scale}")
        steps = max(MIN_TIMESTEPS, round(self.timesteps * scale))
        every = min(self.dqn.checkpoint_every, max(MIN_TIMESTEPS, steps // 10))
        return Protocol(self.maps, self.seeds, steps, load_dqn_config(self.dqn.to_dict(), checkpoint_every=every),
                        self.name)


def load_protocol(path: str | Path, learner: str | None = None) -> Protocol:
    """Read a protocol TOML; unknown tables or keys are an error.

    The runs' DQN config is the learner's (:data:`~garage_mj.generation.training.LEARNERS`: ``learner``,
    else the file's ``[experiment] learner``, else the default) with the ``[dqn]`` keys on top.
    """
    path = Path(path)
    data = read_toml(path, "protocol file")
    unknown = sorted(set(data) - {"experiment", "dqn"})
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {', '.join(unknown)}; known: experiment, dqn")
    exp = dict(data.get("experiment", {}))
    known = {"name", "maps", "seeds", "timesteps", "learner"}
    if set(exp) - known:
        raise ConfigError(f"{path}: unknown key(s) {', '.join(sorted(set(exp) - known))} in [experiment]; "
                          f"known keys: {', '.join(sorted(known))}")
    missing = sorted({"maps", "seeds", "timesteps"} - set(exp))
    if missing:
        raise ConfigError(f"{path}: [experiment] needs {', '.join(missing)}")
    maps, seeds, steps = exp["maps"], exp["seeds"], exp["timesteps"]
    if not isinstance(maps, list) or not maps or not all(isinstance(m, str) for m in maps):
        raise ConfigError(f"{path}: [experiment] maps must be a non-empty list of map names")
    if not isinstance(seeds, list) or not seeds or not all(type(s) is int for s in seeds):
        raise ConfigError(f"{path}: [experiment] seeds must be a non-empty list of integers")
    if type(steps) is not int or steps < 1:
        raise ConfigError(f"{path}: [experiment] timesteps must be a positive integer")
    learner = exp.get("learner", DEFAULT_LEARNER) if learner is None else learner
    if learner not in LEARNERS:
        raise ConfigError(f"{path}: [experiment] learner must be one of {', '.join(LEARNERS)}, got {learner!r}")
    try:
        dqn = load_dqn_config(data.get("dqn", {}), learner=learner)
    except ConfigError as exc:
        raise ConfigError(f"{path} [dqn]: {exc}") from None
    return Protocol(tuple(maps), tuple(seeds), steps, dqn, str(exp.get("name", path.stem)))


def run_dir(out: Path, map: str, seed: int) -> Path:
    return out / "runs" / Path(map).stem / f"seed_{seed}"


def protocol_folder(out: str | Path, compute: Compute = DEFAULT_COMPUTE) -> Path:
    """The folder the runs write into: ``out``, made absolute for Ray (its workers start elsewhere)."""
    out = Path(out)
    return out.absolute() if compute.backend == "ray" else out


def run_status(folder: Path, timesteps: int) -> str:
    """``new``, ``finished`` (nothing to do) or ``resume``."""
    if not (folder / MANIFEST).exists():
        return "new"
    m = read_manifest(folder)
    return "finished" if m.get("status") == "finished" and m.get("timesteps", 0) >= timesteps else "resume"


def _one_run(map: str, seed: int, timesteps: int, folder: str, library: str, config: dict[str, Any],
             progress: bool) -> dict[str, Any]:
    """Worker: train or resume one run (top-level so the process pool can pickle it)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    resume = (Path(folder) / MANIFEST).exists()
    return train(map, timesteps, seed, folder, config=None if resume else load_dqn_config(config),
                 resume=resume, library_path=library, progress=progress)


def _job(args: tuple) -> dict[str, Any]:
    return _one_run(*args)


def run_protocol(protocol: Protocol, out: str | Path, *, compute: Compute = DEFAULT_COMPUTE) -> dict[str, Any]:
    """Train every (map, seed) of ``protocol`` not yet finished, into ``out`` (:func:`protocol_folder`).

    ``compute.backend``: ``"local"`` (this process, or a spawn pool of ``workers``) or ``"ray"``
    (``workers`` runs at a time as Ray tasks on any node; ``address``: a running cluster, else a
    private local Ray; this process alone writes ``out``, :mod:`garage_mj.generation.remote`); a
    run's result does not depend on where it trains. ``compute.progress``: a bar of the runs (and,
    with one local worker, each run's own). Returns a summary: runs trained and skipped,
    the library, garages per map, each trained run's throughput.
    """
    from tqdm import tqdm

    check_backend(compute)
    out = protocol_folder(out, compute)
    for m in protocol.maps:
        load_map(m)  # fail on a bad map before any run starts
    out.mkdir(parents=True, exist_ok=True)
    library = out / LIBRARY
    with FolderLock(out, f"generation protocol {protocol.name}", remove=True):
        Library(library).close()  # create it once, before the workers race to
        jobs, skipped = [], []
        for m in protocol.maps:
            for s in protocol.seeds:
                folder = run_dir(out, m, s)
                (skipped if run_status(folder, protocol.timesteps) == "finished" else jobs).append((m, s, folder))
        done: list[dict[str, Any]] = []
        if jobs:
            bar = tqdm(total=len(jobs), desc=f"{protocol.name}: runs", unit="run", disable=not compute.progress)
            if compute.backend == "ray":
                keepers = [RunKeeper(f, m, s, protocol.timesteps, protocol.dqn.to_dict(), library) for m, s, f in jobs]
                say = (lambda text: tqdm.write(text, file=sys.stderr)) if compute.progress else None
                results = run_remote(keepers, compute=compute, say=say)
            else:
                bars = compute.progress and compute.workers == 1  # a run's own bar, in this process only
                args = [(m, s, protocol.timesteps, str(f), str(library), protocol.dqn.to_dict(), bars)
                        for m, s, f in jobs]
                results = map_unordered(_job, args, compute=compute)
            for result in results:
                done.append(result)
                bar.update()
            bar.close()
    with Library(library) as lib:
        per_map = {m: lib.count(map=Path(m).stem) for m in protocol.maps}
    return {"trained": [(d["map"], d["seed"]) for d in done], "skipped": [(m, s) for m, s, _ in skipped],
            "library": str(library), "garages": per_map,
            "throughput": {f"{d['map']}/seed_{d['seed']}": d.get("last_session") for d in done}}
