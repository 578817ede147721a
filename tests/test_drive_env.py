"""GarageDrive-v0: spaces, check_env, seeded determinism, and every outcome forced through the env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import garage_mj  # noqa: F401  (registers the ids)
from garage_mj.driving.drivers import load_driver
from garage_mj.driving.sim.drive_env import START_OFFSET, GarageDriveEnv, _hit_sensors
from garage_mj.scene.mjcf_scene import parked_stalls
from garage_mj.scene.semantics import Semantic

ENV_ID = "garage_mj/GarageDrive-v0"
FULL = np.array([1.0, 0.0], dtype=np.float32)
BRAKE = np.array([-1.0, 0.0], dtype=np.float32)


def rollout(env, policy, max_steps: int = 2000):
    """Step ``policy(obs)`` (after a reset) until the episode ends; returns info, rewards, term, trunc."""
    obs = None
    rewards = []
    for _ in range(max_steps):
        obs, r, term, trunc, info = env.step(policy(obs))
        rewards.append(r)
        if term or trunc:
            return info, rewards, term, trunc
    raise AssertionError("the episode did not end")


def drive(env, driver_name: str, seed: int, **reset_options):
    driver = load_driver(driver_name)
    obs, info = env.reset(seed=seed, options=reset_options or None)
    driver.reset(env.unwrapped.driver_info(seed))
    trajectory = []
    while True:
        obs, _, term, trunc, info = env.step(driver.act(obs))
        trajectory.append(info["pose"])
        if term or trunc:
            return info, np.array(trajectory)


@pytest.fixture(scope="module")
def env(painted_tiny):
    e = gym.make(ENV_ID, garage=painted_tiny, action_type="continuous")
    yield e
    e.close()


def test_check_env_and_spaces(painted_tiny):
    env = gym.make(ENV_ID, garage=painted_tiny, action_type="discrete", rgb=True).unwrapped
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=3)
    assert obs["depth"].dtype == np.float32 and obs["depth"].shape == (64, 64)
    assert obs["segmentation"].dtype == np.uint8 and obs["rgb"].shape == (64, 64, 3)
    assert obs["waypoint"].shape == (2,) and obs["waypoint"][0] > 0  # ahead of the car
    assert info["target_stall"] in env.targets and info["route_length"] > START_OFFSET
    assert env.action_space.n == 4
    env.close()


def test_reset_draws_everything_from_the_seed(env):
    u = env.unwrapped
    draws = []
    for seed in (0, 1, 0):
        _, info = env.reset(seed=seed)
        draws.append((info["target_stall"], tuple(parked_stalls(u.model)), info["pose"]))
    assert draws[0] == draws[2]
    assert draws[0] != draws[1]
    assert draws[0][0] not in draws[0][1]  # the target stall is always empty


def test_occupancy_fraction(painted_tiny):
    env = GarageDriveEnv(garage=painted_tiny, occupancy=0.0)
    env.reset(seed=0)
    assert parked_stalls(env.model) == []
    env.close()
    env = GarageDriveEnv(garage=painted_tiny, occupancy=1.0)
    _, info = env.reset(seed=0)
    assert len(parked_stalls(env.model)) == len(env.parkable) - 1
    env.close()


def test_info_keeps_the_tests_entries_and_gives_each_step_its_own(env):
    _, first = env.reset(seed=4)
    fixed = {k: first[k] for k in ("target_stall", "route_length", "time_limit", "parked", "goal", "feasible")}
    first["actors"]["pedestrian"] = 99  # a caller changing one info changes no other
    infos = [env.step(1)[4] for _ in range(3)]
    for info in infos:
        assert {k: info[k] for k in fixed} == fixed
        assert info["actors"] == {"pedestrian": 0, "moving_car": 0, "clutter": 0}
    assert infos[0]["actors"] is not infos[1]["actors"]
    assert infos[0]["time"] < infos[1]["time"] < infos[2]["time"]
    _, other = env.reset(seed=5)  # a new test: its own entries
    assert other["time"] == 0.0 and other["route_length"] == env.unwrapped.route.length


@pytest.mark.parametrize("driver", ["waypoint", "vision"])
def test_builtin_drivers_reach_the_goal_deterministically(env, driver):
    info, traj = drive(env, driver, seed=2)
    assert info["outcome"] == "success", info["reason"]
    assert info["path_length"] > 0.8 * (info["route_length"] - START_OFFSET)
    again, traj2 = drive(env, driver, seed=2)
    assert again["outcome"] == info["outcome"] and again["time"] == info["time"]
    np.testing.assert_array_equal(traj, traj2)


def test_fused_scene_shows_the_camera_what_the_plain_scene_does(painted_tiny):
    """The env's scene (static bodies fused, empty stalls' cars hidden in place) renders the same depth and
    segmentation as the plain scene with those cars below the floor, frame by frame along a drive."""
    import mujoco

    from garage_mj.driving.sim.sensors import Camera
    from garage_mj.driving.sim.vehicle import attach_car, compile_mjcf
    from garage_mj.scene.mjcf_scene import HIDDEN_DEPTH, build_scene, parked_car_bodies

    env = GarageDriveEnv(garage=painted_tiny, action_type="continuous", occupancy=0.6)
    root = build_scene(env.scene)
    attach_car(root, *env._entrance)
    plain = compile_mjcf(root)
    # the same geoms, plus the invisible plane the car rolls on (the slab is drawn only): the frames show it is invisible
    assert env.model.nbody < plain.nbody and env.model.ngeom == plain.ngeom + 1
    datas = {"plain": mujoco.MjData(plain), "env": mujoco.MjData(env.model)}
    cams = {"plain": Camera(plain, env.camera_config), "env": Camera(env.model, env.camera_config)}
    driver = load_driver("waypoint")
    obs, _ = env.reset(seed=1)
    driver.reset(env.driver_info(1))
    for sid, b in parked_car_bodies(plain).items():
        plain.body_pos[b, 2] = 0.0 if sid in env.occupied else -HIDDEN_DEPTH
    frames, seen = 0, set()
    for step in range(400):
        if step % 2 == 0:
            img = {}
            for name, model in (("plain", plain), ("env", env.model)):
                datas[name].qpos[:] = env.data.qpos
                mujoco.mj_forward(model, datas[name])
                img[name] = cams[name].render(datas[name])
            np.testing.assert_array_equal(img["env"]["segmentation"], img["plain"]["segmentation"])
            np.testing.assert_array_equal(img["env"]["depth"], img["plain"]["depth"])
            seen |= set(np.unique(img["env"]["segmentation"]).tolist())
            frames += 1
        obs, _, term, trunc, _ = env.step(driver.act(obs))
        if term or trunc:
            break
    for cam in cams.values():
        cam.close()
    env.close()
    assert frames > 20  # the whole drive
    assert {Semantic.FLOOR, Semantic.ROAD_MARKING, Semantic.STALL_MARKING, Semantic.PILLAR, Semantic.PARKED_CAR} <= seen


def test_registered_id_is_deterministic_under_a_seed(painted_tiny):
    def run():
        env = gym.make(ENV_ID, garage=painted_tiny, action_type="discrete")
        obs, _ = env.reset(seed=7)
        env.action_space.seed(7)
        out = []
        for _ in range(30):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            out.append((r, info["pose"], float(obs["depth"].sum()), int(obs["segmentation"].sum())))
            if term or trunc:
                break
        env.close()
        return out

    assert run() == run()


def test_collision_with_the_border_is_recorded_with_its_class(painted_tiny):
    env = gym.make(ENV_ID, garage=painted_tiny, action_type="continuous", outcome={"max_deviation": 100.0})
    env.reset(seed=0, options={"start": (22.0, 4.5, np.pi), "occupied": []})  # west along the south road
    info, _, term, trunc = rollout(env, lambda _: FULL)
    env.close()
    assert term and not trunc
    assert info["outcome"] == "collision" and info["hit"] == "obstacle"
    assert info["hit_geom"].startswith("obstacle_")


def test_collision_with_a_parked_car(painted_tiny):
    env = gym.make(ENV_ID, garage=painted_tiny, action_type="continuous", occupancy=1.0,
                   outcome={"max_deviation": 100.0})
    env.reset(seed=0)
    info, rewards, term, _ = rollout(env, lambda _: FULL)  # straight on at the first bend
    assert info["outcome"] == "collision" and info["hit"] == "parked_car"
    assert rewards[-1] < 0
    env.close()


def test_collision_with_a_pillar_of_the_fused_scene(painted_tiny):
    import mujoco

    env = gym.make(ENV_ID, garage=painted_tiny, action_type="continuous", outcome={"max_deviation": 100.0})
    model = env.unwrapped.model
    pillar = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "pillar_20_column")
    assert model.geom_bodyid[pillar] == 0  # a geom of the world body now, no body of its own
    x, y = model.geom_pos[pillar, :2]
    env.reset(seed=0, options={"start": (x - 4.0, y, 0.0), "occupied": []})  # 4 m west of it, facing it
    info, _, term, _ = rollout(env, lambda _: FULL)
    env.close()
    assert term and info["outcome"] == "collision" and info["hit"] == "pillar"
    assert info["hit_geom"] == "pillar_20_column"


def test_the_contact_sensors_say_hit_exactly_when_the_contact_list_does(painted_tiny):
    """The env reads three contact-sensor counts per physics step instead of the contact list: on
    random drives (walls, parked cars, actors) both must agree at every step."""
    import mujoco

    env = gym.make(ENV_ID, garage=painted_tiny, action_type="continuous", occupancy=1.0,
                   scenario={"pedestrians": 1, "moving_cars": 1, "clutter": 1})
    base = env.unwrapped
    assert base._hit_counts is not None  # the floor is all the car touches that is no hit
    touched, floor, own = base._hit_counts
    model, data, ego, hittable = base.model, base.data, base.car.geom_mask, base._hittable
    rng = np.random.default_rng(0)
    steps = hits = 0
    for seed in range(4):
        env.reset(seed=seed)
        for _ in range(60):
            base.car.act(data, np.array([rng.uniform(0.3, 1.0), rng.uniform(-1.0, 1.0)]), base.dt)
            base._move_actors(*base.car.pose(data)[:2])
            for _ in range(base.n_substeps):
                mujoco.mj_step(model, data)
                g = data.contact.geom[: data.ncon]
                listed = bool(np.any(ego[g[:, 0]] & hittable[g[:, 1]] | ego[g[:, 1]] & hittable[g[:, 0]]))
                counted = bool(data.sensordata[touched] > data.sensordata[floor] + data.sensordata[own])
                assert listed == counted, (seed, g)
                steps, hits = steps + 1, hits + listed
    assert hits > 100 and steps - hits > 100  # both cases were seen
    marking = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "roadmark")
    assert marking >= 0 and not hittable[marking]
    model.geom_contype[marking] = model.geom_conaffinity[marking] = 1  # a touchable geom that is no hit:
    assert _hit_sensors(model, ego, hittable) is None  # the counts cannot tell, the env reads the list
    env.close()


def test_braking_forever_deadlocks(env):
    env.reset(seed=0)
    info, _, term, _ = rollout(env, lambda _: BRAKE)
    assert term and info["outcome"] == "deadlock" and "no progress" in info["reason"]


def test_a_missed_goal_terminates_like_a_deadlock(painted_tiny):
    # the same stop at the entrance, counted as near the goal (a radius wider than the garage): missed_goal
    env = gym.make(ENV_ID, garage=painted_tiny, action_type="continuous", outcome={"missed_goal_radius": 1000.0})
    env.reset(seed=0)
    info, _, term, trunc = rollout(env, lambda _: BRAKE)
    assert term and not trunc and info["outcome"] == "missed_goal"
    assert "from the goal pose (tolerance 1 m, 0.35 rad), no progress for" in info["reason"]
    env.close()


def test_timeout_truncates(painted_tiny):
    env = gym.make(ENV_ID, garage=painted_tiny, action_type="discrete",
                   outcome={"min_mean_speed": 1000.0, "time_slack": 2.0})
    env.reset(seed=0)
    info, _, term, trunc = rollout(env, lambda _: 3)  # BRAKE
    assert trunc and not term and info["outcome"] == "timeout"
    env.close()


def test_bad_arguments_are_one_clear_error(painted_tiny):
    from garage_mj.core.config import ConfigError

    with pytest.raises(ValueError, match="needs garage="):
        GarageDriveEnv()
    with pytest.raises(ValueError, match="action_type"):
        GarageDriveEnv(garage=painted_tiny, action_type="joystick")
    with pytest.raises(ConfigError, match="unknown key"):
        GarageDriveEnv(garage=painted_tiny, car={"max_sped": 3.0})


@pytest.mark.parametrize("action", [[np.nan, 0.0], [0.5, np.inf], [-np.inf, np.nan]])
def test_a_non_finite_action_is_refused_naming_it_before_anything_moves(env, action):
    env.reset(seed=0)
    env.step(FULL)
    sim = env.unwrapped
    before = (sim.data.time, sim.car.pose(sim.data), sim.monitor.progress)
    with pytest.raises(ValueError, match=r"the driver's action \[.*\] is not finite \(NaN or infinity\)"):
        env.step(np.array(action, np.float32))
    assert (sim.data.time, sim.car.pose(sim.data), sim.monitor.progress) == before
    _, _, term, trunc, info = env.step(FULL)  # a finite action drives on
    assert sim.data.time > before[0] and not (term or trunc)


def test_a_non_finite_discrete_action_is_refused(painted_tiny):
    env = GarageDriveEnv(garage=painted_tiny, action_type="discrete")
    env.reset(seed=0)
    for action in (np.float64(np.nan), float("inf"), np.float32(-np.inf)):
        with pytest.raises(ValueError, match="is not finite"):
            env.step(action)
    with pytest.raises(ValueError, match="is not one of 0..3"):
        env.step(7)
    env.step(0)
    env.close()


def test_sb3_trains_ppo_on_image_observations_through_make_vec_env(painted_tiny):
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.preprocessing import is_image_space
    from stable_baselines3.common.torch_layers import NatureCNN

    venv = make_vec_env("garage_mj/GarageDrive-v0", n_envs=2, seed=0,
                        env_kwargs={"garage": painted_tiny, "action_type": "continuous", "image_obs": True})
    try:
        space = venv.observation_space
        assert is_image_space(space["depth"]) and is_image_space(space["segmentation"])
        obs = venv.reset()
        assert obs["depth"].shape == (2, 64, 64, 1) and obs["depth"].dtype == np.uint8
        model = PPO("MultiInputPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
        extractors = model.policy.features_extractor.extractors
        assert isinstance(extractors["depth"], NatureCNN) and isinstance(extractors["segmentation"], NatureCNN)
        model.learn(256)
        assert model.num_timesteps >= 256
    finally:
        venv.close()
