"""The fast learner: GarageGenVecEnv paints what the single env paints, OneHotWindow rebuilds its input,
WindowLayer is the first dense layer on that input, and the named learners train, resume and reproduce."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv

from garage_mj.core.config import ConfigError
from garage_mj.generation.gen_env import GarageGenEnv
from garage_mj.generation.library import Library
from garage_mj.generation.protocol import load_protocol
from garage_mj.generation.runs import latest_checkpoint, load_dqn
from garage_mj.generation.training import (
    DEFAULT_LEARNER,
    LEARNERS,
    DQNConfig,
    FinalGarage,
    load_dqn_config,
    train,
)
from garage_mj.generation.vec_env import GarageGenVecEnv
from garage_mj.generation.window_net import OneHotWindow, WindowLayer
from tests._vec_compare import step_alike


def _one_hot(obs: np.ndarray, window: str) -> np.ndarray:
    """Codes observations as the single env's one-hot ones, through the Q-network's own input layer."""
    if window == "one_hot":
        return obs
    space = GarageGenVecEnv("tiny_7x11", 1, window="codes").observation_space
    return OneHotWindow(space)(torch.as_tensor(obs)).numpy()


@pytest.mark.parametrize("map_name", ["tiny_7x11", "m5_13x13_aligned"])
@pytest.mark.parametrize("window", ["one_hot", "codes"])
def test_vector_env_paints_what_single_envs_paint(map_name, window):
    """Same seeds and actions: the same observations, rewards, episode ends, final garages and infos as
    SB3's DummyVecEnv over GarageGenEnv."""
    n = 4
    vec = GarageGenVecEnv(map_name, n, window=window)
    ref = DummyVecEnv([lambda: FinalGarage(GarageGenEnv(map_name)) for _ in range(n)])
    assert len(step_alike(vec, ref, lambda obs: _one_hot(obs, window), 1500)) > 20


def test_vector_env_refuses_bad_arguments():
    with pytest.raises(ValueError, match="window must be one of one_hot, codes"):
        GarageGenVecEnv("tiny_7x11", 2, window="pixels")
    with pytest.raises(ValueError, match="n_envs must be >= 1"):
        GarageGenVecEnv("tiny_7x11", 0)
    vec = GarageGenVecEnv("tiny_7x11", 2)
    vec.reset()
    with pytest.raises(ValueError, match="action must be 0-3"):
        vec.step(np.array([0, 7]))


def test_codes_observation_space_holds_every_observation():
    vec = GarageGenVecEnv("m5_13x13_aligned", 3, window="codes")
    obs = vec.reset()
    rng = np.random.default_rng(1)
    for _ in range(300):
        assert vec.observation_space.contains(obs[0])
        obs, *_ = vec.step(rng.integers(0, 4, 3))


def test_window_layer_is_the_dense_first_layer():
    """WindowLayer computes ReLU(Linear(one-hot window and state)) from the codes: the same initial weights
    from the same seed, the same outputs and the same gradients, up to float rounding."""
    space = GarageGenVecEnv("m5_13x13_aligned", 1, window="codes").observation_space
    torch.manual_seed(5)
    layer = WindowLayer(space, width=16)
    after_layer = torch.rand(4)
    torch.manual_seed(5)
    dense = torch.nn.Linear(OneHotWindow(space).features_dim, 16)
    assert torch.equal(torch.rand(4), after_layer)  # the layers built after it draw what they drew
    n = layer.window.shape[0]
    assert torch.equal(layer.window, dense.weight[:, :n].t())
    assert torch.equal(layer.state.weight, dense.weight[:, n:]) and torch.equal(layer.state.bias, dense.bias)

    vec = GarageGenVecEnv("m5_13x13_aligned", 8, window="codes")
    vec.seed(0)
    obs, rng = [vec.reset()], np.random.default_rng(0)
    for _ in range(40):
        obs.append(vec.step(rng.integers(0, 4, 8))[0])
    x = torch.as_tensor(np.concatenate(obs))
    ours = layer(x)
    ref = torch.relu(dense(OneHotWindow(space)(x)))
    assert torch.allclose(ours, ref, atol=1e-6)
    weights = torch.rand_like(ref)
    g_ours = torch.autograd.grad((ours * weights).sum(), [layer.window, layer.state.weight, layer.state.bias])
    g_ref = torch.autograd.grad((ref * weights).sum(), [dense.weight, dense.bias])
    assert torch.allclose(g_ours[0], g_ref[0][:, :n].t(), atol=1e-4)
    assert torch.allclose(g_ours[1], g_ref[0][:, n:], atol=1e-4)
    assert torch.allclose(g_ours[2], g_ref[1], atol=1e-4)


