"""The Ray backend (garage_mj.core.backends): same rows as the local backend, resume, retries, experiments.

One private Ray (127.0.0.1, 2 CPUs) serves the whole module: its start-up costs seconds.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest

from garage_mj.core.backends import BackendError, Compute, check_backend, map_unordered, ray_session
from garage_mj.driving.cruise import run_cruise
from garage_mj.driving.sources import CruiseSettings
from garage_mj.generation.library import Library
from garage_mj.generation.protocol import load_protocol
from garage_mj.grid.painters import paint_garage
from garage_mj.reporting.experiment import run_experiment

pytest.importorskip("ray", reason="pip install 'garage-mj[ray]' (make install does)")

FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def ray2():
    with ray_session(Compute(workers=2, backend="ray")) as ray:
        yield ray


@pytest.fixture(scope="module")
def garages():
    return [paint_garage("tiny_7x11", seed=s) for s in (1, 2)]


def rows_of(path: Path) -> list[tuple]:
    """tests.csv rows without the wall time, sorted."""
    with open(path, newline="") as f:
        return sorted(tuple((k, v) for k, v in r.items() if k != "wall_s") for r in csv.DictReader(f))


def _cruise(garages, out, backend="local", **kw):
    return run_cruise(garages, 2, CruiseSettings("waypoint", seed=3, action_type="continuous", env=FAST), out,
                      compute=Compute(workers=2, backend=backend, progress=False), **kw)


def test_cruise_rows_equal_local_and_a_rerun_resumes(ray2, garages, tmp_path):
    local = _cruise(garages, tmp_path / "local")
    first = _cruise(garages, tmp_path / "ray", backend="ray", max_tests=1)  # "interrupted" after one test
    second = _cruise(garages, tmp_path / "ray", backend="ray")
    assert local.tests_run == 4 and (first.tests_run, second.tests_run) == (1, 3)
    assert rows_of(tmp_path / "ray" / "tests.csv") == rows_of(tmp_path / "local" / "tests.csv")
    assert ray2.is_initialized()  # the batches used the module's Ray and left it running
    again = _cruise(garages, tmp_path / "ray", backend="ray")
    assert again.tests_run == 0 and len(again.rows) == 4


def _die_once(job):
    """A ``*die`` job kills its worker process the first time (a lost node, in small); returns env and pid."""
    mark = Path(job)
    if mark.name.endswith("die") and not mark.exists():
        mark.write_text("died")
        os._exit(1)
    return mark.name, os.environ.get("MUJOCO_GL"), os.environ.get("GARAGE_MJ_TEST_MARK"), os.getpid()


def _always_die(_job):
    os._exit(1)


def _raise(job):
    raise ValueError(f"bad job {job}")


def test_workers_get_the_env_and_a_lost_worker_is_retried_then_named(ray2, tmp_path, monkeypatch):
    monkeypatch.setenv("GARAGE_MJ_TEST_MARK", "seen")
    jobs = [str(tmp_path / n) for n in ("0die", "1", "2", "3", "4", "5")]
    got = sorted(map_unordered(_die_once, jobs, compute=Compute(2, "ray"), max_retries=1))
    assert [g[0] for g in got] == ["0die", "1", "2", "3", "4", "5"]  # the lost job retried, once
    assert {g[1:3] for g in got} == {(os.environ["MUJOCO_GL"], "seen")}  # as in a spawned pool worker
    assert len({g[3] for g in got}) <= 3  # one process per worker slot (+1 restarted), not one per job
    with pytest.raises(BackendError, match="lost its worker 1 times.*run again to resume"):
        list(map_unordered(_always_die, [0], compute=Compute(1, "ray"), max_retries=0))
    with pytest.raises(ValueError, match="bad job 7"):  # the job's own error: as it is, no retry
        list(map_unordered(_raise, [7], compute=Compute(1, "ray")))


def test_a_job_past_its_time_limit_or_lost_for_good_goes_to_on_lost(ray2):
    """As on the local pool: the actor's interval timer stops a job that hangs; a job whose worker dies on every
    try is the caller's on_lost to record; the other jobs run."""
    from tests import _crashing

    got = map_unordered(_crashing.square_or_hang, range(3), compute=Compute(2, "ray"), timeout=1.5,
                        on_lost=lambda job, why: (job, why.kind, why.reason))
    assert sorted(map(repr, got)) == sorted(map(repr, [0, 1, (2, "timeout", "ran past the time limit of 1.5 s of "
                                                                             "wall time")]))
    lost = list(map_unordered(_always_die, [5], compute=Compute(1, "ray"), max_retries=0,
                              on_lost=lambda job, why: (job, why.kind, why.reason)))
    assert lost == [(5, "crash", "its process or node died on its one try")]


