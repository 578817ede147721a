"""Training a learned driver: the unprivileged observation, the fleet env, train-driver end to end and resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from garage_mj.driving.learning.observation import learned_observation, learned_space
from garage_mj.driving.sources import painted_sources

TINY = dict(iterations=2, steps_per_iteration=60, epochs=1, batch_size=32, n_envs=1, val_tests=1,
            cnn_channels=[8, 16, 16])


@pytest.fixture(scope="module")
def tiny_sources():
    return painted_sources("tiny_7x11", 2, seed=0)


def test_learned_observation_reads_nothing_privileged():
    rng = np.random.default_rng(0)
    obs = {"depth": rng.uniform(0, 60, (64, 64)).astype(np.float32),
           "segmentation": rng.integers(0, 14, (64, 64)).astype(np.uint8),
           "waypoint": np.array([4.0, -1.0], np.float32), "speed": np.array([2.0], np.float32),
           "remaining": np.array([25.0], np.float32), "steer": np.array([0.5], np.float32),
           "goal": np.array([3.0, 3.0], np.float32), "pose": np.array([1.0, 2.0, 0.3], np.float32),
           "actors": np.zeros((3, 4), np.float32)}
    depth_before = obs["depth"].copy()
    out = learned_observation(obs)
    assert set(out) == {"image", "vector"}
    assert learned_space(64, 64).contains(out)
    np.testing.assert_array_equal(obs["depth"], depth_before)  # the env's observation is not changed
    moved = dict(obs, pose=np.array([50.0, -5.0, 2.0], np.float32), actors=np.ones((3, 4), np.float32))
    other = learned_observation(moved)
    for key in out:
        np.testing.assert_array_equal(out[key], other[key])
    # what it does read changes it
    for key, value in (("steer", [-0.5]), ("goal", [-0.5, 0.2])):  # the car-frame goal is read, unlike the pose
        assert not np.array_equal(learned_observation(dict(obs, **{key: np.array(value, np.float32)}))["vector"],
                                  out["vector"])
    assert out["image"][0].max() == 255  # depth beyond the range saturates
    assert out["vector"][3] == out["vector"][5] == 1.0  # route left capped, at both scales
    assert out["vector"][6] == 1.0 and out["vector"][7] == 1.0  # goal 3 m ahead and left: clipped at 2 m


def test_fleet_env_is_seeded_and_unprivileged(tiny_sources):
    from garage_mj.driving.learning.fleet_env import FleetDriveEnv

    def run(seed):
        env = FleetDriveEnv(tiny_sources, expert=True, cache_size=1)
        seen = []
        obs, info = env.reset(seed=seed)
        for _ in range(3):
            assert set(obs) == {"image", "vector"} and env.observation_space.contains(obs)
            assert info["expert_action"] in range(4)
            seen.append((info["garage_index"], info["test_seed"], obs["vector"].tobytes()))
            for _ in range(5):
                obs, _, term, trunc, info = env.step(info["expert_action"])
            obs, info = env.reset()
        env.close()
        return seen

    assert run(3) == run(3)
    assert len({g for g, _, _ in run(3)} | {g for g, _, _ in run(4)}) >= 1
    env = FleetDriveEnv(tiny_sources, weights=[0.0, 1.0])
    assert {env.reset(seed=s)[1]["garage_index"] for s in range(4)} == {1}
    with pytest.raises(ValueError, match="weights"):
        env.set_weights([1.0])
    env.close()


def _params(path):
    with zipfile.ZipFile(path) as z:
        return z.read("policy.pth")


def test_train_driver_runs_resumes_and_repeats(tmp_path, tiny_sources, monkeypatch):
    from garage_mj.driving.learning import train as td

    a = td.train_driver(tiny_sources, tmp_path / "a", config=TINY, seed=1, progress=False)
    manifest = json.loads((tmp_path / "a" / "run.json").read_text())
    assert manifest["state"]["iterations_done"] == 2
    curve = (tmp_path / "a" / "curve.csv").read_text().splitlines()
    assert len(curve) == 3 and curve[0].startswith("iteration,states")
    assert a.name == "model.zip" and a.stat().st_size < 20e6
    from garage_mj.driving.drivers.learned import load_model
    from garage_mj.driving.learning.network import CameraRouteExtractor

    extractor = load_model(a).policy.q_net.features_extractor  # the filters the config asked for
    assert isinstance(extractor, CameraRouteExtractor) and [c.out_channels for c in extractor.convs] == [8, 16, 16]
    chosen = manifest["state"]["selected_iteration"]  # the best validation success, the later of equals
    rows = [r.split(",") for r in curve[1:]]
    best = max((float(r[6]), int(r[0])) for r in rows)[1]
    assert chosen == best
    assert _params(a) == _params(tmp_path / "a" / "checkpoints" / f"iter_{chosen:03d}.zip")

    calls = {"n": 0}
    real = td.validate

    def interrupted(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(td, "validate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        td.train_driver(tiny_sources, tmp_path / "b", config=TINY, seed=1, progress=False)
    assert json.loads((tmp_path / "b" / "run.json").read_text())["state"]["iterations_done"] == 1
    monkeypatch.setattr(td, "validate", real)
    with pytest.raises(td.TrainDriverError, match="another config"):
        td.train_driver(tiny_sources, tmp_path / "b", config=dict(TINY, epochs=2), seed=1, progress=False)
    with pytest.raises(td.TrainDriverError, match="--resume"):
        td.train_driver(tiny_sources, tmp_path / "b", config=TINY, seed=1, progress=False, resume=False)
    b = td.train_driver(tiny_sources, tmp_path / "b", config=TINY, seed=1, progress=False)
    assert _params(a) == _params(b)  # interrupted and resumed = uninterrupted
    def no_time(lines):  # wall_s (last column) differs between runs; every figure before it may not
        return [line.rsplit(",", 1)[0] for line in lines]

    assert no_time((tmp_path / "b" / "curve.csv").read_text().splitlines()) == no_time(curve)


def test_train_driver_command_and_the_model_drives(tmp_path, capsys):
    from garage_mj.cli import main
    from garage_mj.driving.drivers import load_driver
    from garage_mj.driving.sim.drive_env import GarageDriveEnv

    config = tmp_path / "driver.toml"
    config.write_text("epochs = 1\nbatch_size = 32\nval_tests = 1\n")
    out = tmp_path / "run"
    argv = ["train-driver", "tiny_7x11", "-n", "2", "--iterations", "1", "--steps", "40", "--workers", "1",
            "--config", str(config), "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    assert "drive it with --driver learned:" in capsys.readouterr().out
    assert json.loads((out / "garages.json").read_text())["garages"]
    assert main(argv) == 2  # an existing run is not overwritten
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume" in err[0]
    assert main([*argv, "--resume"]) == 0  # resumed after its end: nothing to do, the model stays

    driver = load_driver(f"learned:{out / 'model.zip'}")
    env = GarageDriveEnv(garage=painted_sources("tiny_7x11", 1, seed=0)[0].garage, action_type="discrete")
    obs, info = env.reset(seed=0)
    driver.reset(env.driver_info(0))
    for _ in range(2000):
        obs, _, term, trunc, info = env.step(driver.act(obs))
        if term or trunc:
            break
    env.close()
    assert info.get("outcome") in {"success", "collision", "timeout", "deadlock", "missed_goal"}


def test_hunt_curriculum_trains_on_the_garages_its_hunt_found(tmp_path, tiny_sources):
    import csv

    from garage_mj.driving.learning.train import train_driver

    cfg = dict(TINY, iterations=2, curriculum="hunt", hunt_budget=16)
    train_driver(tiny_sources, tmp_path / "h", config=cfg, seed=0, progress=False)
    state = json.loads((tmp_path / "h" / "run.json").read_text())["state"]
    with (tmp_path / "h" / "hunt" / "iter_001" / "failures.csv").open(newline="") as f:
        failing = [r for r in csv.DictReader(f) if int(r["failures"]) > 0]
    hunted = state.get("hunted", {}).get("1", [])
    assert len(hunted) == min(len(failing), cfg.get("hunt_keep", 8))
    assert set(hunted) <= {r["garage_hash"] for r in failing}


def test_dqn_fine_tuning_after_imitation(tmp_path, tiny_sources):
    from garage_mj.driving.learning.train import train_driver

    model = train_driver(tiny_sources, tmp_path / "rl", config=dict(TINY, iterations=1, rl_timesteps=300), seed=0,
                         progress=True)  # the bars of both stages
    rl = json.loads((tmp_path / "rl" / "run.json").read_text())["state"]["rl"]
    assert rl["timesteps"] == 300 and sum(rl["val"].values()) >= 1
    episodes = (tmp_path / "rl" / "rl_monitor.csv").read_text().splitlines()[2:]
    assert episodes and model.exists()
    assert _params(model) != _params(tmp_path / "rl" / "checkpoints" / "iter_000.zip")  # DQN changed the network
    # a finished imitation run gets (or drops) a DQN stage on resume, without imitating again
    train_driver(tiny_sources, tmp_path / "rl", config=dict(TINY, iterations=1), seed=0, progress=False)
    assert "rl" not in json.loads((tmp_path / "rl" / "run.json").read_text())["state"]
    assert _params(model) == _params(tmp_path / "rl" / "checkpoints" / "iter_000.zip")


def test_train_driver_with_actors_labels_the_oracles_yield(tmp_path):
    from garage_mj.cli import main
    from garage_mj.driving.learning.fleet_env import FleetDriveEnv

    config = tmp_path / "driver.toml"
    config.write_text("epochs = 1\nbatch_size = 32\nval_tests = 1\n")
    out = tmp_path / "run"
    assert main(["train-driver", "tiny_7x11", "-n", "1", "--iterations", "1", "--steps", "30", "--workers", "1",
                 "--pedestrians", "1", "--config", str(config), "--out", str(out), "--no-progress"]) == 0
    env_kwargs = json.loads((out / "run.json").read_text())["env"]
    assert env_kwargs["scenario"]["pedestrians"] == 1
    env = FleetDriveEnv(painted_sources("tiny_7x11", 1, seed=0), expert=True, env_kwargs=env_kwargs)
    obs, info = env.reset(seed=0)
    assert set(obs) == {"image", "vector"} and info["actors"]["pedestrian"] == 1  # the actor exists, unobserved
    env.close()


@pytest.mark.parametrize("channels", [[16, 32], [16, 0, 32], [16, 32, 2.5]])
def test_a_network_config_without_three_filter_counts_is_refused(channels):
    from garage_mj.driving.learning.train import DriverTrainConfig

    with pytest.raises(ValueError, match="cnn_channels must be a list of 3 integers"):
        DriverTrainConfig(cnn_channels=tuple(channels))


def test_the_network_body_is_its_layers_called_in_order():
    """The extractor's lean forward pass gives what calling its layers as modules gives, for a camera of any size."""
    import torch

    from garage_mj.driving.learning.network import CameraRouteExtractor
    from garage_mj.driving.learning.observation import learned_space

    torch.manual_seed(0)
    for h, w in ((64, 64), (48, 80)):
        net = CameraRouteExtractor(learned_space(h, w), channels=(4, 8, 8), cnn_features=16)
        assert net.features_dim == 16 + 8
        obs = {"image": torch.randint(0, 256, (3, 2, h, w)).float(), "vector": torch.rand(3, 8)}
        layers = [m for c in net.convs for m in (c, torch.nn.ReLU())] + [torch.nn.Flatten(), net.linear, torch.nn.ReLU()]
        with torch.no_grad():
            image = torch.nn.Sequential(*layers)(obs["image"] / 255.0)
            assert torch.equal(net(obs), torch.cat((image, obs["vector"]), dim=1))


