"""Runs trained elsewhere and kept here (garage_mj.generation.remote), without Ray: the same stream in-process.

The worker side (:func:`train_remote`) and the head side (:class:`RunKeeper`) are the code a Ray
cluster runs (tests/test_ray_cluster.py); here they meet in one process, so the library, the run
folder, the resume from the head's checkpoint and the progress view are checked in seconds.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from garage_mj.core.backends import Compute
from garage_mj.core.errors import FolderBusy
from garage_mj.core.fsutil import FolderLock
from garage_mj.generation.library import Library
from garage_mj.generation.progress import format_progress, protocol_progress
from garage_mj.generation.protocol import LIBRARY, load_protocol, run_dir, run_protocol
from garage_mj.generation.remote import WORK_DIR_ENV, RunKeeper, run_remote, train_remote
from garage_mj.grid.painters import paint_garage

GENERATION = Path(__file__).resolve().parents[1] / "generation"
#: seed 0 meets ~10 usable garages in 1,500 timesteps of this config on tiny_7x11; the paper learner's one env
#: counts timesteps one at a time, so the checkpoints fall on exact multiples of 500
PROTOCOL = ("[experiment]\nname = 't'\nmaps = ['tiny_7x11']\nseeds = [0]\ntimesteps = 1500\nlearner = 'paper'\n"
            "[dqn]\ncheckpoint_every = 500\nlearning_starts = 300\nexploration_fraction = 0.1\n"
            "target_update_interval = 250\n")


def library_rows(path: Path) -> list[tuple]:
    """The library's rows without id and created_at, the run id without its start time and folder digest."""
    with Library(path, create=False) as lib:
        return sorted(tuple(v for k, v in r.to_dict().items() if k not in ("id", "created_at", "run"))
                      + (r.run.rsplit("_", 2)[0],) for r in lib.query())


def monitor_rows(folder: Path) -> list[str]:
    """monitor.csv's episodes: return and length (not the wall time)."""
    return [line.rsplit(",", 1)[0] for line in (folder / "monitor.csv").read_text().splitlines()[2:]]


def test_credit_keeps_the_lowest_seed_whatever_the_order(tmp_path):
    g = paint_garage("tiny_7x11", seed=1)
    ends = []
    for order in ((3, 1, 2), (1, 2, 3), (2, 3, 1)):
        with Library(tmp_path / f"{order}.sqlite") as lib:
            got = [lib.credit(g, map="tiny_7x11", run=f"r{s}", seed=s, episode=10 * s, timestep=100 * s) for s in order]
            (row,) = lib.query()
            ends.append((row.run, row.seed, row.episode, row.timestep))
            assert got[0] == row.id  # stored; later: the id when credited to a lower seed, else None
            assert [x is not None for x in got[1:]] == [s < min(order[: i + 1]) for i, s in enumerate(order[1:])]
            assert lib.credit(g, map="other", run="x", seed=0, episode=0, timestep=0) is None  # another map: kept
    assert ends == [("r1", 1, 10, 100)] * 3


