"""The conditioned painter on the vector env: GarageGenVecEnv(env_cls=GarageGenCondEnv) paints, rewards and
reports what single GarageGenCondEnv do, its codes window feeds a WindowLayer with the 5 band values after the
7 state values, and the fast learner trains a conditioned generator that ``generate`` uses."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv
from stable_baselines3.dqn.policies import DQNPolicy

from garage_mj.core.config import ConfigError
from garage_mj.generation.cond_env import N_COND, ConditionConfig, GarageGenCondEnv
from garage_mj.generation.conditioned import (
    load_generator_config,
    load_policy,
    save_policy,
    train_conditioned,
)
from garage_mj.generation.generator import GenerationError, generate, reads_codes
from garage_mj.generation.library import Library
from garage_mj.generation.training import FinalGarage, load_dqn_config
from garage_mj.generation.vec_env import GarageGenVecEnv
from garage_mj.generation.window_net import STATE_VALUES, OneHotWindow, WindowLayer
from tests._vec_compare import INFO_KEYS, step_alike

COND_STATE = STATE_VALUES + N_COND
# every usable garage lands in the band: the band bonus path is stepped too
WIDE = ConditionConfig(band_width=1.0, coverage_share=0.0)


def _vec(n: int, window: str, condition: ConditionConfig | None = None, map: str = "tiny_7x11") -> GarageGenVecEnv:
    return GarageGenVecEnv(map, n, window=window, env_cls=GarageGenCondEnv, condition=condition)


@functools.cache
def _one_hot_layer() -> OneHotWindow:
    return OneHotWindow(_vec(1, "codes").observation_space, state_values=COND_STATE)


def _one_hot(obs: np.ndarray, window: str) -> np.ndarray:
    """Codes observations as the single conditioned env's one-hot ones, through the Q-network's input layer."""
    if window == "one_hot":
        return obs
    return _one_hot_layer()(torch.as_tensor(obs)).numpy()


@pytest.mark.parametrize("condition", [None, WIDE], ids=["drawn_bands", "wide_band"])
@pytest.mark.parametrize("window", ["one_hot", "codes"])
def test_vector_cond_env_paints_what_single_cond_envs_paint(window, condition):
    """Same seeds and actions: the same observations, rewards, episode ends, bands, final garages and infos as
    SB3's DummyVecEnv over GarageGenCondEnv."""
    n = 4
    vec = _vec(n, window, condition)
    ref = DummyVecEnv([lambda: FinalGarage(GarageGenCondEnv("tiny_7x11", condition=condition)) for _ in range(n)])
    ended = step_alike(vec, ref, lambda obs: _one_hot(obs, window), 1000,
                       keys=(*INFO_KEYS, "target_difficulty", "target_coverage", "in_band"))
    assert len(ended) > 20
    if condition is WIDE:
        assert any(info["in_band"] for info in ended)


def test_cond_codes_observation_space():
    """The codes window, the 7 state values, the 5 band values; every observation lies in the space."""
    vec = _vec(3, "codes", map="m5_13x13_aligned")
    env = vec.envs[0]
    assert vec.observation_space.shape == (env.view_size ** 2 + COND_STATE,)
    assert np.array_equal(vec.observation_space.high[-N_COND:], np.ones(N_COND, dtype=np.float32))
    obs = vec.reset()
    rng = np.random.default_rng(1)
    for _ in range(200):
        assert vec.observation_space.contains(obs[0])
        obs, *_ = vec.step(rng.integers(0, 4, 3))
    lo, hi = env.target_difficulty
    np.testing.assert_allclose(obs[0][-N_COND:], [lo, hi, env._difficulty, *env.target_coverage], atol=1e-6)