def test_bad_backend_fails_before_any_job():
    with pytest.raises(BackendError, match="unknown backend"):
        Compute(backend="dask")
    with pytest.raises(BackendError, match="--backend ray"):
        Compute(backend="local", address="10.0.0.1:6379")
    check_backend(Compute(backend="ray"))  # Ray is installed
    with pytest.raises(BackendError, match="cannot reach the Ray cluster at 127.0.0.1:1"):  # not minutes of retries
        list(map_unordered(_raise, [0], compute=Compute(1, "ray", "127.0.0.1:1")))


def test_generation_experiment_on_ray_gives_the_same_runs(ray2, tmp_path):
    # 12,000 timesteps: the default learner steps 32 garages together, and its figures need a finished episode per
    # run (an episode ends at the latest after 4 x 7 x 11 steps of one garage)
    path = tmp_path / "p.toml"
    path.write_text("[experiment]\nname = 't'\nmaps = ['tiny_7x11']\nseeds = [0, 1]\ntimesteps = 12000\n"
                    "[dqn]\ncheckpoint_every = 100\nlearning_starts = 100\n")
    protocol = load_protocol(path)
    local = run_experiment(protocol, tmp_path / "local", compute=Compute(progress=False))
    remote = run_experiment(protocol, tmp_path / "ray",
                            compute=Compute(workers=2, backend="ray", progress=False))
    assert sorted(remote["trained"]) == sorted(local["trained"]) == [("tiny_7x11", 0), ("tiny_7x11", 1)]
    assert remote["garages"] == local["garages"]

    def found(out):  # (run without its start time, garage hash): the same garages from the same runs
        with Library(out / "library.sqlite") as lib:
            return sorted((r.run.rsplit("_", 2)[0], r.hash) for r in lib.query())

    assert found(tmp_path / "ray") == found(tmp_path / "local")
    again = run_experiment(protocol, tmp_path / "ray",
                           compute=Compute(workers=2, backend="ray", progress=False))
    assert again["trained"] == [] and len(again["skipped"]) == 2


def test_hunt_on_ray_gives_the_local_hunt(ray2, tmp_path):
    from garage_mj.driving.hunt import HuntConfig
    from garage_mj.reporting.hunt import hunt

    cfg = HuntConfig(budget=10, tests=2, population=4, elites=1, worst=1)
    settings = CruiseSettings("waypoint", seed=1, action_type="discrete", env=FAST)
    kw = dict(map="tiny_7x11", config=cfg, videos=False)
    local = hunt(settings, tmp_path / "local", compute=Compute(progress=False),
                 **kw)  # in-process: no pool to start
    remote = hunt(settings, tmp_path / "ray", compute=Compute(workers=2, backend="ray", progress=False), **kw)
    assert [(s.source.hash, len(s.rows), s.rate) for s in remote.ranked] == [
        (s.source.hash, len(s.rows), s.rate) for s in local.ranked]
    assert rows_of(tmp_path / "ray" / "cruise" / "tests.csv") == rows_of(tmp_path / "local" / "cruise" / "tests.csv")