def test_a_failed_start_leaves_the_folder_as_it_was_and_a_new_run_writes_its_own_garages(tmp_path, monkeypatch):
    """Ctrl-C (or any error) before the first iteration is done undoes what the start wrote; a new run in a
    folder where a killed start left another garages.json writes its own."""
    from garage_mj.cli import main
    from garage_mj.driving.learning import train as td

    seen = []

    def interrupted(*args, **kwargs):  # the start is made: the run's garage set is in the folder
        seen.append([g["hash"] for g in json.loads((out / "garages.json").read_text())["garages"]])
        raise KeyboardInterrupt

    monkeypatch.setattr(td, "_collect", interrupted)
    config = tmp_path / "driver.toml"
    config.write_text("epochs = 1\nbatch_size = 32\nval_tests = 0\n")
    out = tmp_path / "run"
    argv = ["train-driver", "tiny_7x11", "--iterations", "1", "--steps", "20", "--workers", "1",
            "--config", str(config), "--out", str(out), "--no-progress"]
    assert main([*argv, "-n", "2"]) == 130
    assert not out.exists()  # a new folder is not left behind
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "garages.json").write_text("left by a start that was killed")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main([*argv, "-n", "1", "--seed", "3"]) == 130
    assert len(seen) == 2 and len(seen[1]) == 1 and seen[1] != seen[0][:1]  # its own garage, not the stale file
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != ".garage-mj.lock"} == before