def test_window_layer_with_band_values_is_the_dense_first_layer():
    space = _vec(1, "codes").observation_space
    torch.manual_seed(2)
    layer = WindowLayer(space, width=16, state_values=COND_STATE)
    torch.manual_seed(2)
    dense = torch.nn.Linear(OneHotWindow(space, state_values=COND_STATE).features_dim, 16)
    vec = _vec(4, "codes")
    vec.seed(0)
    obs, rng = [vec.reset()], np.random.default_rng(0)
    for _ in range(30):
        obs.append(vec.step(rng.integers(0, 4, 4))[0])
    x = torch.as_tensor(np.concatenate(obs))
    ref = torch.relu(dense(OneHotWindow(space, state_values=COND_STATE)(x)))
    assert torch.allclose(layer(x), ref, atol=1e-6)
    assert layer.state.in_features == COND_STATE
    with pytest.raises(ValueError, match="cannot hold a window"):
        WindowLayer(space, state_values=space.shape[0])


def test_generator_config_chooses_the_learner(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text('[dqn]\nlearner = "fast"\nn_envs = 8\n[condition]\nband_width = 0.2\n')
    dqn, cond, _ = load_generator_config(path)
    assert dqn == load_dqn_config(learner="fast", n_envs=8) and cond.band_width == 0.2
    assert load_generator_config(path, learner="paper")[0] == load_dqn_config({"n_envs": 8})
    path.write_text("[dqn]\nn_envs = 8\n")
    assert load_generator_config(path)[0] == load_dqn_config(learner="fast", n_envs=8)  # the default learner
    assert not load_generator_config(path, learner="paper")[0].vector_env
    path.write_text('[dqn]\nlearner = "quick"\n')
    with pytest.raises(ConfigError, match="g.toml: unknown learner 'quick'; choose one of paper, fast"):
        load_generator_config(path)


def _one_hot_twin(policy: DQNPolicy, env: GarageGenCondEnv) -> DQNPolicy:
    """The same Q-function on the single env's one-hot observations: WindowLayer's rows and state columns
    joined back into the dense first layer of a plain MLP policy."""
    width = policy.q_net.features_extractor.features_dim
    twin = DQNPolicy(env.observation_space, env.action_space, lambda _: 1e-3, net_arch=[width, 64])
    first = policy.q_net.features_extractor
    layers = [m for m in twin.q_net.q_net if isinstance(m, torch.nn.Linear)]
    rest = [m for m in policy.q_net.q_net if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        layers[0].weight.copy_(torch.cat([first.window.t(), first.state.weight], dim=1))
        layers[0].bias.copy_(first.state.bias)
        for mine, theirs in zip(layers[1:], rest, strict=True):
            mine.weight.copy_(theirs.weight)
            mine.bias.copy_(theirs.bias)
    return twin


def test_fast_learner_trains_a_generator_that_generate_uses(tmp_path):
    dqn = load_dqn_config(learner="fast", n_envs=8, learning_starts=256, checkpoint_every=1000)
    out = tmp_path / "gen"
    meta = train_conditioned("tiny_7x11", 2000, 0, out, dqn=dqn, progress=False, search_evaluations=100)
    assert meta["timesteps"] >= 2000 and meta["episodes"] > 0 and meta["dqn"]["vector_env"]
    again = train_conditioned("tiny_7x11", 2600, 0, out, progress=False, resume=True)  # from the checkpoint
    assert again["timesteps"] >= 2600 and again["dqn"] == meta["dqn"]
    policy = load_policy(out / "generator.zip")
    assert reads_codes(policy) and policy.q_net.features_extractor.state.in_features == COND_STATE
    # the codes policy and its one-hot twin paint the same garages from the same seed: generate gives the
    # codes policy the codes of the window it gives the one-hot policy
    twin = tmp_path / "twin" / "generator.zip"
    twin.parent.mkdir()
    save_policy(_one_hot_twin(policy, GarageGenCondEnv("tiny_7x11")), twin)
    assert not reads_codes(load_policy(twin))
    found = []
    for name, model in (("codes", out / "generator.zip"), ("one_hot", twin)):
        try:
            result = generate("tiny_7x11", (0.0, 1.0), 3, tmp_path / f"{name}.sqlite", model=model, seed=1,
                              max_episodes=40, progress=False, search=False)
        except GenerationError as exc:  # a 2,000-step generator may not reach the exit often yet
            assert "of 3" in str(exc)
            result = exc.result
        assert result.episodes > 0
        with Library(tmp_path / f"{name}.sqlite") as lib:
            found.append((result.episodes, sorted(r.hash for r in lib.query())))
    assert found[0] == found[1]