def test_fast_learner_network_is_the_one_hot_mlp():
    """The fast learner's Q-network equals a (64, 64) MLP on OneHotWindow built from the same seed."""
    from stable_baselines3 import DQN

    vec = GarageGenVecEnv("tiny_7x11", 4, window="codes")
    kwargs = load_dqn_config(learner="fast").dqn_kwargs()
    ours = DQN("MlpPolicy", vec, seed=3, device="cpu", **kwargs)
    kwargs["policy_kwargs"] = {"net_arch": [64, 64], "features_extractor_class": OneHotWindow}
    ref = DQN("MlpPolicy", vec, seed=3, device="cpu", **kwargs)
    obs = torch.as_tensor(vec.reset())
    with torch.no_grad():
        assert torch.allclose(ours.q_net(obs), ref.q_net(obs), atol=1e-6)
        assert torch.allclose(ours.q_net_target(obs), ref.q_net_target(obs), atol=1e-6)


def test_named_learners():
    assert load_dqn_config(learner="paper") == DQNConfig()
    fast = load_dqn_config(learner="fast")
    assert fast.vector_env and fast.n_envs == 32 and fast.net_arch == (64, 64)
    assert "features_extractor_class" in fast.dqn_kwargs()["policy_kwargs"]
    assert load_dqn_config({"n_envs": 16}, learner="fast").n_envs == 16  # a file's keys override the learner's
    assert DEFAULT_LEARNER in LEARNERS
    with pytest.raises(ConfigError, match="unknown learner 'slow'; choose one of paper, fast"):
        load_dqn_config(learner="slow")
    from garage_mj.cli.train import LEARNER_NAMES

    assert sorted(LEARNER_NAMES) == sorted(LEARNERS)
    with pytest.raises(ConfigError, match="device must be one of"):
        DQNConfig(device="tpu")