@pytest.fixture(scope="module")
def one_iteration_run(tmp_path_factory):
    """The argv and folder of a finished one-iteration run of train-driver (copied, never changed, by the tests)."""
    from garage_mj.cli import main

    root = tmp_path_factory.mktemp("driver_run")
    config = root / "driver.toml"
    config.write_text("epochs = 1\nbatch_size = 32\nval_tests = 0\n")
    argv = ["train-driver", "tiny_7x11", "-n", "1", "--iterations", "1", "--steps", "20", "--workers", "1",
            "--config", str(config), "--no-progress"]
    assert main([*argv, "--out", str(root / "run")]) == 0
    return argv, root / "run"


def test_init_starts_from_a_trained_model_and_a_checkpoint_brings_its_runs_states(one_iteration_run, tmp_path,
                                                                                   capsys):
    """``--init RUN/checkpoints/iter_NNN.zip`` fits the new run over that run's states and its own; ``--init
    model.zip`` over its own only; a resume with another --init, a missing file or another network is refused in
    one line, and a refused start leaves no folder."""
    from garage_mj.cli import main

    argv, run = one_iteration_run
    ckpt = run / "checkpoints" / "iter_000.zip"
    out = tmp_path / "tuned"
    assert main([*argv, "--out", str(out), "--init", str(ckpt)]) == 0
    manifest = json.loads((out / "run.json").read_text())
    assert manifest["init"]["states_from"] == [str(run / "data" / "iter_000.npz")]
    assert manifest["state"]["curve"][0]["states"] == 40  # the run's 20 states and the 20 it started from
    again = tmp_path / "again"  # carried on from the carried-on run: its states and those it started from
    assert main([*argv, "--out", str(again), "--init", str(out / "checkpoints" / "iter_000.zip")]) == 0
    manifest = json.loads((again / "run.json").read_text())
    assert manifest["init"]["states_from"] == [str(run / "data" / "iter_000.npz"), str(out / "data" / "iter_000.npz")]
    assert manifest["state"]["curve"][0]["states"] == 60
    weights = tmp_path / "weights"
    assert main([*argv, "--out", str(weights), "--init", str(run / "model.zip")]) == 0
    manifest = json.loads((weights / "run.json").read_text())
    assert manifest["init"]["states_from"] == [] and manifest["state"]["curve"][0]["states"] == 20
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--resume", "--init", str(run / "model.zip")]) == 2
    assert "another init" in capsys.readouterr().err
    for init, what in ((tmp_path / "none.zip", "is not a file"), ("learned:avp", "two models")):
        assert main([*argv, "--out", str(tmp_path / "refused"), "--init", str(init)]) == 2
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and what in err[0], err
    other = tmp_path / "other.toml"
    other.write_text("epochs = 1\nbatch_size = 32\nval_tests = 0\ncnn_channels = [8, 16, 16]\n")
    config = argv.index("--config") + 1
    assert main([*argv[:config], str(other), *argv[config + 1:], "--out", str(tmp_path / "refused"),
                 "--init", str(ckpt)]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "cnn_channels" in err[0] and "models/drivers/" in err[0], err
    assert not (tmp_path / "refused").exists()


def test_a_run_from_before_a_config_key_existed_resumes_under_its_default(one_iteration_run, tmp_path, capsys):
    import shutil

    from garage_mj.cli import main

    argv, run = one_iteration_run
    out = tmp_path / "run"
    shutil.copytree(run, out)
    manifest = json.loads((out / "run.json").read_text())
    del manifest["config"]["expert_foresight"]  # as a run.json written before the key was added
    (out / "run.json").write_text(json.dumps(manifest))
    assert main([*argv, "--out", str(out), "--resume"]) == 0
    manifest["config"]["expert_foresight"] = "present"  # another value than the default is another config
    (out / "run.json").write_text(json.dumps(manifest))
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--resume"]) == 2 and "another config" in capsys.readouterr().err


@pytest.mark.parametrize("how", ["truncated", "garbage", "empty", "missing", "other_arrays"])
def test_resume_over_a_damaged_data_shard_is_one_line_naming_it(one_iteration_run, tmp_path, capsys, how):
    import shutil

    from garage_mj.cli import main

    argv, run = one_iteration_run
    out = tmp_path / "run"
    shutil.copytree(run, out)
    shard = out / "data" / "iter_000.npz"
    data = shard.read_bytes()
    if how == "missing":
        shard.unlink()
    elif how == "other_arrays":
        np.savez(shard, image=np.zeros((3, 2, 8, 8), np.uint8), vector=np.zeros((3, 8), np.float32))
    else:
        shard.write_bytes({"truncated": data[: len(data) // 2], "garbage": b"\x93NUMPY garbage" * 50,
                           "empty": b""}[how])
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main([*argv, "--out", str(out), "--resume"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and str(shard) in err[0] and "another --out" in err[0], err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def _children(pid: int) -> list[int]:
    """The process ids whose parent is ``pid`` (read from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds the worker processes through /proc")
def test_a_killed_env_worker_is_one_line_that_says_resume(tmp_path):
    """kill -9 of a process driving the training envs: one line naming it, and --resume continues."""
    out = tmp_path / "run"
    proc = subprocess.Popen([str(Path(sys.executable).with_name("garage-mj")), "train-driver", "tiny_7x11", "-n", "1",
                             "--iterations", "1", "--steps", "100000", "--workers", "2", "--out", str(out),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        start, workers = time.monotonic(), []
        while not workers:  # the forkserver's children drive the envs
            assert proc.poll() is None and time.monotonic() - start < 90, proc.communicate()
            time.sleep(0.2)
            workers = [w for fs in _children(proc.pid) if "forkserver" in Path(f"/proc/{fs}/cmdline").read_text()
                       for w in _children(fs)]
        time.sleep(3.0)  # started, most likely stepping
        os.kill(workers[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    lines = err.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, err
    assert lines[0].startswith("garage-mj train-driver: error: a worker process driving the training envs died")
    assert lines[0].endswith("run the same command with --resume to continue")
    if "(worker " in lines[0]:  # killed while the envs stepped (not while they started): it is named
        assert "was killed by signal SIGKILL" in lines[0]


# -- the parking driver (train-driver --task park|avp) ------------------------------------------------------------
def _park_obs(rng, **over):
    obs = {"depth": rng.uniform(0, 30, (64, 64)).astype(np.float32),
           "segmentation": rng.integers(0, 14, (64, 64)).astype(np.uint8),
           "rear_depth": rng.uniform(0, 30, (64, 64)).astype(np.float32),
           "rear_segmentation": rng.integers(0, 14, (64, 64)).astype(np.uint8),
           "waypoint": np.array([4.0, -1.0], np.float32), "speed": np.array([-0.5], np.float32),
           "remaining": np.array([5.0], np.float32), "steer": np.array([0.5], np.float32),
           "goal": np.array([3.0, 3.0], np.float32), "stall": np.array([3.0, -4.0, 0.0, 1.0], np.float32),
           "gear": np.array([-1.0], np.float32), "ultrasonic": np.full(12, 5.0, np.float32),
           "slot": np.array([3.0, -4.2, 1.57, 2.5, 4.5], np.float32),
           "pose": np.array([1.0, 2.0, 0.3], np.float32), "park_plan": np.zeros((5, 3), np.float32)}
    obs.update(over)
    return obs


def test_park_observation_reads_the_parking_sensors_and_nothing_privileged():
    from garage_mj.driving.learning.observation import PARK_VECTOR_KEYS, park_observation, park_space

    rng = np.random.default_rng(0)
    obs = _park_obs(rng)
    out = park_observation(obs)
    assert park_space(64, 64).contains(out)
    vec = dict(zip(PARK_VECTOR_KEYS, out["vector"].tolist()))
    assert vec["gear"] == -1.0 and vec["slot_near_x"] == 1.0 and vec["slot_near_y"] == -1.0
    assert (vec["facing_cos"], vec["facing_sin"]) == (0.0, 1.0)  # the heading to end in: the stall entry's yaw
    # the rear camera is the image's second half; privileged entries and the route (a park test's is its reference
    # plan) change nothing
    assert not np.array_equal(park_observation(_park_obs(rng))["image"][2:], out["image"][2:])
    moved = park_observation(dict(obs, pose=np.array([9.0, 9.0, 1.0], np.float32),
                                  waypoint=np.array([-3.0, 2.0], np.float32), remaining=np.array([1.0], np.float32)))
    for key in out:
        np.testing.assert_array_equal(out[key], moved[key])
    with pytest.raises(ValueError, match="rear_depth, ultrasonic, slot.*--sensors rear_camera,ultrasonic,slot"):
        park_observation({k: v for k, v in obs.items() if k not in ("rear_depth", "ultrasonic", "slot")})
    # with the park route: the waypoint ahead on the route and the route left, at two scales, after the rest
    routed = park_observation(obs, route=True)
    assert park_space(64, 64, route=True).contains(routed) and not park_space(64, 64).contains(routed)
    np.testing.assert_array_equal(routed["vector"][: len(PARK_VECTOR_KEYS)], out["vector"])
    assert routed["vector"][len(PARK_VECTOR_KEYS):].tolist() == [1.0, -0.25, 0.5, 1.0]  # 4 m ahead, 5 m left


def test_a_parking_config_refuses_what_only_a_cruise_driver_does():
    from garage_mj.driving.learning.train import DriverTrainConfig

    with pytest.raises(ValueError, match="rl_timesteps"):
        DriverTrainConfig(task="park", rl_timesteps=10)
    with pytest.raises(ValueError, match="curriculum"):
        DriverTrainConfig(task="park", curriculum="hunt")
    with pytest.raises(ValueError, match="scenarios: the park actor scenarios"):
        DriverTrainConfig(scenarios=("park_clutter",))
    assert DriverTrainConfig(geometries=("default", "tight")).variants() == [  # a cruise driver in two geometries
        {}, {"world": {"stall_width": 2.3, "aisle_width": 6.5}, "parked_fleet": "mixed", "parked_jitter": 0.15}]
    pairs = DriverTrainConfig(task="park", geometries=("default", "parallel"), scenarios=("none", "park_clutter"))
    assert pairs.variants() == [{}, {"scenario": "park_clutter"}, {"world": {"stall_angle": 0.0}},
                                {"world": {"stall_angle": 0.0}, "scenario": "park_clutter"}]


def test_train_driver_task_park_trains_a_parking_model_that_parks_with_its_sensors(tmp_path, capsys):
    import csv

    from garage_mj.cli import main
    from garage_mj.core.backends import Compute
    from garage_mj.driving.cruise import run_cruise
    from garage_mj.driving.drivers import load_driver, tasks_of
    from garage_mj.driving.drivers.learned import LearnedParkDriver
    from garage_mj.driving.sources import CruiseSettings

    config = tmp_path / "park.toml"
    config.write_text("epochs = 1\nbatch_size = 32\nval_tests = 1\ncnn_channels = [8, 16, 16]\n")
    out = tmp_path / "run"
    argv = ["train-driver", "tiny_7x11", "-n", "2", "--task", "park", "--geometries", "default,tight",
            "--iterations", "1", "--steps", "30", "--workers", "1", "--config", str(config), "--out", str(out),
            "--no-progress"]
    assert main(argv) == 0
    assert "drive it with --driver learned:" in capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    assert run["task"] == "park" and run["config"]["geometries"] == ["default", "tight"]
    shard = np.load(out / "data" / "iter_000.npz")
    assert shard["image"].shape[1:] == (4, 64, 64) and shard["label"].ndim == 1  # a park command's index
    assert 0 <= shard["label"].min() and shard["label"].max() < 90
    spec = f"learned:{out / 'model.zip'}"
    driver = load_driver(spec)
    assert isinstance(driver, LearnedParkDriver) and tasks_of(spec) == ("park",)
    # a run turns on the sensors the driver observes, and stores them
    result = run_cruise(painted_sources("tiny_7x11", 1, seed=0), 1, CruiseSettings(driver=spec, task="park"),
                        tmp_path / "cruise", compute=Compute(workers=1, progress=False))
    stored = json.loads((tmp_path / "cruise" / "run.json").read_text())
    assert stored["action_type"] == "continuous"
    assert stored["env"]["sensors"] == {"rear_camera": True, "ultrasonic": True, "slot": True}
    rows = list(csv.DictReader((tmp_path / "cruise" / "tests.csv").open()))
    assert len(rows) == 1 and rows[0]["task"] == "park" and rows[0]["outcome"]
    assert result is not None


def avp_driver(guide: bool):
    """A learned:avp driver over two stand-in models: the cruise one always says [0.5, -0.2], the parking one (reading
    the park guide or not) [0.3, 1.0, -1.0]."""
    from garage_mj.driving.drivers.learned import LearnedAVPDriver

    class Cruise:
        def act(self, obs):
            return np.array([0.5, -0.2], np.float32)

    class Park:
        def act(self, obs):
            return np.array([0.3, 1.0, -1.0], np.float32)

    driver = LearnedAVPDriver.__new__(LearnedAVPDriver)
    driver.cruise, driver.park, driver.phase = Cruise(), Park(), "cruise"
    driver.dt, driver.decel, driver.covered = 0.1, 5.0, 0.0  # what reset takes from the reset info
    driver.park.guide = guide
    return driver


def test_the_learned_avp_driver_cruises_until_the_stall_is_alongside_stops_then_parks():
    """A parking model without the park guide takes over where the slot detector shows the stall alongside."""
    from garage_mj.driving.drivers import resolve_driver
    from garage_mj.driving.drivers.learned import LearnedAVPDriver

    assert resolve_driver("learned:avp") is LearnedAVPDriver and LearnedAVPDriver.tasks == ("avp",)
    driver = avp_driver(guide=False)

    def step(slot_x, slot_y, speed):
        return driver.act({"slot": np.array([slot_x, slot_y, 1.57, 2.5, 4.5], np.float32),
                           "speed": np.array([speed], np.float32)}).tolist()

    assert step(12.0, -5.0, 3.0) == [0.5, pytest.approx(-0.2), 1.0] and driver.phase == "cruise"  # stall ahead
    assert step(0.5, -9.0, 3.0)[2] == 1.0 and driver.phase == "cruise"  # alongside but too far aside
    assert step(0.5, -5.0, 3.0) == [-1.0, 0.0, 1.0] and driver.phase == "stop"  # alongside: brake
    assert step(-0.5, -5.0, 1.0) == [-1.0, 0.0, 1.0] and driver.phase == "stop"
    assert step(-0.7, -5.0, 0.0) == [pytest.approx(0.3), 1.0, -1.0] and driver.phase == "park"  # at rest: it parks
    assert step(20.0, 0.0, 2.0)[2] == -1.0 and driver.phase == "park"  # and keeps parking


def test_the_learned_avp_driver_hands_over_on_the_plans_start_once_the_park_guide_begins():
    """A parking model that reads the park guide takes over on the park plan's start (where its park tests started),
    wherever the stall is: from where the guide begins, START_RADIUS short of it, the car crawls on the cruise model's
    steering until its odometry says it has covered that, less its stopping distance; then it brakes to rest."""
    from garage_mj.driving.sim.park_guide import START_RADIUS

    driver = avp_driver(guide=True)

    def step(gear, speed, slot_x=0.0):
        guide = np.array([gear, 0.1, 0.0, 0.0, 0.0, 4.0, 1.0], np.float32) if gear else np.zeros(7, np.float32)
        return driver.act({"park_guide": guide, "slot": np.array([slot_x, -5.0, 1.57, 2.5, 4.5], np.float32),
                           "speed": np.array([speed], np.float32)}).tolist()

    assert step(0.0, 3.0) == [0.5, pytest.approx(-0.2), 1.0] and driver.phase == "cruise"  # stall alongside: not yet
    assert step(1.0, 3.0, slot_x=7.0) == [-1.0, pytest.approx(-0.2), 1.0]  # the guide begins: down to a crawl
    assert driver.phase == "approach" and driver.covered == pytest.approx(0.3)
    assert step(1.0, 0.4) == [1.0, pytest.approx(-0.2), 1.0]  # below the crawl: on, on the cruise model's steering
    for _ in range(40):
        out = step(1.0, 0.5)
        if driver.phase != "approach":
            break
    assert out == [-1.0, 0.0, 1.0] and driver.phase == "stop"  # covered, but for the stop from a crawl: brake
    stopping = driver.CRAWL * driver.dt + driver.CRAWL ** 2 / (2 * driver.decel)
    assert START_RADIUS - stopping <= driver.covered < START_RADIUS - stopping + 0.05 + 1e-9
    assert step(1.0, 0.0, slot_x=6.5) == [pytest.approx(0.3), 1.0, -1.0] and driver.phase == "park"  # at rest: park


def test_a_park_command_is_the_nearest_of_the_grid_in_the_same_gear():
    from garage_mj.driving.learning.park_actions import PARK_COMMANDS, nearest_park_action, park_command

    assert PARK_COMMANDS.shape == (90, 3)
    for index in range(len(PARK_COMMANDS)):  # every command is its own nearest
        assert nearest_park_action(PARK_COMMANDS[index]) == index
    assert park_command(nearest_park_action([0.9, -0.6, -1.0])).tolist() == [1.0, -0.5, -1.0]
    assert park_command(nearest_park_action([-0.2, 0.13, 1.0])).tolist() == [pytest.approx(-0.3), 0.25, 1.0]
    assert park_command(nearest_park_action([0.0, 0.0, 0.4])).tolist()[2] == 1.0  # gear >= 0: D, as the env reads it


@pytest.mark.parametrize("spec", ["learned:park", "learned:avp"])
def test_the_named_parking_drivers_run_the_shipped_model_and_say_how_to_train_one_without_it(spec, monkeypatch,
                                                                                             tmp_path):
    import garage_mj.driving.drivers.learned as learned
    from garage_mj.driving.drivers import DriverError, load_driver, tasks_of
    from garage_mj.driving.learning.saved_model import AVP_CRUISE_MODEL, PARK_MODEL, default_model

    driver = load_driver(spec)  # the shipped model, with the park route and the park guide it was trained with
    park = driver if isinstance(driver, learned.LearnedParkDriver) else driver.park
    assert park.path == default_model(PARK_MODEL) and (park.route, park.guide) == (True, True)
    if spec == "learned:avp":  # to the stall with the cruise model trained in the park geometries too
        assert driver.cruise.path == default_model(AVP_CRUISE_MODEL) != default_model()
    assert tasks_of(spec) == (spec.split(":")[1],)
    shipped = learned.model_path
    monkeypatch.setattr(learned, "model_path", lambda name: tmp_path / "park.zip" if name == "park" else shipped(name))
    with pytest.raises(DriverError, match=r"^no parking model is shipped at .*park\.zip: train one with garage-mj "
                                          r"train-driver GARAGES --task park --out RUN and drive it with --driver "
                                          r"learned:RUN/model\.zip"):
        load_driver(spec)


def test_the_replanning_park_expert_plans_again_once_the_car_has_left_its_plan(tiny_sources):
    from garage_mj.driving.learning.fleet_env import FleetDriveEnv
    from garage_mj.driving.learning.park_actions import PARK_COMMANDS

    off_plan = int(np.flatnonzero((PARK_COMMANDS == [1.0, 1.0, 1.0]).all(1))[0])  # full throttle, full left, D

    def plans(replan):
        env = FleetDriveEnv(tiny_sources, expert=True, env_kwargs={"task": "park", "maneuver": "any"}, replan=replan)
        obs, info = env.reset(seed=1)
        seen = [env._plan_poses]
        for _ in range(10):
            obs, _, term, trunc, info = env.step(off_plan)
            if env._plan_poses is not seen[-1]:
                seen.append(env._plan_poses)
            if term or trunc:
                break
        env.close()
        return seen

    kept = plans(False)
    assert len(kept) == 1  # the first plan, tracked whatever the car does
    again = plans(True)
    assert len(again) >= 2  # a new plan from where the car went
    assert np.hypot(*(again[1][0, :2] - again[0][0, :2])) > 0.5  # it starts from the car, not the test's start


def test_the_guided_park_expert_drives_the_new_plan_the_guide_shows(tiny_sources):
    """With the park guide, a learner held at rest off its plan is shown a new plan (the env's ``guide_replans``); the
    expert that labels its states tracks that plan from then on, not the test's first."""
    from garage_mj.driving.learning.fleet_env import FleetDriveEnv
    from garage_mj.driving.learning.park_actions import PARK_COMMANDS
    from garage_mj.driving.sim.park_guide import REPLAN_STUCK

    brake = int(np.flatnonzero((PARK_COMMANDS == [-1.0, 0.0, 1.0]).all(1))[0])
    env = FleetDriveEnv(tiny_sources, expert=True, env_kwargs={"task": "park", "maneuver": "reverse"},
                        park_route=True, park_guide=True)
    try:
        env.reset(seed=3)
        first = env._oracle.tracker
        for _ in range(int(round(REPLAN_STUCK / env.env.dt)) + 2):
            _, _, term, trunc, info = env.step(brake)
            assert not (term or trunc)
        guide, tracker = env.env.park_guide, env._oracle.tracker
        assert guide.replans == 1 and tracker is not first
        np.testing.assert_allclose(tracker.segments[0].points[0], guide.tracker.segments[0].points[0])
        assert tracker.k == guide.stretch == 0
    finally:
        env.close()


def test_the_park_expert_steers_on_the_learners_levels_so_its_labels_park(tiny_sources):
    """The expert's wheel targets are the learner's steering levels: driven by its own labels (the 90 commands), it
    parks, and it never waits at rest for a wheel angle between two levels (labels that taught the learner to
    stand still)."""
    from garage_mj.driving.drivers.park_tracking import ParkTrackConfig, ParkTracker
    from garage_mj.driving.learning.fleet_env import FleetDriveEnv
    from garage_mj.driving.learning.park_actions import PARK_COMMANDS, STEER_LEVELS

    env = FleetDriveEnv(tiny_sources, expert=True, env_kwargs={"task": "park", "maneuver": "reverse"}, replan=True)
    obs, info = env.reset(seed=3)
    assert env._oracle.park_config.steer_levels == STEER_LEVELS
    labels, done = [], False
    while not done:
        labels.append(info["expert_action"])
        obs, _, term, trunc, info = env.step(info["expert_action"])
        done = term or trunc
    env.close()
    assert info["outcome"] == "success", info.get("reason")
    assert set(PARK_COMMANDS[labels, 1].tolist()) <= set(STEER_LEVELS)
    for levels in (STEER_LEVELS, ()):  # a wheel target between two levels: snapped to the nearer with levels only
        tracker = ParkTracker.__new__(ParkTracker)
        tracker.car, tracker.config = env._oracle.car, ParkTrackConfig(steer_levels=levels)
        wheel = tracker._steer_for(0.04)
        assert (wheel in STEER_LEVELS) == bool(levels), wheel


def test_a_parking_drivers_rare_decisions_weigh_more_in_the_loss():
    """Changing gear and moving off at rest are a few states among many waits: they weigh gear_change_weight and
    start_weight; a brake at rest, or a go while moving, weighs 1."""
    from garage_mj.driving.learning.observation import PARK_VECTOR_KEYS, SPEED_RANGE
    from garage_mj.driving.learning.park_actions import nearest_park_action
    from garage_mj.driving.learning.train import DriverTrainConfig, _state_weights

    cfg = DriverTrainConfig(task="park", gear_change_weight=7.0, start_weight=3.0, stop_weight=1.0)
    speed, gear = PARK_VECTOR_KEYS.index("speed"), PARK_VECTOR_KEYS.index("gear")
    vectors = np.zeros((4, len(PARK_VECTOR_KEYS)), np.float32)
    vectors[:, gear] = 1.0  # D engaged
    vectors[3, speed] = 1.0 / SPEED_RANGE  # 1 m/s
    labels = np.array([nearest_park_action(c) for c in ([-1.0, 0.0, 1.0], [1.0, 0.5, 1.0], [-1.0, 0.0, -1.0],
                                                        [1.0, 0.0, 1.0])])
    assert _state_weights(cfg, vectors, labels).tolist() == [1.0, 3.0, 7.0, 1.0]


def test_the_shipped_parking_model_parks_a_tiny_garage_test_and_repeats_itself():
    """``--driver learned:park``: the shipped ``models/drivers/park_m5.zip`` (trained on m5 garages only) parked 2 of
    the first 6 park tests of this tiny garage when shipped (tests 1 and 2); test 2 is pinned here, driven twice."""
    from garage_mj.driving.cruise import run_test
    from garage_mj.driving.learning.observation import PARK_SENSORS
    from garage_mj.driving.sources import CruiseSettings

    (source,) = painted_sources("tiny_7x11", 1, seed=0)
    settings = CruiseSettings.from_env_kwargs("learned:park", {}, seed=0, action_type="continuous", task="park",
                                              maneuver="any").with_sensors(PARK_SENSORS)
    first, again = (run_test(source, 2, settings) for _ in range(2))
    assert first["outcome"] == "success", first.get("reason")
    same = ("outcome", "reason", "time", "path_length")
    assert {k: first.get(k) for k in same} == {k: again.get(k) for k in same}


def test_handover_start_is_a_parking_drivers_setting_within_a_car_length():
    from garage_mj.core.config import load_config
    from garage_mj.driving.learning.train import DriverTrainConfig

    with pytest.raises(ValueError, match="handover_start"):
        DriverTrainConfig(handover_start=1.5)  # a cruise driver's tests start at the entrance
    with pytest.raises(ValueError, match="handover_start"):
        load_config(DriverTrainConfig, {"task": "park", "handover_start": 7.0})
    assert DriverTrainConfig(task="park", handover_start=1.5).handover_start == 1.5