@pytest.fixture
def protocol(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text(PROTOCOL)
    return load_protocol(path)


def _keeper(protocol, out: Path) -> RunKeeper:
    return RunKeeper(run_dir(out, "tiny_7x11", 0), "tiny_7x11", 0, protocol.timesteps, protocol.dqn.to_dict(),
                     out / LIBRARY)


def test_a_streamed_run_keeps_what_a_local_run_writes(protocol, tmp_path, monkeypatch):
    monkeypatch.setenv(WORK_DIR_ENV, str(tmp_path / "work"))
    run_protocol(protocol, tmp_path / "local", compute=Compute(progress=False))
    keeper = _keeper(protocol, tmp_path / "head")
    job = keeper.job()
    assert job.files == {} and str(tmp_path / "head") not in repr(job)  # a worker gets no path of the head's
    (finished,) = run_remote([keeper], compute=Compute())  # local: here, the same stream
    assert library_rows(tmp_path / "head" / LIBRARY) == library_rows(tmp_path / "local" / LIBRARY) != []
    local, head = run_dir(tmp_path / "local", "tiny_7x11", 0), run_dir(tmp_path / "head", "tiny_7x11", 0)
    assert monitor_rows(head) == monitor_rows(local) != []
    assert sorted(p.name for p in (head / "checkpoints").iterdir()) == sorted(
        p.name for p in (local / "checkpoints").iterdir())  # the newest two, as locally
    assert (head / "final_model.zip").exists()
    a, b = (json.loads((f / "run.json").read_text()) for f in (local, head))
    assert {k: a[k] for k in ("status", "timesteps", "episodes", "garages_stored", "config", "seed", "map")} == {
        k: b[k] for k in ("status", "timesteps", "episodes", "garages_stored", "config", "seed", "map")}
    assert b["library"] == str(tmp_path / "head" / LIBRARY) and finished["garages_stored"] == b["garages_stored"]
    assert b["attempts"][0]["from_timesteps"] == 0 and b["live"]["timesteps"] == 1500
    assert list((tmp_path / "work").iterdir()) == []  # the worker's scratch folder is gone


def test_a_stopped_stream_resumes_from_the_heads_checkpoint(protocol, tmp_path, monkeypatch):
    monkeypatch.setenv(WORK_DIR_ENV, str(tmp_path / "work"))
    out = tmp_path / "head"
    keeper = _keeper(protocol, out)
    with Library(out / LIBRARY) as lib:  # the worker is lost right after its first checkpoint reached the head
        events = train_remote(keeper.job())
        for event, payload in events:
            keeper.take(event, payload, lib)
            if event == "files" and any(name.startswith("checkpoints/") for name in payload):
                break
        events.close()
        before = {r.hash for r in lib.query()}
    keeper.interrupted()
    assert list((tmp_path / "work").iterdir()) == []
    (row,) = protocol_progress(protocol, out)
    assert (row.status, row.timesteps, row.target, row.garages) == ("resume", 500, 1500, len(before))
    (finished,) = run_remote([_keeper(protocol, out)], compute=Compute())
    assert finished["status"] == "finished" and finished["timesteps"] == 1500
    assert [a["from_timesteps"] for a in finished["attempts"]] == [0, 500]
    folder = run_dir(out, "tiny_7x11", 0)
    assert len(monitor_rows(folder)) == finished["episodes"]  # cut back to the checkpoint, then continued
    with Library(out / LIBRARY, create=False) as lib:
        after = {r.hash for r in lib.query()}
        assert before <= after and lib.count() == len(after) == finished["garages_stored"]
    (row,) = protocol_progress(protocol, out)
    assert (row.status, row.timesteps, row.garages) == ("finished", 1500, len(after))


def test_status_view_and_one_protocol_per_folder(tmp_path, capsys):
    import importlib.util

    spec = importlib.util.spec_from_file_location("run_script", GENERATION / "run.py")
    run_script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run_script)
    assert run_script.main([str(GENERATION / "smoke.toml"), "--status", "--out", str(tmp_path / "s")]) == 0
    text = capsys.readouterr().out
    assert "tiny_7x11     0  new     0 / 3,000" in text and "total: 2 new; 0 / 6,000 timesteps (0.0%)" in text
    assert not (tmp_path / "s").exists()  # a look changes nothing
    smoke = load_protocol(GENERATION / "smoke.toml")
    rows = protocol_progress(smoke, tmp_path / "s")
    assert format_progress(rows).splitlines()[0].split() == ["map", "seed", "status", "timesteps", "garages",
                                                             "timesteps/s", "where"]
    with FolderLock(tmp_path / "busy", "another protocol"), pytest.raises(FolderBusy, match="another protocol"):
        run_protocol(smoke, tmp_path / "busy", compute=Compute(progress=False))
