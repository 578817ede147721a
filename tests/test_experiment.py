"""The generation experiment: protocol files, scaling, and a rerun that skips finished runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from garage_mj.core.backends import Compute
from garage_mj.core.config import ConfigError
from garage_mj.generation.library import Library
from garage_mj.generation.protocol import load_protocol
from garage_mj.reporting.experiment import run_experiment

GENERATION = Path(__file__).resolve().parents[1] / "generation"


def test_shipped_protocols():
    paper = load_protocol(GENERATION / "paper.toml")
    assert paper.maps == ("tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u")
    assert paper.seeds == (0, 1, 2, 3, 4) and paper.timesteps == 2_000_000
    scaled = paper.scaled(0.01)
    assert scaled.timesteps == 20_000 and scaled.dqn.checkpoint_every <= 2_000
    smoke = load_protocol(GENERATION / "smoke.toml")
    assert smoke.maps == ("tiny_7x11",) and len(smoke.seeds) == 2 and smoke.timesteps <= 10_000


@pytest.mark.parametrize(
    "text, match",
    [
        ("[experiment]\nmaps = ['tiny_7x11']\nseeds = [0]\ntimesteps = 10\nspeed = 1\n", "unknown key"),
        ("[experiment]\nmaps = ['tiny_7x11']\nseeds = [0]\n", "needs timesteps"),
        ("[experiment]\nmaps = []\nseeds = [0]\ntimesteps = 10\n", "maps must be"),
        ("[experiment]\nmaps = ['tiny_7x11']\nseeds = [0]\ntimesteps = 10\n[dqn]\ngama = 0.9\n", "gama"),
        ("[experimnt]\n", "unknown table"),
    ],
)
def test_bad_protocol(tmp_path, text, match):
    path = tmp_path / "p.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_protocol(path)


def test_run_then_rerun_skips(tmp_path):
    path = tmp_path / "p.toml"
    # the fast learner with 8 envs: enough gradient steps in 3,000 timesteps to paint usable garages
    path.write_text("[experiment]\nname = 't'\nmaps = ['tiny_7x11']\nseeds = [0, 1]\ntimesteps = 3000\nlearner = 'fast'\n"
                    "[dqn]\ncheckpoint_every = 1500\nlearning_starts = 500\nn_envs = 8\n")
    protocol = load_protocol(path)
    first = run_experiment(protocol, tmp_path / "out", compute=Compute(progress=False))
    assert sorted(first["trained"]) == [("tiny_7x11", 0), ("tiny_7x11", 1)] and first["skipped"] == []
    with Library(tmp_path / "out" / "library.sqlite") as lib:
        runs = {r.run for r in lib.query()}
        assert lib.count() == first["garages"]["tiny_7x11"] >= 1
    assert all(r.startswith("tiny_7x11_s") for r in runs)
    assert any(f.endswith("convergence.png") for f in first["figures"])
    second = run_experiment(protocol, tmp_path / "out", compute=Compute(progress=False))
    assert second["trained"] == [] and len(second["skipped"]) == 2
    assert second["garages"] == first["garages"]
