"""Generation across a multi-node Ray cluster: the head alone writes, a lost node's run resumes.

The test starts a two-node Ray cluster on this machine (``ray.cluster_utils.Cluster``: a head and
one more node, one CPU each, each its own raylet, object store and workers), as ``ray start
--head`` and ``ray start --address`` do on separate machines, with Ray's token auth as README
"Scaling out" sets it up (``RAY_AUTH_MODE=token``, ``ray get-auth-token --generate``). The
protocol runs with its output folder (library and run folders) on the head side and the workers'
scratch folders in another folder (``GARAGE_MJ_WORK_DIR``), which never holds a library.

Token auth also keeps this module working after a private local Ray in the same pytest process
(tests/test_ray_backend.py): a process that once ran Ray with token auth keeps serving its objects
with it, so a cluster without auth could not fetch them (OwnerDiedError).
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from garage_mj.core.backends import Compute
from garage_mj.generation.library import Library
from garage_mj.generation.progress import protocol_progress
from garage_mj.generation.protocol import LIBRARY, load_protocol, run_dir, run_protocol
from garage_mj.generation.remote import WORK_DIR_ENV
from tests.test_remote import library_rows, monitor_rows

ray = pytest.importorskip("ray", reason="pip install 'garage-mj[ray]' (make install does)")
pytestmark = pytest.mark.slow

#: seeds 0 and 4 on tiny_7x11 under this config meet ~40 garages in 3,000 timesteps, one of them in both runs
#: (checked once: so the lowest-seed rule decides its row)
DQN = "[dqn]\ncheckpoint_every = {every}\nlearning_starts = 300\nexploration_fraction = 0.1\ntarget_update_interval = 250\n"
#: node death noticed within ~5 s (Ray's default is 30 s); workers at the parent's priority, as in backends.py
SYSTEM = {"health_check_period_ms": 1000, "health_check_failure_threshold": 5, "worker_niceness": 0,
          "enable_worker_prestart": False}


@pytest.fixture(scope="module")
def cluster():
    from ray.cluster_utils import Cluster

    # the token in ~/.ray/auth_token, made if missing (a private local Ray makes the same one)
    subprocess.run([str(Path(sys.executable).with_name("ray")), "get-auth-token", "--generate"], check=True,
                   capture_output=True)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("RAY_AUTH_MODE", "token")
        c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                          "_system_config": SYSTEM})
        c.add_node(num_cpus=1)
        ray.init(address=c.address, logging_level="WARNING")
        try:
            yield c
        finally:
            ray.shutdown()
            c.shutdown()


def _protocol(tmp_path: Path, seeds: list[int], timesteps: int, every: int):
    path = tmp_path / "p.toml"
    # the paper learner's one env: timesteps and checkpoints fall on exact multiples
    path.write_text(f"[experiment]\nname = 't'\nmaps = ['tiny_7x11']\nseeds = {seeds}\ntimesteps = {timesteps}\n"
                    "learner = 'paper'\n" + DQN.format(every=every))
    return load_protocol(path)


def manifest(out: Path, seed: int) -> dict:
    return json.loads((run_dir(out, "tiny_7x11", seed) / "run.json").read_text())


def test_cluster_fills_the_library_the_local_pool_does(cluster, tmp_path, monkeypatch):
    monkeypatch.setenv(WORK_DIR_ENV, str(tmp_path / "workers"))
    protocol = _protocol(tmp_path, [0, 4], 3000, 1000)
    local = run_protocol(protocol, tmp_path / "local", compute=Compute(workers=2, progress=False))
    head = tmp_path / "head"
    remote = run_protocol(protocol, head, compute=Compute(2, "ray", cluster.address, progress=False))
    assert sorted(remote["trained"]) == sorted(local["trained"]) == [("tiny_7x11", 0), ("tiny_7x11", 4)]
    assert library_rows(head / LIBRARY) == library_rows(tmp_path / "local" / LIBRARY) != []
    nodes = {n["NodeID"] for n in ray.nodes() if n["Alive"]}
    assert {manifest(head, s)["attempts"][0]["node"] for s in (0, 4)} == nodes and len(nodes) == 2  # one run per node
    for s in (0, 4):
        assert monitor_rows(run_dir(head, "tiny_7x11", s)) == monitor_rows(run_dir(tmp_path / "local", "tiny_7x11", s))
        assert manifest(head, s)["garages_stored"] == manifest(tmp_path / "local", s)["garages_stored"]
    assert [(r.status, r.timesteps) for r in protocol_progress(protocol, head)] == [("finished", 3000)] * 2
    assert not list((tmp_path / "workers").rglob("*"))  # scratch folders gone; no library ever there


def test_a_lost_node_resumes_from_the_heads_checkpoint(cluster, tmp_path, monkeypatch):
    """Kill the non-head node once its run's first checkpoint is on the head: the run restarts there."""
    monkeypatch.setenv(WORK_DIR_ENV, str(tmp_path / "workers"))
    protocol = _protocol(tmp_path, [0, 1], 4000, 500)
    head = tmp_path / "head"
    (worker,) = [n for n in cluster.worker_nodes]
    killed: dict = {}
    ended = threading.Event()

    def kill_when_checkpointed() -> None:
        while not ended.is_set():
            for s in protocol.seeds:
                folder = run_dir(head, "tiny_7x11", s)
                try:
                    m = json.loads((folder / "run.json").read_text())
                except (FileNotFoundError, json.JSONDecodeError):
                    continue
                if m["attempts"][-1]["node"] == worker.node_id and list(folder.glob("checkpoints/*.json")):
                    with Library(head / LIBRARY, create=False) as lib:
                        killed.update(seed=s, rows={r.hash for r in lib.query(run=m["run"])})
                    cluster.remove_node(worker, allow_graceful=False)  # raylet, object store, workers: gone
                    return
            ended.wait(0.05)

    killer = threading.Thread(target=kill_when_checkpointed)
    killer.start()
    try:
        summary = run_protocol(protocol, head, compute=Compute(2, "ray", cluster.address, progress=False))
    finally:
        ended.set()
        killer.join()
    assert killed, "the run on the second node ended before its first checkpoint reached the head"
    assert sorted(summary["trained"]) == [("tiny_7x11", 0), ("tiny_7x11", 1)]
    m = manifest(head, killed["seed"])
    first, second = m["attempts"]
    assert first["node"] == worker.node_id and "NodeDiedError" in first["lost"]
    assert second["node"] != worker.node_id and 500 <= second["from_timesteps"] < 4000
    assert second["from_timesteps"] % 500 == 0  # a checkpoint the head held
    assert (m["status"], m["timesteps"]) == ("finished", 4000)
    folder = run_dir(head, "tiny_7x11", killed["seed"])
    assert len(monitor_rows(folder)) == m["episodes"] and (folder / "final_model.zip").exists()
    with Library(head / LIBRARY, create=False) as lib:
        rows = lib.query(run=m["run"])
        assert killed["rows"] <= {r.hash for r in rows}  # what the lost attempt streamed stays
        assert len(rows) == m["garages_stored"] and lib.count() == len({r.hash for r in lib.query()})
    other = manifest(head, 1 - killed["seed"])
    assert len(other["attempts"]) == 1 and other["status"] == "finished"
    assert not list((tmp_path / "workers").glob("*/library.sqlite"))