def test_protocol_learner(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("[experiment]\nmaps = ['tiny_7x11']\nseeds = [0]\ntimesteps = 100\nlearner = 'paper'\n"
                    "[dqn]\nlearning_rate = 0.002\n")
    assert load_protocol(path).dqn == DQNConfig(learning_rate=0.002)
    fast = load_protocol(path, learner="fast").dqn
    assert fast.vector_env and fast.learning_rate == 0.002
    path.write_text("[experiment]\nmaps = ['tiny_7x11']\nseeds = [0]\ntimesteps = 100\nlearner = 'quick'\n")
    with pytest.raises(ConfigError, match="learner must be one of paper, fast"):
        load_protocol(path)


FAST = load_dqn_config(learner="fast", learning_starts=256, checkpoint_every=1000)


def test_fast_learner_same_seed_same_run(tmp_path):
    a = train("tiny_7x11", 1500, 7, tmp_path / "a", FAST, progress=False)
    b = train("tiny_7x11", 1500, 7, tmp_path / "b", FAST, progress=False)
    assert a["episodes"] == b["episodes"] > 0
    ra = np.loadtxt(tmp_path / "a" / "monitor.csv", delimiter=",", skiprows=2, ndmin=2)
    rb = np.loadtxt(tmp_path / "b" / "monitor.csv", delimiter=",", skiprows=2, ndmin=2)
    assert np.array_equal(ra[:, :2], rb[:, :2])  # return and length of every episode


def test_lean_dqn_trains_what_dqn_trains(monkeypatch, tmp_path):
    """LeanDQN is DQN with less overhead: from the same seed, the same episodes, network and actions."""
    from stable_baselines3 import DQN

    import garage_mj.generation.runs as runs
    from garage_mj.generation.lean_dqn import LeanDQN

    config = load_dqn_config(learner="fast", n_envs=8, learning_starts=200, checkpoint_every=10_000)
    models = {}
    for name, algo in (("lean", LeanDQN), ("sb3", DQN)):
        monkeypatch.setattr(runs, "LeanDQN", algo)
        out = tmp_path / name
        train("tiny_7x11", 2000, 5, out, config, progress=False)
        models[name] = (np.loadtxt(out / "monitor.csv", delimiter=",", skiprows=2, ndmin=2),
                        load_dqn(out / "final_model.zip", config))
    (ra, lean), (rb, sb3) = models["lean"], models["sb3"]
    assert len(ra) > 0 and np.array_equal(ra[:, :2], rb[:, :2])  # return and length of every episode
    saved = json.loads(zipfile.ZipFile(tmp_path / "lean" / "final_model.zip").read("data"))
    assert not {"_hand", "_grad_params", "_modeless"} & set(saved)  # rebuilt on load, not saved
    for p, q in zip(lean.policy.parameters(), sb3.policy.parameters()):
        assert torch.equal(p, q)
    vec = GarageGenVecEnv("tiny_7x11", 8, window="codes")
    model = LeanDQN("MlpPolicy", vec, seed=1, device="cpu", **config.dqn_kwargs())
    assert model._hand is not None  # the run above took its gradients by hand, not through autograd
    obs = vec.reset()
    for eps in (0.0, 0.5):
        model.exploration_rate = eps
        np.random.seed(3), model.action_space.seed(3)
        ours = [model.predict(obs)[0] for _ in range(20)]
        np.random.seed(3), model.action_space.seed(3)
        theirs = [DQN.predict(model, obs)[0] for _ in range(20)]
        assert all(np.array_equal(a, b) for a, b in zip(ours, theirs))


def test_lean_dqn_takes_other_networks_through_autograd():
    """A Q-network HandGradient does not know (here a plain MLP on the one-hot window) trains as DQN does."""
    from stable_baselines3 import DQN

    from garage_mj.generation.lean_dqn import LeanDQN

    kw = {"learning_starts": 0, "batch_size": 32, "policy_kwargs": {"net_arch": [32]}}
    models = {}
    for algo in (LeanDQN, DQN):
        model = algo("MlpPolicy", GarageGenVecEnv("tiny_7x11", 4), seed=2, device="cpu", **kw)
        model.learn(400)
        models[algo] = model
    assert models[LeanDQN]._hand is None
    for p, q in zip(models[LeanDQN].policy.parameters(), models[DQN].policy.parameters()):
        assert torch.equal(p, q)


def test_fast_learner_crash_then_resume_keeps_every_garage_once(tmp_path):
    from stable_baselines3.common.callbacks import BaseCallback

    class Crash(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= 2600:
                raise RuntimeError("boom")
            return True

    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="boom"):
        train("tiny_7x11", 4000, 0, out, FAST, progress=False, callbacks=[Crash()])
    with Library(out / "library.sqlite") as lib:
        before = {r.hash: (r.episode, r.timestep) for r in lib.query()}
    assert before
    ckpt = latest_checkpoint(out)
    assert ckpt is not None and 2000 <= ckpt[1]["timesteps"] < 2600
    manifest = train("tiny_7x11", 4000, 0, out, progress=False, resume=True)
    assert manifest["status"] == "finished" and manifest["timesteps"] >= 4000
    assert manifest["config"]["vector_env"] is True
    with Library(out / "library.sqlite") as lib:
        after = lib.query()
    assert len({r.hash for r in after}) == len(after)
    assert {r.hash: (r.episode, r.timestep) for r in after if r.hash in before} == before
    assert manifest["garages_stored"] == len(after)
