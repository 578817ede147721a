"""The ``learned`` driver: specs, loading a model zip (once), clear errors, driving a tiny garage, determinism."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from garage_mj.core.backends import Compute
from garage_mj.driving.drivers import (
    DRIVERS,
    DriverError,
    action_type_of,
    choose_action_type,
    load_driver,
    resolve_driver,
)
from garage_mj.driving.drivers.learned import DEFAULT_MODEL, LearnedDriver, default_model
from garage_mj.driving.learning.observation import VECTOR_KEYS, learned_space
from garage_mj.driving.sim.drive_env import GarageDriveEnv
from garage_mj.driving.sim.outcomes import OutcomeKind
from garage_mj.driving.sim.vehicle import DISCRETE_COMMANDS, DiscreteAction
from garage_mj.driving.sources import CruiseSettings
from garage_mj.reporting.cruise import run_cruise

REPO = Path(__file__).resolve().parents[1]
FAST = {"outcome": {"min_mean_speed": 2.0, "time_slack": 5.0}}  # short time limits keep tests quick
NO_MODEL = r"no learned driver model at {}.*: train one with `garage-mj train-driver` \(see README\) or give learned:PATH"


class SpaceEnv(gym.Env):
    """A do-nothing env with given spaces: enough to build (not train) an SB3 model."""

    def __init__(self, observation_space, action_space):
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, seed=None, options=None):
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


def save_model(path: Path, algo: str = "DQN", size: int = 64, actions: int = 4, seed: int = 0) -> Path:
    """An untrained ``MultiInputPolicy`` model on ``learned_space(size, size)`` saved at ``path``."""
    import stable_baselines3

    env = SpaceEnv(learned_space(size, size), spaces.Discrete(actions))
    extra = {"buffer_size": 64, "learning_starts": 8} if algo == "DQN" else {"n_steps": 8, "batch_size": 8}
    getattr(stable_baselines3, algo)("MultiInputPolicy", env, seed=seed, device="cpu", **extra).save(path)
    return path


def wire_steering(path: Path, gain: float = 10.0, slow: float = 0.3) -> Path:
    """Rewire the saved DQN at ``path`` into a bang-bang waypoint follower that reads only ``vector``.

    Q(accelerate) = 0.5 + 20 relu(slow - speed), Q(left) = gain relu(waypoint_y), Q(right) =
    gain relu(-waypoint_y), Q(brake) = 20 relu(0.1 - remaining) (all of the vector's scaled
    entries): its actions vary with what the car sees, unlike an untrained net's near-constant one.
    """
    import torch
    from stable_baselines3 import DQN

    model = DQN.load(path, device="cpu")
    extractor = model.policy.q_net.features_extractor
    start = 0  # where "vector" begins in the extractor's concatenated features
    for key, sub in extractor.extractors.items():
        if key == "vector":
            break
        start += int(sub(torch.zeros((1, *model.observation_space[key].shape))).shape[1])
    wy, speed, left = (start + VECTOR_KEYS.index(k) for k in ("waypoint_y", "speed", "remaining"))
    A = DiscreteAction
    for net in (model.policy.q_net, model.policy.q_net_target):
        l1, l2, l3 = (m for m in net.q_net if isinstance(m, torch.nn.Linear))
        with torch.no_grad():
            for layer in (l1, l2, l3):
                layer.weight.zero_()
                layer.bias.zero_()
            l1.weight[0, wy], l1.weight[1, wy], l1.bias[2] = 1.0, -1.0, 1.0
            l1.weight[3, left], l1.bias[3], l1.weight[4, speed], l1.bias[4] = -1.0, 0.1, -1.0, slow
            for i in range(5):
                l2.weight[i, i] = 1.0
            l3.weight[A.TURN_LEFT, 0] = l3.weight[A.TURN_RIGHT, 1] = gain
            l3.weight[A.ACCELERATE, 2], l3.weight[A.BRAKE, 3], l3.weight[A.ACCELERATE, 4] = 0.5, 20.0, 20.0
    model.save(path)
    return path


@pytest.fixture(scope="module")
def dqn_zip(tmp_path_factory) -> Path:
    return save_model(tmp_path_factory.mktemp("learned") / "dqn.zip")


@pytest.fixture(scope="module")
def steering_zip(tmp_path_factory) -> Path:
    return wire_steering(save_model(tmp_path_factory.mktemp("learned") / "steering.zip"))


def frame(waypoint=(4.0, 0.0), speed: float = 1.0, remaining: float = 12.0) -> dict:
    """A drive env observation of an empty 64x64 view."""
    return {"depth": np.full((64, 64), 5.0, np.float32), "segmentation": np.zeros((64, 64), np.uint8),
            "waypoint": np.array(waypoint, np.float32), "speed": np.array([speed], np.float32),
            "remaining": np.array([remaining], np.float32), "steer": np.array([0.0], np.float32),
            "goal": np.array([remaining, 0.0], np.float32)}


@pytest.fixture(scope="module")
def tiny_env(painted_tiny):
    env = GarageDriveEnv(garage=painted_tiny, action_type="discrete", outcome=FAST["outcome"])
    yield env
    env.close()


def drive(env, driver, seed: int) -> tuple[dict, list[int]]:
    """One test driven to its end; (final info, the actions taken)."""
    obs, info = env.reset(seed=seed)
    driver.reset(env.driver_info(seed))
    actions = []
    while True:
        action = driver.act(obs)
        actions.append(action)
        obs, _, term, trunc, info = env.step(action)
        if term or trunc:
            return info, actions


def test_specs_name_the_learned_driver_and_its_model(dqn_zip):
    assert "learned" not in DRIVERS  # hand-written ones only: learned takes a model
    assert resolve_driver("learned") is LearnedDriver
    assert resolve_driver(f"learned:{dqn_zip}") is LearnedDriver
    assert action_type_of("learned") == "discrete"
    assert action_type_of("learned:/no/such/model.zip") == "discrete"  # known without reading the file
    choice = choose_action_type(f"learned:{dqn_zip}")
    assert (choice.action_type, choice.source) == ("discrete", "driver")
    driver = load_driver(f"learned:{dqn_zip}")
    assert isinstance(driver, LearnedDriver) and driver.path == dqn_zip
    with pytest.raises(DriverError, match=r"give the model after the colon, learned:PATH"):
        resolve_driver("learned:")
    with pytest.raises(DriverError, match=r"names its model"):
        load_driver(f"learned:{dqn_zip}", model=dqn_zip)
    with pytest.raises(DriverError, match=r"unknown driver 'learn'.*park_assist, learned or learned:PATH\) or module:Class"):
        resolve_driver("learn")


def test_the_model_acts_on_the_unprivileged_observation(steering_zip):
    driver = load_driver(f"learned:{steering_zip}")
    driver.reset({"seed": 0, "action_type": "discrete"})
    assert driver.act(frame(waypoint=(4.0, 1.0))) == DiscreteAction.TURN_LEFT  # y left in the car frame
    assert driver.act(frame(waypoint=(4.0, -1.0))) == DiscreteAction.TURN_RIGHT
    assert driver.act(frame(waypoint=(4.0, 0.0))) == DiscreteAction.ACCELERATE
    assert driver.act(frame(waypoint=(4.0, 0.0), speed=2.0, remaining=0.2)) == DiscreteAction.BRAKE


@pytest.mark.parametrize("seed", [2, 4])
def test_drives_a_tiny_garage_to_an_outcome_deterministically(steering_zip, tiny_env, seed):
    info, actions = drive(tiny_env, load_driver(f"learned:{steering_zip}"), seed=seed)
    assert info["outcome"] in {k.value for k in OutcomeKind} and info["outcome"] != "infeasible"
    assert all(type(a) is int for a in actions) and len(set(actions)) >= 3  # it steers by what it sees
    again_info, again = drive(tiny_env, load_driver(f"learned:{steering_zip}"), seed=seed)
    assert again == actions
    assert (again_info["outcome"], again_info["time"], again_info["hit"]) == (
        info["outcome"], info["time"], info["hit"])


def test_a_process_loads_a_model_file_once_and_again_when_it_changes(tmp_path):
    path = save_model(tmp_path / "m.zip", seed=1)
    first, second = LearnedDriver(path), load_driver(f"learned:{path}")
    assert first.model is second.model
    save_model(path, seed=2)  # retrained in place: a new file version
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    assert LearnedDriver(path).model is not first.model


def test_a_ppo_model_drives_too_and_the_hosts_torch_settings_stay(tmp_path):
    import torch

    driver = LearnedDriver(save_model(tmp_path / "ppo.zip", algo="PPO"))
    driver.reset({"seed": 0, "action_type": "discrete"})
    threads, mkldnn = torch.get_num_threads(), torch.backends.mkldnn.enabled
    torch.set_num_threads(3)
    try:
        for host in (True, False):
            torch.backends.mkldnn.enabled = host
            assert driver.act(frame()) in range(4)
            assert torch.get_num_threads() == 3  # one thread only while the model acts
            assert torch.backends.mkldnn.enabled is host  # oneDNN off only while the model acts
    finally:
        torch.set_num_threads(threads)
        torch.backends.mkldnn.enabled = mkldnn


def test_continuous_actions_get_the_chosen_actions_command(steering_zip):
    driver = LearnedDriver(steering_zip)
    driver.reset({"seed": 0, "action_type": "continuous"})
    command = driver.act(frame(waypoint=(4.0, 1.0)))
    assert command.dtype == np.float32 and tuple(command) == DISCRETE_COMMANDS[DiscreteAction.TURN_LEFT]


def test_a_model_for_another_camera_is_one_clear_line(tmp_path, tiny_env):
    path = save_model(tmp_path / "small.zip", size=48)
    driver = load_driver(f"learned:{path}")  # loads: the camera is known at the first frame
    with pytest.raises(DriverError) as err:
        drive(tiny_env, driver, seed=3)
    msg = str(err.value)
    assert msg.startswith(f"learned driver model {path} does not fit this camera (64x64): its 'image' is "
                          "(2, 48, 48) uint8, the camera gives (2, 64, 64) uint8;") and "\n" not in msg


def test_a_model_with_other_actions_is_refused(tmp_path):
    path = save_model(tmp_path / "three.zip", actions=3)
    with pytest.raises(DriverError, match=rf"{path}: its actions are Discrete\(3\), the paper's are Discrete\(4\)"):
        load_driver(f"learned:{path}")


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_a_model_with_non_finite_weights_is_refused_naming_the_file(tmp_path, dqn_zip, bad):
    """A diverged model's NaN Q-values would argmax to one constant action that passes as its driving."""
    import torch
    from stable_baselines3 import DQN

    model = DQN.load(dqn_zip, device="cpu")
    with torch.no_grad():
        for p in model.policy.parameters():
            p.fill_(bad)
    path = tmp_path / "diverged.zip"
    model.save(path)
    with pytest.raises(DriverError, match=rf"learned driver model {path}: its weight .* holds NaN or infinite "
                                          r"values \(the training diverged\); retrain it") as err:
        load_driver(f"learned:{path}")
    assert "\n" not in str(err.value)


