"""GarageGenEnv: the MDP of docs/spec.md section 3, checked step by step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from garage_mj import Block, evaluate
from garage_mj.core.config import ConfigError
from garage_mj.core.geometry import EAST, NORTH, SOUTH, WEST
from garage_mj.generation.gen_env import GarageGenEnv
from garage_mj.grid.garage import Garage
from garage_mj.grid.metrics import coverage
from garage_mj.grid.reward import RewardConfig
from garage_mj.grid.road_segments import RoadTracker, analyse
from garage_mj.grid.rules import road_squares, stall_rule_violations

ENV_ID = "garage_mj/GarageGen-v0"


def test_check_env_and_registration():
    check_env(GarageGenEnv(map="tiny_7x11"), skip_render_check=True)
    env = gym.make(ENV_ID, map="tiny_7x11", view_size=5, max_errors=3, six_stall_axis="EW")
    assert env.unwrapped.view_size == 5 and env.unwrapped.max_errors == 3
    assert env.observation_space.shape == (5 * 5 * 10 + 7,)
    assert ENV_ID in gym.registry
    import garage_mj

    garage_mj.register_envs()  # idempotent: registering again is harmless
    assert sum(1 for k in gym.registry if k == ENV_ID) == 1


def rollout(seed: int, actions) -> list:
    env = gym.make(ENV_ID, map="tiny_7x11")
    obs, info = env.reset(seed=seed)
    out = [(obs.copy(), None, info["six_stall_axis"])]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs.copy(), r, term, trunc, env.unwrapped.grid.copy()))
        if term or trunc:
            break
    return out


def test_same_seed_and_actions_same_trajectory():
    actions = np.random.default_rng(7).integers(4, size=150)
    a, b = rollout(11, actions), rollout(11, actions)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        for u, v in zip(x, y):
            np.testing.assert_array_equal(u, v)


def test_axis_is_drawn_from_the_seed_and_can_be_fixed():
    env = gym.make(ENV_ID, map="tiny_7x11")
    axes = {env.reset(seed=s)[1]["six_stall_axis"] for s in range(20)}
    assert axes == {"NS", "EW"}
    fixed = gym.make(ENV_ID, map="tiny_7x11", six_stall_axis="EW")
    assert {fixed.reset(seed=s)[1]["six_stall_axis"] for s in range(10)} == {"EW"}
    assert env.reset(seed=0, options={"six_stall_axis": "NS"})[1]["six_stall_axis"] == "NS"


def make_env(**kw) -> GarageGenEnv:
    env = GarageGenEnv(map="tiny_7x11", six_stall_axis="NS", **kw)
    env.reset(seed=0)
    return env


def test_collisions_count_as_errors_and_keep_the_car():
    env = make_env()
    assert env.pos == (6, 2) and env.heading == NORTH
    for a in (WEST, EAST, SOUTH):  # obstacles beside the entrance, off the grid below
        _, r, term, _, info = env.step(a)
        assert env.pos == (6, 2) and r < 0 and not term
    assert info["errors"] == 3
    env.step(NORTH)
    _, _, _, _, info = env.step(SOUTH)  # back onto the entrance: a collision
    assert env.pos == (5, 2) and info["errors"] == 4


def test_backward_move_is_penalised_but_not_an_error():
    cfg = RewardConfig(w_s=0, w_r=0, w_c=0, step_penalty=0)
    env = make_env(reward=cfg)
    env.step(NORTH)
    env.step(NORTH)
    _, r, _, _, info = env.step(SOUTH)  # back along its own road
    assert r == pytest.approx(cfg.backward_penalty) and info["errors"] == 0 and env.pos == (5, 2)


def test_two_by_two_square_is_refused():
    env2 = make_env()
    for a in (NORTH, NORTH, EAST):
        env2.step(a)
    _, r, _, _, info = env2.step(SOUTH)  # painting (5,3) completes (4,2),(4,3),(5,2),(5,3)
    assert info["errors"] == 1 and env2.pos == (4, 3) and env2.grid[5, 3] != Block.ROAD


def test_exit_terminates_usable_with_bonus():
    env = make_env()
    path = [NORTH] * 3 + [EAST] * 6 + [NORTH] * 3  # up column 2, along row 3, up column 8 to the exit
    for a in path[:-1]:
        _, _, term, _, _ = env.step(a)
        assert not term
    _, r, term, trunc, info = env.step(path[-1])
    assert term and not trunc and info["connected"] and info["usable"]
    assert r > env.reward_config.exit_bonus / 2
    m = evaluate(env.garage())
    assert m.usable and m.stalls == info["stalls"]
    assert m.difficulty == pytest.approx(info["difficulty"])


def test_too_many_errors_fail_and_step_limit_truncates():
    env = make_env(max_errors=2)
    for _ in range(3):
        _, r, term, _, info = env.step(WEST)
    assert term and not info["usable"] and r < env.reward_config.failure_penalty / 2
    env = make_env(max_steps=5)
    results = [env.step(a) for a in (NORTH, SOUTH, NORTH, SOUTH, NORTH)]
    assert results[-1][3] and not results[-1][2]


def test_observation_is_a_local_window():
    env = make_env()
    obs = env._obs()
    k = env.view_size
    window = obs[: k * k * 10].reshape(k, k, 10)
    assert window.sum(axis=2).min() == 1.0  # one-hot everywhere
    assert window[k // 2, k // 2].argmax() == Block.ENTRANCE  # the car's cell at the centre
    assert window[k - 1, k // 2].argmax() == Block.OBSTACLE  # outside the grid reads OBSTACLE
    tail = obs[k * k * 10 :]
    assert tail[0] == 0 and tail[1] == 0 and tail[2] == 0 and tail[3 + NORTH] == 1


def test_reward_config_rejects_unknown_keys():
    with pytest.raises(ConfigError, match="unknown key"):
        GarageGenEnv(map="tiny_7x11", reward={"exit_bonnus": 3})
    env = GarageGenEnv(map="tiny_7x11", reward={"exit_bonus": 3})
    assert env.reward_config.exit_bonus == 3.0


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**16),
    actions=st.lists(st.integers(0, 3), min_size=1, max_size=120),
    map_name=st.sampled_from(["tiny_7x11", "m7_13x13_u"]),
)
def test_invariants_hold_after_every_step(seed, actions, map_name):
    env = GarageGenEnv(map=map_name)
    env.reset(seed=seed)
    initial = env.initial
    fixed = np.isin(initial, [Block.OBSTACLE, Block.ENTRANCE, Block.EXIT])
    for a in actions:
        _, _, term, trunc, info = env.step(a)
        grid = np.array(env.grid)
        assert not road_squares(grid)
        assert not stall_rule_violations(grid, env.six_stall_axis)
        np.testing.assert_array_equal(grid[fixed], initial[fixed])
        assert info["coverage"] == pytest.approx(coverage(grid, initial))
        painted = env.garage()
        # the env's garage is the one the validating constructor builds from its grid
        checked = Garage(grid, initial, six_stall_axis=env.six_stall_axis, name=env.map_name)
        for f in ("grid", "initial"):
            got, want = getattr(painted, f), getattr(checked, f)
            assert got.dtype == want.dtype and np.array_equal(got, want)
        # and owns its arrays: the next step does not change it
        assert not np.shares_memory(painted.grid, env._padded) and not np.shares_memory(painted.initial, env.initial)
        assert (painted.six_stall_axis, painted.name, painted.entrance, painted.exit) == (
            checked.six_stall_axis, checked.name, checked.entrance, checked.exit)
        m = evaluate(painted)
        # the incremental statistics equal a full recomputation
        assert info["stalls"] == m.stalls
        assert info["mean_road_length"] == pytest.approx(m.mean_road_length)
        assert info["mean_intersection_degree"] == pytest.approx(m.mean_intersection_degree)
        assert len(env._tracker.segments) == len(analyse(grid).segments)
        if term or trunc:
            break
    # the next episode starts from the unpainted map's statistics, untouched by this one
    env.reset(seed=seed + 1)
    fresh = RoadTracker(initial)
    assert (env._tracker.masks, env._tracker.segments) == (fresh.masks, fresh.segments)
    assert (+env._tracker.x_hist, +env._tracker.y_hist) == (+fresh.x_hist, +fresh.y_hist)


def test_bad_arguments():
    with pytest.raises(ValueError, match="odd"):
        GarageGenEnv(view_size=4)
    with pytest.raises(ValueError, match="six_stall_axis"):
        GarageGenEnv(six_stall_axis="XY")
    env = make_env()
    with pytest.raises(ValueError, match="action must be 0-3"):
        env.step(4)


def test_rgb_array_render_shows_the_car_moving():
    env = gym.make(ENV_ID, map="tiny_7x11", render_mode="rgb_array")
    check_env(env.unwrapped)  # with the render check
    env.reset(seed=0)
    before = env.render()
    assert before.shape == (7 * 16, 11 * 16, 3) and before.dtype == np.uint8
    env.step(env.unwrapped._inward)  # one cell inward: the car moves and paints
    after = env.render()
    assert after.shape == before.shape and not np.array_equal(before, after)
    with pytest.raises(TypeError, match="render_mode"):
        GarageGenEnv(render_mode="human")


def test_render_colours_are_those_of_garage_show():
    from garage_mj.grid.image import BLOCK_RGB
    from garage_mj.reporting.plots import BLOCK_COLOURS

    for block, hex_colour in BLOCK_COLOURS.items():
        assert "#" + "".join(f"{v:02x}" for v in BLOCK_RGB[block]) == hex_colour.lower()


def test_sb3_make_vec_env_steps_two_envs():
    from stable_baselines3.common.env_util import make_vec_env

    venv = make_vec_env(ENV_ID, n_envs=2, seed=0, env_kwargs={"map": "tiny_7x11"})
    obs = venv.reset()
    assert obs.shape == (2, 7 * 7 * 10 + 7)
    for _ in range(100):  # long enough for episodes to end and reset inside the vec env
        obs, rewards, dones, infos = venv.step(np.array([venv.action_space.sample() for _ in range(2)]))
    assert obs.shape == (2, 7 * 7 * 10 + 7) and rewards.shape == (2,)
    assert venv.render_mode == "rgb_array" and venv.get_images()[0].shape == (7 * 16, 11 * 16, 3)
    venv.close()
