"""``generation/run.py --status`` tells a running protocol from one whose process is gone (``kill -9``).

A run's ``live`` progress in ``run.json`` stays fresh for minutes after its process died; only the
protocol folder's lock (an ``flock`` the kernel drops with the process) says whether anyone still runs it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import pytest

from garage_mj.core.fsutil import LOCK_NAME, FolderLock, lock_holder
from garage_mj.generation.progress import format_progress, protocol_progress
from garage_mj.generation.protocol import load_protocol, run_dir

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ("[experiment]\nname = 't'\nmaps = ['tiny_7x11']\nseeds = [0, 1]\ntimesteps = 1000000\n"
            "learner = 'paper'\n[dqn]\ncheckpoint_every = 300\nlearning_starts = 200\n")


def _run_script():
    spec = importlib.util.spec_from_file_location("run_script", ROOT / "generation" / "run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def protocol_file(tmp_path) -> Path:
    path = tmp_path / "p.toml"
    path.write_text(PROTOCOL)
    return path


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _leave_what_a_killed_run_leaves(out: Path) -> None:
    """Both runs' run.json "running" with a live progress seconds old, and the lock file naming a dead pid."""
    now = datetime.now(timezone.utc).isoformat(timespec="seconds")
    for seed in (0, 1):
        folder = run_dir(out, "tiny_7x11", seed)
        folder.mkdir(parents=True)
        (folder / "run.json").write_text(json.dumps({
            "run": f"r{seed}", "map": "tiny_7x11", "seed": seed, "status": "running", "timesteps": 600,
            "live": {"timesteps": 900, "episodes": 3, "timesteps_per_s": 800.0, "updated_at": now}}))
    (out / LOCK_NAME).write_text(json.dumps({"pid": _dead_pid(), "what": "generation protocol t"}))


def test_a_run_whose_process_is_gone_is_stopped_not_running(protocol_file, tmp_path):
    out = tmp_path / "out"
    _leave_what_a_killed_run_leaves(out)
    protocol = load_protocol(protocol_file)
    rows = protocol_progress(protocol, out)
    assert [r.status for r in rows] == ["resume", "resume"]
    text = format_progress(rows)
    assert "running" not in text.replace("not running", "") and "h left" not in text
    assert "stopped (not running; run the same command to resume)" in text
    assert lock_holder(out) is None and (out / LOCK_NAME).is_file()  # the look took nothing and left the file
    with FolderLock(out, "generation protocol t", remove=True):  # the same files, a live holder: running
        assert lock_holder(out)["pid"] == os.getpid()
        rows = protocol_progress(protocol, out)
        assert [r.status for r in rows] == ["running", "running"]
        assert "total: 2 running" in format_progress(rows) and "h left" in format_progress(rows)


def test_status_after_a_real_kill_9(protocol_file, tmp_path, capsys):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(ROOT / "generation" / "run.py"), str(protocol_file), "--out",
                             str(out), "--no-progress"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    manifest = run_dir(out, "tiny_7x11", 0) / "run.json"
    try:
        deadline = time.monotonic() + 120
        while not (manifest.is_file() and '"running"' in manifest.read_text()):
            if time.monotonic() > deadline or proc.poll() is not None:
                pytest.fail("the protocol wrote no running run.json in 120 s")
            time.sleep(0.2)
        script = _run_script()
        assert script.main([str(protocol_file), "--status", "--out", str(out)]) == 0
        assert "1 running" in capsys.readouterr().out
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert script.main([str(protocol_file), "--status", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "running" not in text.replace("not running", "") and "h left" not in text, text
    assert "1 resume" in text and "stopped (not running; run the same command to resume)" in text, text


def test_a_look_at_a_killed_jobs_lock_never_refuses_the_next_job(tmp_path):
    """A --status look holds the lock file for an instant; a job starting then, over a lock file that names a
    killed job, waits that instant instead of being refused as if the killed job still ran."""
    import fcntl
    import threading

    (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": _dead_pid(), "what": "generation protocol t"}))
    fd = os.open(tmp_path / LOCK_NAME, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_SH)  # what lock_holder holds while it looks, here for 0.3 s
    threading.Timer(0.3, os.close, (fd,)).start()
    with FolderLock(tmp_path, "generation protocol t"):
        assert lock_holder(tmp_path)["pid"] == os.getpid()
    assert lock_holder(tmp_path) is None
