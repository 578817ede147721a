"""Controllable generation: the conditioned painter env, its training and ``garage-mj generate``."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from garage_mj.cli import main
from garage_mj.generation.cond_env import N_COND, ConditionConfig, GarageGenCondEnv
from garage_mj.generation.conditioned import shipped_generator, train_conditioned
from garage_mj.generation.gen_env import GarageGenEnv
from garage_mj.generation.generator import GenerationError, generate
from garage_mj.generation.library import Library
from garage_mj.generation.search import painter_actions
from garage_mj.grid.metrics import evaluate
from garage_mj.grid.painters import paint_garage

ENV_ID = "garage_mj/GarageGenCond-v0"


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_check_env_registration_and_shape():
    check_env(GarageGenCondEnv(map="tiny_7x11"), skip_render_check=True)
    env = gym.make(ENV_ID, map="tiny_7x11", view_size=5)
    assert env.observation_space.shape == (GarageGenEnv(view_size=5).observation_space.shape[0] + N_COND,)
    assert sum(1 for k in gym.registry if k == ENV_ID) == 1


def _rollout(seed: int, actions) -> list:
    env = gym.make(ENV_ID, map="tiny_7x11")
    obs, info = env.reset(seed=seed)
    out = [(obs.copy(), 0.0)]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs.copy(), r))
        if term or trunc:
            break
    return out


def test_deterministic_under_a_seed():
    actions = np.random.default_rng(3).integers(4, size=120)
    a, b = _rollout(5, actions), _rollout(5, actions)
    assert len(a) == len(b)
    for (oa, ra), (ob, rb) in zip(a, b):
        np.testing.assert_array_equal(oa, ob)
        assert ra == rb
    assert not np.array_equal(_rollout(6, actions)[0][0], a[0][0])  # another seed, another band


def test_band_is_in_the_observation():
    cfg = ConditionConfig(difficulty_lo=0.4, difficulty_hi=0.9, band_width=0.1)
    env = GarageGenCondEnv(map="tiny_7x11", condition=cfg)
    obs, info = env.reset(seed=0, options={"difficulty": (0.3, 0.45), "coverage": (0.5, 0.8)})
    np.testing.assert_allclose(obs[-N_COND:], [0.3, 0.45, info["difficulty"], 0.5, 0.8], atol=1e-6)
    assert info["target_difficulty"] == (0.3, 0.45)
    for seed in range(20):  # drawn bands: band_width wide, inside the configured range
        obs, info = env.reset(seed=seed)
        lo, hi = info["target_difficulty"]
        assert 0.4 <= lo and hi <= 0.9 + 1e-9 and hi - lo == pytest.approx(0.1)
        np.testing.assert_allclose(obs[-N_COND:-3], [lo, hi], atol=1e-6)
    with pytest.raises(ValueError, match="band"):
        env.reset(seed=0, options={"difficulty": (0.6, 0.2)})


def test_landing_in_the_band_pays():
    garage = paint_garage("tiny_7x11", seed=1)
    actions = painter_actions(garage)

    def run(band):
        env = GarageGenCondEnv(map=garage, six_stall_axis=garage.six_stall_axis, max_steps=4 * len(actions))
        env.reset(seed=0, options={"difficulty": band})
        total, info = 0.0, {}
        for a in actions:
            _, r, term, trunc, info = env.step(a)
            total += r
            if term or trunc:
                break
        return total, info

    d = run((0.0, 1.0))[1]["difficulty"]
    inside, info_in = run((max(0.0, d - 0.05), min(1.0, d + 0.05)))
    outside, info_out = run((0.0, 0.0) if d > 0.3 else (1.0, 1.0))
    assert info_in["usable"] and info_in["in_band"] and not info_out["in_band"]
    assert inside - outside >= ConditionConfig().band_bonus


def test_generate_stores_distinct_garages_in_the_band_deterministically(tmp_path):
    assert shipped_generator("tiny_7x11") is not None, "models/generators/tiny_7x11.zip is not shipped"
    hashes = []
    for name in ("a", "b"):
        lib = tmp_path / f"{name}.sqlite"
        r = generate("tiny_7x11", (0.4, 1.0), 6, lib, seed=3, progress=False)
        assert r.found == r.stored == 6
        with Library(lib, create=False) as store:
            rows = store.query()
            assert len(rows) == 6 and len({x.hash for x in rows}) == 6
            assert all(0.4 <= x.difficulty <= 1.0 and x.map == "tiny_7x11" for x in rows)
            assert all(x.run == "generate:tiny_7x11" and x.seed == 3 for x in rows)
            hashes.append(sorted(x.hash for x in rows))
    assert hashes[0] == hashes[1]


def test_generate_cli_and_unreachable_band(tmp_path, capsys):
    lib = tmp_path / "g.sqlite"
    assert main(["generate", "--map", "tiny_7x11", "--difficulty", "0.4", "1.0", "--count", "3",
                 "--library", str(lib), "--no-progress"]) == 0
    assert "3 distinct garages" in capsys.readouterr().out
    # tiny_7x11 admits nothing below ~0.45 (garage_mj.generation.search): the band stays empty
    assert main(["generate", "--map", "tiny_7x11", "--difficulty", "0.0", "0.05", "--count", "5",
                 "--library", str(lib), "--max-episodes", "40", "--no-progress"]) == 2
    assert "found 0 of 5" in _err_line(capsys)


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--map", "tiny_7x11", "--difficulty", "0.9", "0.1"], "LO is above HI"),
        (["--map", "no_such_map", "--difficulty", "0.1", "0.9"], "no map named"),
        (["--map", "{usermap}", "--difficulty", "0.1", "0.9", "--model-out", "{tmp}/g.pt"], "ends in .zip"),
        (["--map", "tiny_7x11", "--difficulty", "0.1", "0.9", "--model", "{tmp}/none.zip"], "does not exist"),
        (["--map", "tiny_7x11", "--difficulty", "0.1", "0.9", "--model", "{junk}"], "not a generator"),
    ],
)
def test_bad_input_is_one_line(tmp_path, capsys, argv, match):
    usermap = tmp_path / "mine.txt"
    usermap.write_text("2 2 7 2 2\n2 0 0 0 2\n2 0 0 0 2\n2 0 0 0 2\n2 2 8 2 2\n")
    junk = tmp_path / "junk.zip"
    junk.write_bytes(b"not a model")
    subst = {"tmp": tmp_path, "usermap": usermap, "junk": junk}
    argv = ["generate", *[a.format(**subst) for a in argv], "--count", "2", "--library", str(tmp_path / "l.sqlite")]
    assert main(argv) == 2
    assert match in _err_line(capsys)


def test_train_a_tiny_generator_and_use_it(tmp_path):
    from garage_mj.generation.training import DQNConfig

    dqn = DQNConfig(n_envs=2, learning_starts=100, checkpoint_every=400, buffer_size=2000)
    out = tmp_path / "gen"
    meta = train_conditioned("tiny_7x11", 800, 0, out, dqn=dqn, progress=False, search_evaluations=200)
    assert meta["timesteps"] >= 800 and (out / "generator.zip").is_file() and meta["curve"]
    lo, hi = meta["condition"]["difficulty_lo"], meta["condition"]["difficulty_hi"]
    assert 0.0 <= lo < hi <= 1.0
    again = train_conditioned("tiny_7x11", 1200, 0, out, progress=False, resume=True)  # resumes
    assert again["timesteps"] >= 1200
    try:
        r = generate("tiny_7x11", (0.0, 1.0), 1, tmp_path / "l.sqlite", model=out / "generator.zip",
                     max_episodes=30, progress=False)
        assert r.found == 1
    except GenerationError as exc:  # an 1,200-step generator may not reach the exit yet
        assert "found 0 of 1" in str(exc)


def _replays_in_band(record, band) -> bool:
    """The stored garage, re-painted by GarageGenEnv, is usable and the same, with the stored difficulty in band."""
    g = record.garage
    env = GarageGenEnv(map=g, six_stall_axis=g.six_stall_axis)
    env.reset(seed=0)
    info = {}
    for a in painter_actions(g):
        _, _, term, trunc, info = env.step(a)
        if term or trunc:
            break
    return (info.get("usable") and np.array_equal(env.garage().grid, g.grid)
            and abs(info["difficulty"] - record.difficulty) < 1e-9 and band[0] <= record.difficulty <= band[1])


def test_search_stage_fills_a_low_band_the_rollouts_never_reach(tmp_path):
    # m5's generator paints 0.33-0.9; 0.2-0.3 is admissible (garage_mj.generation.search) but no rollout lands there
    band, hashes = (0.2, 0.3), []
    for name in ("a", "b"):
        lib = tmp_path / f"{name}.sqlite"
        r = generate("m5_13x13_aligned", band, 5, lib, seed=0, progress=False)
        assert r.found == r.stored == 5 and r.found_policy == 0 and r.found_search == 5
        assert r.replays >= 5 and r.search_steps > 0 and r.search_seeds > 0
        with Library(lib, create=False) as store:
            rows = store.query()
        assert len({x.hash for x in rows}) == 5
        assert all(x.run == "generate:m5_13x13_aligned+search" and x.seed == 0 for x in rows)
        assert all(_replays_in_band(x, band) for x in rows)
        hashes.append([x.hash for x in rows])
    assert hashes[0] == hashes[1]  # same seed, same garages in the same order


def test_coverage_band_is_kept_by_the_search(tmp_path):
    lib = tmp_path / "c.sqlite"
    r = generate("m5_13x13_aligned", (0.4, 0.5), 3, lib, coverage=(0.9, 1.0), seed=1, progress=False)
    assert r.found == 3
    with Library(lib, create=False) as store:
        rows = store.query()
    assert all(0.9 <= x.coverage <= 1.0 and evaluate(x.garage).usable and _replays_in_band(x, (0.4, 0.5))
               for x in rows)


def test_no_search_is_rejection_sampling_only(tmp_path, capsys):
    with pytest.raises(GenerationError, match="found 0 of 2") as info:
        generate("m5_13x13_aligned", (0.2, 0.3), 2, tmp_path / "n.sqlite", seed=0, max_episodes=200,
                 progress=False, search=False)
    r = info.value.result
    assert r.episodes == 200 and r.search_steps == 0 and r.found_search == 0 and "search steps" not in str(info.value)
    assert main(["generate", "--map", "m5_13x13_aligned", "--difficulty", "0.2", "0.3", "--count", "2",
                 "--library", str(tmp_path / "n.sqlite"), "--max-episodes", "50", "--no-search", "--no-progress"]) == 2
    assert "found 0 of 2" in _err_line(capsys)


def test_unreachable_band_with_search_is_one_line(tmp_path, capsys):
    # tiny_7x11 admits nothing below ~0.45: the policy and 3,000 search steps find nothing
    assert main(["generate", "--map", "tiny_7x11", "--difficulty", "0.0", "0.05", "--count", "5", "--library",
                 str(tmp_path / "u.sqlite"), "--max-episodes", "300", "--no-progress"]) == 2
    err = _err_line(capsys)
    assert "found 0 of 5" in err and "search steps" in err


def test_generate_trains_a_generator_for_a_map_file(tmp_path, capsys):
    lib = tmp_path / "mine.sqlite"
    argv = ["generate", "--map", "tests/data/maps/small_5x9.txt", "--difficulty", "0.0", "1.0", "--count", "3",
            "--library", str(lib), "--train-timesteps", "2000", "--no-progress"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    model = tmp_path / "mine.small_5x9.generator.zip"
    assert "trained the generator in" in out and "3 distinct garages" in out
    assert model.is_file() and model.with_suffix(".json").is_file()
    assert not (tmp_path / "mine.small_5x9.generator.zip.run").exists()
    with Library(lib, create=False) as store:
        assert store.count() == 3
    assert main(argv) == 0  # reused, not trained again; the same seed finds the same garages
    out = capsys.readouterr().out
    assert "using the generator trained earlier" in out and "0 new" in out
