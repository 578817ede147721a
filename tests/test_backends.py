"""How long jobs run (garage_mj.core.backends.Compute): a bad value is one clear error, before any job; the local
pool notices a worker that dies or a job that hangs, and never waits for ever."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from garage_mj.cli import main
from garage_mj.core.backends import BackendError, Compute, LostJob, map_unordered
from tests import _crashing

TWO = Compute(workers=2, progress=False)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"workers": 0}, "workers must be >= 1, got 0"),
    ({"workers": True}, "workers must be >= 1, got True"),
    ({"workers": "2"}, "workers must be >= 1, got '2'"),
    ({"backend": "dask"}, "unknown backend 'dask'; choose one of local, ray"),
    ({"address": "10.0.0.1:6379"}, "--address names a Ray cluster; use it with --backend ray"),
    ({"progress": "yes"}, "progress must be True or False, got 'yes'"),
])
def test_a_bad_compute_value_is_one_clear_error(kwargs, message):
    with pytest.raises(BackendError) as err:
        Compute(**kwargs)
    assert str(err.value) == message  # one line, naming the value and the fix
    with pytest.raises(BackendError):  # a changed copy is checked too
        dataclasses.replace(Compute(), **kwargs)


def test_compute_defaults_and_a_local_batch():
    assert Compute() == Compute(workers=1, backend="local", address=None, progress=True)
    assert sorted(map_unordered(abs, [-2, 1, -3], compute=Compute(progress=False))) == [1, 2, 3]
    assert list(map_unordered(abs, [])) == []


def test_the_command_line_says_a_bad_address_in_one_line(capsys):
    assert main(["hunt", "--map", "tiny_7x11", "--address", "10.0.0.1:6379", "--out", "/nonexistent/x"]) == 2
    err = capsys.readouterr().err
    assert err == "garage-mj hunt: error: --address names a Ray cluster; use it with --backend ray\n"


def test_a_worker_killed_mid_job_is_replaced_and_its_job_given_again(tmp_path):
    """kill -9 of a pool worker (the OOM killer, a user): noticed at once, the job runs again, the batch ends."""
    mark = tmp_path / "died"
    jobs = [(n, str(mark) if n == 2 else "") for n in range(5)]
    start = time.monotonic()
    assert sorted(map_unordered(_crashing.square_or_die, jobs, compute=TWO)) == [0, 1, 4, 9, 16]
    assert mark.read_text() == "died once" and time.monotonic() - start < 10


def test_a_job_that_kills_every_worker_is_lost_not_waited_for():
    """A job that segfaults on every try: with on_lost its result is what on_lost makes of it (the others run);
    without, the batch stops in one line naming the signal."""
    got = sorted(map(repr, map_unordered(_crashing.square_or_segfault, range(4), compute=TWO,
                                         on_lost=lambda job, why: (job, why.kind, why.reason))))
    assert got == sorted(map(repr, [0, 1, 4, (3, "crash", "its process was killed by signal SIGSEGV on each of 2 tries")]))
    with pytest.raises(BackendError) as err:
        list(map_unordered(_crashing.square_or_segfault, [3, 1], compute=TWO))
    assert str(err.value) == ("local: a job was lost (its process was killed by signal SIGSEGV on each of 2 tries); "
                              "finished jobs are saved, run again to resume")


@pytest.mark.parametrize("workers", [1, 2])
def test_a_job_past_its_time_limit_is_stopped_and_the_batch_goes_on(workers):
    start = time.monotonic()
    got = list(map_unordered(_crashing.square_or_hang, range(4), compute=Compute(workers=workers, progress=False),
                             timeout=1.5, on_lost=lambda job, why: why))
    lost = [g for g in got if isinstance(g, LostJob)]
    assert sorted(g for g in got if not isinstance(g, LostJob)) == [0, 1, 9]
    assert [(w.kind, w.reason) for w in lost] == [("timeout", "ran past the time limit of 1.5 s of wall time")]
    assert 1.4 < lost[0].seconds < 5 and time.monotonic() - start < 12


def _alive(pid: int) -> bool:
    """The process runs (a zombie left for a reaper that never comes counts as ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc (Linux)")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_pool_workers_end_when_their_parent_is_killed(tmp_path, sig):
    """``kill`` of a batch's process (a scheduler's SIGTERM, kill -9) runs no clean-up in it; its pool workers
    must not go on with their jobs as orphans."""
    code = ("import sys\nfrom garage_mj.core.backends import Compute, map_unordered\nfrom tests import _crashing\n"
            "list(map_unordered(_crashing.pid_then_hang, [sys.argv[1]] * 2, compute=Compute(workers=2, progress=False)))")
    parent = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], cwd=Path(__file__).parent.parent)
    try:
        deadline = time.monotonic() + 60
        while len(list(tmp_path.iterdir())) < 2 and time.monotonic() < deadline and parent.poll() is None:
            time.sleep(0.1)
        workers = [int(p.name) for p in tmp_path.iterdir()]
        assert len(workers) == 2 and all(map(_alive, workers))
        parent.send_signal(sig)
        parent.wait(10)
        deadline = time.monotonic() + 10
        while any(map(_alive, workers)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(map(_alive, workers))
    finally:
        parent.kill()
        for p in tmp_path.iterdir():
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(p.name), signal.SIGKILL)
