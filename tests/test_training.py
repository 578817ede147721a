"""DQN training: garages reach the library with true metrics, runs resume without loss or duplicates."""

from __future__ import annotations

import json

import numpy as np
import pytest
from stable_baselines3.common.callbacks import BaseCallback

from garage_mj.core.config import ConfigError
from garage_mj.generation.library import Library
from garage_mj.generation.runs import latest_checkpoint
from garage_mj.generation.training import DQNConfig, TrainingError, load_dqn_config, train
from garage_mj.grid.metrics import evaluate

FAST = DQNConfig(checkpoint_every=1000)


class Crash(BaseCallback):
    """Raises ``exc`` once the run reaches ``at`` timesteps (a crash or a Ctrl-C in the middle)."""

    def __init__(self, at: int, exc: BaseException) -> None:
        super().__init__()
        self.at, self.exc = at, exc

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.at:
            raise self.exc
        return True


def _monitor_returns(run) -> np.ndarray:
    return np.loadtxt(run / "monitor.csv", delimiter=",", skiprows=2, ndmin=2)[:, 0]


@pytest.fixture(scope="module")
def run3000(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "tiny_s0"
    manifest = train("tiny_7x11", 3000, 0, out, FAST, progress=False)
    return out, manifest


def test_training_stores_usable_garages_with_true_metrics(run3000):
    out, manifest = run3000
    with Library(out / "library.sqlite") as lib:
        records = lib.query()
    assert len(records) >= 1
    assert manifest["garages_stored"] == len(records)
    for r in records:
        m = evaluate(r.garage)
        assert m.usable
        assert (r.coverage, r.difficulty, r.stalls) == (m.coverage, m.difficulty, m.stalls)
        assert (r.mean_road_length, r.mean_intersection_degree) == (m.mean_road_length, m.mean_intersection_degree)
        assert (r.map, r.seed, r.run) == ("tiny_7x11", 0, manifest["run"])
        assert 0 <= r.episode < manifest["episodes"] and 0 < r.timestep <= 3000


def test_run_folder_manifest_monitor_checkpoints(run3000):
    out, manifest = run3000
    on_disk = json.loads((out / "run.json").read_text())
    assert on_disk["status"] == "finished" and on_disk["timesteps"] == 3000
    assert len(_monitor_returns(out)) == manifest["episodes"] > 0
    s = manifest["last_session"]
    assert s["timesteps"] == 3000 and s["timesteps_per_s"] > 0 and 0 < s["env_share"] < 1
    assert (out / "final_model.zip").exists()
    ckpt = latest_checkpoint(out)
    assert ckpt is not None and ckpt[1]["timesteps"] == 3000
    assert len(list((out / "checkpoints").glob("step_*.zip"))) == 2  # older ones are pruned


def test_same_seed_same_run(tmp_path):
    a = train("tiny_7x11", 1500, 7, tmp_path / "a", FAST, progress=False)
    b = train("tiny_7x11", 1500, 7, tmp_path / "b", FAST, progress=False)
    assert a["episodes"] == b["episodes"]
    assert np.array_equal(_monitor_returns(tmp_path / "a"), _monitor_returns(tmp_path / "b"))


def test_crash_then_resume_keeps_every_garage_once(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="boom"):
        train("tiny_7x11", 4000, 0, out, FAST, progress=False, callbacks=[Crash(2600, RuntimeError("boom"))])
    with Library(out / "library.sqlite") as lib:
        before = {r.hash: (r.episode, r.timestep) for r in lib.query()}
    assert before, "the crashed run should already have reported garages"
    ckpt = latest_checkpoint(out)
    assert ckpt is not None and ckpt[1]["timesteps"] == 2000
    manifest = train("tiny_7x11", 4000, 0, out, progress=False, resume=True)
    assert manifest["status"] == "finished" and manifest["timesteps"] == 4000
    with Library(out / "library.sqlite") as lib:
        after = lib.query()
    hashes = [r.hash for r in after]
    assert len(hashes) == len(set(hashes))  # nothing twice
    assert {h: v for h, v in ((r.hash, (r.episode, r.timestep)) for r in after) if h in before} == before
    new = [r for r in after if r.hash not in before]
    assert all(r.timestep > 2000 and r.episode >= ckpt[1]["episodes"] for r in new)
    # the monitor log continues from the checkpoint's episodes, without the lost ones
    assert len(_monitor_returns(out)) == manifest["episodes"]


def test_ctrl_c_saves_a_checkpoint_and_resume_continues(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        # multiples of n_envs (8): the vectorised run counts 8 timesteps per step
        train("tiny_7x11", 2400, 1, out, FAST, progress=False, callbacks=[Crash(1600, KeyboardInterrupt())])
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    ckpt = latest_checkpoint(out)
    assert ckpt is not None and ckpt[1]["timesteps"] == 1600
    manifest = train("tiny_7x11", 2400, 1, out, progress=False, resume=True)
    assert manifest["timesteps"] == 2400 and manifest["last_session"]["timesteps"] == 800
    again = train("tiny_7x11", 2400, 1, out, progress=False, resume=True)
    assert again["timesteps"] == 2400  # a finished run resumes to nothing


def test_refuses_to_mix_runs(tmp_path, run3000):
    out, _ = run3000
    with pytest.raises(TrainingError, match="already holds a run"):
        train("tiny_7x11", 100, 0, out, progress=False)
    with pytest.raises(TrainingError, match="seed"):
        train("tiny_7x11", 100, 5, out, progress=False, resume=True)
    with pytest.raises(TrainingError, match="no training run"):
        train("tiny_7x11", 100, 0, tmp_path / "empty", progress=False, resume=True)


def test_config_from_toml(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text("[dqn]\nlearning_rate = 0.001\nnet_arch = [64, 64]\n")
    cfg = load_dqn_config(good)
    assert cfg.learning_rate == 0.001 and cfg.net_arch == (64, 64)
    assert cfg.dqn_kwargs()["policy_kwargs"]["net_arch"] == [64, 64]
    bad = tmp_path / "bad.toml"
    bad.write_text("learning_rat = 0.001\n")
    with pytest.raises(ConfigError, match="unknown key.*learning_rat"):
        load_dqn_config(bad)
    with pytest.raises(ConfigError, match="exploration_fraction"):
        DQNConfig(exploration_fraction=2.0)


def test_fast_vectorised_config_trains_and_checkpoints(tmp_path):
    """generation/dqn_fast.toml (8 envs in one process): every episode logged, checkpoints on crossing."""
    from pathlib import Path

    toml = Path(__file__).resolve().parent.parent / "generation" / "dqn_fast.toml"
    cfg = load_dqn_config(toml, learning_starts=200, checkpoint_every=300)
    manifest = train("tiny_7x11", 900, 0, tmp_path / "fast", cfg, progress=False)
    assert 900 <= manifest["timesteps"] < 908 and manifest["config"]["n_envs"] == 8
    assert len(_monitor_returns(tmp_path / "fast")) == manifest["episodes"] > 0
    ckpt = latest_checkpoint(tmp_path / "fast")
    assert ckpt is not None and ckpt[1]["timesteps"] >= 900


def test_latest_checkpoint_passes_over_one_pruned_while_it_reads(tmp_path):
    """``--status`` reads a running run's checkpoints while the run prunes old ones: a record listed and then
    gone is passed over, not an error."""
    ck = tmp_path / "checkpoints"
    ck.mkdir()
    for step in (1000, 2000):
        (ck / f"step_{step:09d}.zip").write_bytes(b"")
        (ck / f"step_{step:09d}.json").write_text(json.dumps({"timesteps": step, "episodes": 1}))
    gone = ck / "step_000000500.json"  # listed by the glob, deleted before its read: a dangling link
    gone.symlink_to(ck / "pruned.json")
    (ck / "step_000000500.zip").write_bytes(b"")
    model, state = latest_checkpoint(tmp_path)
    assert model.name == "step_000002000.zip" and state["timesteps"] == 2000


def test_every_dqn_setting_declares_its_bounds():
    """Each number, list and string of DQNConfig has a declared range, checked for every TOML key."""
    import dataclasses

    from garage_mj.core.config import BOUNDS

    unbounded = [f.name for f in dataclasses.fields(DQNConfig) if f.type != "bool" and BOUNDS not in f.metadata]
    assert not unbounded


@pytest.mark.parametrize(("line", "says"), [
    ("n_envs = 100000000", "n_envs = 100000000 is not allowed: n_envs must be an integer in [1, 1_024]"),
    ("batch_size = 10000000", "batch_size = 10000000 is not allowed: batch_size must be an integer in [1, 65_536]"),
    ("net_arch = [64, 100000]",
     "net_arch = [64, 100000] is not allowed: net_arch must be a non-empty list of integers, each in [1, 4_096]"),
    ("target_update_interval = 0",
     "target_update_interval = 0 is not allowed: target_update_interval must be an integer in [1, 1_000_000_000]"),
])
def test_train_refuses_a_setting_out_of_bounds_before_writing(line, says, tmp_path, capsys):
    from tests._cli import one_line_error

    config = tmp_path / "dqn.toml"
    config.write_text(line + "\n")
    out = tmp_path / "run"
    err = one_line_error(capsys, ["train", "--map", "tiny_7x11", "--timesteps", "100", "--out", str(out),
                                  "--config", str(config), "--no-progress"])
    assert f"{config}: {says}" in err and not out.exists()