def test_missing_or_corrupt_models_name_the_file_and_the_fix(tmp_path, dqn_zip):
    missing = tmp_path / "missing.zip"
    with pytest.raises(DriverError, match=NO_MODEL.format(missing)):
        load_driver(f"learned:{missing}")
    garbage = tmp_path / "garbage.zip"
    garbage.write_bytes(b"not a zip at all")
    with pytest.raises(DriverError, match=NO_MODEL.format(garbage)) as err:
        load_driver(f"learned:{garbage}")
    assert "not a stable-baselines3 model zip: BadZipFile" in str(err.value) and "\n" not in str(err.value)
    broken = tmp_path / "broken.zip"  # a real zip whose weights are damaged
    with zipfile.ZipFile(dqn_zip) as src, zipfile.ZipFile(broken, "w") as dst:
        for name in src.namelist():
            dst.writestr(name, b"\x00damaged" if name == "policy.pth" else src.read(name))
    with pytest.raises(DriverError, match=NO_MODEL.format(broken)) as err:
        load_driver(f"learned:{broken}")
    assert "(cannot load it as DQN: " in str(err.value) and "\n" not in str(err.value)
    other = tmp_path / "other.zip"  # an SB3 zip of an algorithm the driver does not run
    with zipfile.ZipFile(dqn_zip) as src, zipfile.ZipFile(other, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "data":
                meta = json.loads(data)
                meta["policy_class"]["__module__"] = "sb3_contrib.qrdqn.policies"
                data = json.dumps(meta).encode()
            dst.writestr(name, data)
    with pytest.raises(DriverError, match=r"its policy is from sb3_contrib.qrdqn.policies; the learned driver runs "
                                          r"DQN or PPO"):
        load_driver(f"learned:{other}")


def test_learned_alone_runs_the_shipped_model(tmp_path, monkeypatch, dqn_zip):
    assert default_model() == REPO / "models" / "drivers" / f"{DEFAULT_MODEL}.zip"
    shipped = tmp_path / "drivers" / f"{DEFAULT_MODEL}.zip"
    import garage_mj.driving.learning.saved_model as saved_model_mod  # where the shipped models are named

    monkeypatch.setattr(saved_model_mod, "default_model", lambda name=DEFAULT_MODEL: shipped)
    with pytest.raises(DriverError, match=NO_MODEL.format(shipped)):
        load_driver("learned")
    shipped.parent.mkdir()
    shipped.write_bytes(dqn_zip.read_bytes())
    driver = load_driver("learned")
    assert driver.path == shipped and driver.model.action_space == spaces.Discrete(4)


def test_cruise_records_the_spec_and_builds_the_driver_from_it(dqn_zip, painted_tiny, tmp_path):
    spec = f"learned:{dqn_zip}"
    res = run_cruise([painted_tiny], 2, CruiseSettings(spec, env=FAST), tmp_path / "c",
                     compute=Compute(progress=False))
    assert res.tests_run == 2
    settings = json.loads((tmp_path / "c" / "run.json").read_text())
    assert settings["driver"] == spec and settings["action_type"] == "discrete"
    rows = (tmp_path / "c" / "tests.csv").read_text().splitlines()[1:]
    assert len(rows) == 2 and all(spec in row for row in rows)


def test_cli_cruise_with_a_missing_model_is_one_line(painted_tiny, tmp_path, capsys):
    from garage_mj.cli import main
    from garage_mj.generation.library import Library

    library = tmp_path / "lib.sqlite"
    with Library(library) as lib:
        lib.add(painted_tiny, map="tiny_7x11", run="test", seed=0, episode=0, timestep=0)
    missing = tmp_path / "nope.zip"
    assert main(["cruise", "--library", str(library), "--tests", "1", "--driver", f"learned:{missing}",
                 "--out", str(tmp_path / "c"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"garage-mj cruise: error: no learned driver model at {missing}: train one with "
                   "`garage-mj train-driver` (see README) or give learned:PATH")


def test_the_shipped_model_drives_a_tiny_garage_and_repeats_itself(painted_tiny):
    """``--driver learned``: the shipped ``models/drivers/cruise_m5.zip`` (trained on m5 garages only)
    drives 10 fixed tests of a tiny garage it never saw; it succeeded in 7 when shipped."""
    driver = load_driver("learned")
    env = GarageDriveEnv(garage=painted_tiny, action_type="discrete")

    def drive(seed):
        obs, info = env.reset(seed=seed)
        driver.reset(env.driver_info(seed))
        actions = []
        while True:
            actions.append(int(driver.act(obs)))
            obs, _, term, trunc, info = env.step(actions[-1])
            if term or trunc:
                return info["outcome"], actions

    try:
        runs = [drive(seed) for seed in range(10)]
        assert drive(0) == runs[0]  # deterministic
    finally:
        env.close()
    assert sum(outcome == "success" for outcome, _ in runs) >= 5
    assert all(len(set(actions)) >= 3 for _, actions in runs if len(actions) > 50)  # it steers and brakes


def test_the_fast_greedy_step_picks_what_sb3_predict_picks(painted_tiny):
    """``LearnedDriver.act`` calls the policy directly; on real frames it must agree with ``model.predict``
    (on the convolutions the act runs: oneDNN's differ in the 7th digit)."""
    import torch

    from garage_mj.driving.drivers.learned import MKLDNN_IN_ACT
    from garage_mj.driving.learning.observation import learned_observation

    driver = load_driver("learned")
    env = GarageDriveEnv(garage=painted_tiny, action_type="discrete")
    obs, _ = env.reset(seed=3)
    driver.reset(env.driver_info(3))
    try:
        for _ in range(60):
            action = driver.act(obs)
            host, torch.backends.mkldnn.enabled = torch.backends.mkldnn.enabled, MKLDNN_IN_ACT
            try:
                expected, _ = driver.model.predict(learned_observation(obs), deterministic=True)
            finally:
                torch.backends.mkldnn.enabled = host
            assert action == int(expected)
            obs, _, term, trunc, _ = env.step(action)
            if term or trunc:
                break
    finally:
        env.close()


class Touch:
    """A pickle that, when loaded, creates the file ``path``: what a crafted model file could run."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return Path.touch, (self.path,)


def rewrite_zip(src: Path, dst: Path, **entries: bytes) -> Path:
    """``src`` copied to ``dst`` with the given entries replaced or added (``policy_pth`` for ``policy.pth``)."""
    entries = {name.replace("_pth", ".pth"): data for name, data in entries.items()}
    with zipfile.ZipFile(src) as s, zipfile.ZipFile(dst, "w") as d:
        for name in s.namelist():
            d.writestr(name, entries.pop(name, None) or s.read(name))
        for name, data in entries.items():
            d.writestr(name, data)
    return dst


@pytest.mark.parametrize("key", ["policy_class", "policy_kwargs", "observation_space", "action_space",
                                 "lr_schedule", "exploration_schedule", "replay_buffer_class", "train_freq",
                                 "a_new_entry"])
def test_a_pickle_in_a_models_data_is_never_run(key, tmp_path):
    """Every pickled entry of the data is rebuilt from its plain fields (the payload ignored) or refused."""
    import base64
    import pickle

    marker = tmp_path / "ran"
    with zipfile.ZipFile(default_model()) as z:
        data = json.loads(z.read("data"))
    payload = base64.b64encode(pickle.dumps(Touch(marker))).decode()
    data[key] = {**data.get(key, {}), ":serialized:": payload}
    path = rewrite_zip(default_model(), tmp_path / f"{key}.zip", data=json.dumps(data).encode())
    try:
        driver = LearnedDriver(path)
    except DriverError as err:
        msg = str(err)
        assert key == "a_new_entry" and "\n" not in msg and msg.startswith(f"no learned driver model at {path} ")
        assert f"its data entry '{key}' is pickled Python" in msg and msg.endswith("give learned:PATH")
    else:
        assert key != "a_new_entry"
        assert driver.act(frame()) == LearnedDriver(default_model()).act(frame())
    assert not marker.exists()


def test_a_pickle_in_a_models_weights_is_never_run(tmp_path, dqn_zip):
    import io

    import torch

    marker = tmp_path / "ran"
    for entry in ("policy_pth", "pytorch_variables_pth"):
        blob = io.BytesIO()
        torch.save({"weight": Touch(marker)}, blob)
        path = rewrite_zip(dqn_zip, tmp_path / f"{entry}.zip", **{entry: blob.getvalue()})
        with pytest.raises(DriverError) as err:
            load_driver(f"learned:{path}")
        msg, name = str(err.value), entry.replace("_pth", ".pth")
        assert msg == (f"no learned driver model at {path} (cannot load it as DQN: its {name} holds more than weights "
                       "(Python objects to rebuild)): train one with `garage-mj train-driver` (see README) or give "
                       "learned:PATH")
        assert "weights_only" not in msg and not marker.exists()


def test_a_model_whose_plain_fields_lie_is_refused(tmp_path, dqn_zip):
    with zipfile.ZipFile(dqn_zip) as z:
        data = json.loads(z.read("data"))
    data["observation_space"]["spaces"] = "{'image': Box(0, 255, (3, 64, 64), uint8)}"
    path = rewrite_zip(dqn_zip, tmp_path / "lies.zip", data=json.dumps(data).encode())
    with pytest.raises(DriverError, match=r"its observation space .* is not a learned driver's \(learned_space or "
                                          r"park_space\)\): "
                                          r"train one with `garage-mj train-driver`"):
        load_driver(f"learned:{path}")


def test_a_driver_loads_its_model_to_act_the_same_as_a_trainer_would(dqn_zip):
    import torch
    from stable_baselines3 import DQN

    from garage_mj.driving.learning.saved_model import ActingOnly, load_driver_model

    acting = LearnedDriver(dqn_zip).model
    trainable = load_driver_model(dqn_zip, DQN)
    assert isinstance(acting.policy.optimizer, ActingOnly)  # no torch optimizer built (it imports torch._dynamo)
    assert not isinstance(trainable.policy.optimizer, ActingOnly)
    acting.observation_space.seed(0)
    for _ in range(5):
        obs = {k: v[None] for k, v in acting.observation_space.sample().items()}
        assert acting.predict(obs, deterministic=True)[0] == trainable.predict(obs, deterministic=True)[0]
    for a, b in zip(acting.policy.parameters(), trainable.policy.parameters(), strict=True):
        assert torch.equal(a, b)
    with pytest.raises(RuntimeError, match="loaded to act"):
        acting.policy.optimizer.step()
