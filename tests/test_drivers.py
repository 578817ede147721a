"""Drivers: registry and user loading, closed-loop outcomes on tiny arenas, determinism under a seed."""

from __future__ import annotations

import sys
import textwrap
import warnings

import numpy as np
import pytest

from garage_mj.driving.drivers import (
    DRIVERS,
    ActionTypeWarning,
    DriverError,
    action_type_of,
    choose_action_type,
    load_driver,
    resolve_driver,
)
from garage_mj.driving.drivers.vision import VisionDriver
from garage_mj.driving.sim.outcomes import OutcomeKind
from garage_mj.driving.sim.vehicle import DiscreteAction
from garage_mj.scene.semantics import NUM_CLASSES
from garage_mj.testing import driver_spec
from tests._scenes import run_test

L_ROUTE = [(0.0, 0.0), (14.0, 0.0), (14.0, 12.0)]  # a left turn at 14 m
STRAIGHT = [(0.0, 0.0), (20.0, 0.0)]
PILLAR_ON_ROUTE = [("pillar_0", (12.0, 0.0, 1.5), (0.3, 0.3, 1.5))]
WALL_ACROSS = [("wall_x", (12.0, 0.0, 1.5), (0.2, 10.0, 1.5))]


@pytest.mark.parametrize("name", sorted(DRIVERS))
def test_builtins_load(name):
    driver = load_driver(name)
    if name == "oracle":  # privileged: it needs the test's plan, and says so
        with pytest.raises(ValueError, match="needs the test's plan"):
            driver.reset({"seed": 0})
        return
    driver.reset({"seed": 0})
    assert callable(driver.act)


def test_bad_specs_are_clear_errors():
    with pytest.raises(DriverError, match=r"unknown driver 'nope'.*waypoint, vision.*module:Class"):
        resolve_driver("nope")
    with pytest.raises(DriverError, match=r"cannot import module 'no_such_pkg\.mod'"):
        resolve_driver("no_such_pkg.mod:Driver")
    with pytest.raises(DriverError, match=r"has no attribute 'Nope'"):
        resolve_driver("garage_mj.scene.route_line:Nope")
    with pytest.raises(DriverError, match=r"must be a class with reset\(info\) and act\(obs\)"):
        resolve_driver("garage_mj.scene.route_line:to_car_frame")
    with pytest.raises(ValueError, match="unknown key"):
        load_driver("waypoint", config={"cruise_sped": 2.0})


def test_user_driver_by_module_and_class(tmp_path, monkeypatch):
    (tmp_path / "my_driver.py").write_text(textwrap.dedent("""
        class Brake:
            def reset(self, info):
                self.seed = info["seed"]
            def act(self, obs):
                return 3

        class NeedsArgument(Brake):
            def __init__(self, gain):
                self.gain = gain
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        driver = load_driver("my_driver:Brake")
        driver.reset({"seed": 5})
        assert driver.act({}) == DiscreteAction.BRAKE
        with pytest.raises(DriverError, match=r"cannot construct NeedsArgument"):
            load_driver("my_driver:NeedsArgument")
    finally:
        sys.modules.pop("my_driver", None)


@pytest.mark.parametrize("name", sorted(DRIVERS))
def test_builtins_are_made_for_continuous_actions(name):
    assert action_type_of(name) == "continuous"
    choice = choose_action_type(name)
    assert (choice.action_type, choice.source, choice.label) == (
        "continuous", "driver", "continuous actions, the driver's own")


@pytest.fixture
def user_drivers(tmp_path, monkeypatch):
    (tmp_path / "typed_drivers.py").write_text(textwrap.dedent("""
        class Paper:  # no action_type: the paper's discrete actions
            def reset(self, info): pass
            def act(self, obs): return 0

        class Steering(Paper):
            action_type = "continuous"

        class Joystick(Paper):
            action_type = "joystick"
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "typed_drivers"
    sys.modules.pop("typed_drivers", None)


def test_a_user_driver_declares_its_action_type_or_is_discrete(user_drivers):
    assert action_type_of(f"{user_drivers}:Paper") == "discrete"
    assert action_type_of(f"{user_drivers}:Steering") == "continuous"
    with pytest.raises(DriverError, match=r"Joystick.action_type is 'joystick'; declare one of 'continuous', "):
        action_type_of(f"{user_drivers}:Joystick")


def test_another_action_type_than_the_drivers_own_is_warned_about(user_drivers):
    with pytest.warns(ActionTypeWarning) as caught:
        choice = choose_action_type("oracle", "discrete")
    (w,) = caught
    assert str(w.message).startswith("driver 'oracle' is made for continuous actions but runs with discrete ones: "
                                     "its [throttle, steer] commands are rounded to the paper's 4 actions")
    assert "\n" not in str(w.message) and "24% of feasible tests that way" in str(w.message)
    assert choice.label == "discrete actions from --action-type; the driver's own: continuous"
    with pytest.warns(ActionTypeWarning, match="'typed_drivers:Paper' is made for discrete actions but runs with "
                                               "continuous"):
        choose_action_type(f"{user_drivers}:Paper", "continuous")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # its own type, given or not: no warning
        assert choose_action_type("waypoint", "continuous").source == "--action-type"
        assert choose_action_type(f"{user_drivers}:Paper").action_type == "discrete"
        assert choose_action_type("oracle", "discrete", warn=False).action_type == "discrete"
    with pytest.raises(DriverError, match="action type 'joystick'"):
        choose_action_type("oracle", "joystick")


def test_noise_is_seeded_and_delay_shifts_commands():
    obs = {"waypoint": np.array([4.0, 1.0]), "speed": np.array([1.0])}
    noisy = {"steer_std": 0.2, "throttle_std": 0.2}

    def actions(seed, noise, n=6):
        d = load_driver("waypoint", noise=noise)
        d.reset({"seed": seed})
        return np.array([d.act(obs) for _ in range(n)])

    assert np.array_equal(actions(1, noisy), actions(1, noisy))
    assert not np.array_equal(actions(1, noisy), actions(2, noisy))
    delayed = actions(0, {"delay_steps": 2})
    assert np.array_equal(delayed[:2], np.zeros((2, 2))) and np.array_equal(delayed[2], actions(0, {})[0])


def test_waypoint_driver_follows_an_l_route():
    out, traj = run_test([], L_ROUTE, load_driver("waypoint"))
    assert out.kind is OutcomeKind.SUCCESS, out.reason
    assert traj[:, 1].max() > 8.0


def test_waypoint_driver_with_discrete_actions():
    out, _ = run_test([], L_ROUTE, load_driver("waypoint"), action_type="discrete")
    assert out.kind is OutcomeKind.SUCCESS, out.reason


def test_waypoint_driver_is_blind_and_hits_the_pillar():
    out, _ = run_test(PILLAR_ON_ROUTE, STRAIGHT, load_driver("waypoint"))
    assert out.kind is OutcomeKind.COLLISION
    assert out.hit_class == "pillar" and out.hit_geom == "pillar_0"


def test_vision_driver_follows_an_l_route():
    out, _ = run_test([], L_ROUTE, load_driver("vision"))
    assert out.kind is OutcomeKind.SUCCESS, out.reason


def test_vision_driver_goes_round_the_pillar():
    out, traj = run_test(PILLAR_ON_ROUTE, STRAIGHT, load_driver("vision"))
    assert out.kind is OutcomeKind.SUCCESS, out.reason
    assert np.abs(traj[:, 1]).max() > 1.0  # it swerved


def test_vision_driver_stops_before_a_wall():
    out, traj = run_test(WALL_ACROSS, STRAIGHT, load_driver("vision"))
    assert out.kind is OutcomeKind.DEADLOCK, out.reason
    assert traj[:, 0].max() < 12.0 - 0.2 - 2.3  # bumper short of the wall face


def test_vision_obstacle_points_see_the_pillar():
    from garage_mj.driving.sim.sensors import Camera
    from tests._scenes import build

    model, data, _ = build(PILLAR_ON_ROUTE)
    with Camera(model) as cam:
        img = cam.render(data)
    d = VisionDriver()
    d.reset({})
    pts = d.obstacle_points(img["depth"], img["segmentation"])
    assert len(pts) > 10
    assert np.allclose(np.median(pts, axis=0), (11.7, 0.0), atol=0.3)  # the pillar's face
    # any integer labels give the same points; labels past the last class read as the last class
    seg = img["segmentation"].copy()
    seg[:8] = 250
    wide = seg.astype(np.int32)
    assert np.array_equal(d.obstacle_points(img["depth"], wide), d.obstacle_points(img["depth"], seg))
    wide[:8] = NUM_CLASSES - 1
    assert np.array_equal(d.obstacle_points(img["depth"], wide), d.obstacle_points(img["depth"], seg))
    assert np.array_equal(d.obstacle_points(img["depth"], img["segmentation"].astype(np.int64)), pts)
    free = d.free_distance(pts, np.array([0.0, 0.05]))
    assert free[0] == pytest.approx(11.7 - 2.3, abs=0.3) and free[1] > free[0]


def test_vision_scores_one_arc_as_it_scores_that_arc_among_others():
    """The single-arc path (the waypoint arc, every frame) gives the numbers of the general one, exactly."""
    d = VisionDriver()
    d.reset({})
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-1.0, 16.0, 400), rng.uniform(-8.0, 8.0, 400)])
    k_max = 0.25
    ks = np.concatenate([rng.uniform(-k_max, k_max, 200), [0.0, 5e-5, -5e-5, 1e-4, -1e-4, k_max, -k_max]])
    for k in ks:
        alone, among = np.array([k]), np.array([k, 0.1, -0.2])
        assert d._first_obstacle(points, alone)[0][0] == d._first_obstacle(points, among)[0][0]
        assert d._first_obstacle(points[:3], alone)[0][0] == d._first_obstacle(points[:3], among)[0][0]
        assert d._seen_until(alone)[0] == d._seen_until(among)[0]
    assert np.isinf(d._first_obstacle(points[:0], np.array([0.1]))[0]).all()


@pytest.mark.parametrize("name", ["vision", "waypoint"])  # the oracle's: tests/test_oracle.py
def test_drivers_are_deterministic_under_a_seed(name):
    noise = {"steer_std": 0.1, "throttle_std": 0.1, "delay_steps": 1}
    runs = [run_test([], L_ROUTE, load_driver(name, noise=noise), seed=7) for _ in range(2)]
    (o1, t1), (o2, t2) = runs
    assert o1 == o2 and np.array_equal(t1, t2)


USER_DRIVER = """
class MyDriver:
    action_type = "discrete"
    def reset(self, info):
        pass
    def act(self, obs):
        return 3
"""


def test_user_driver_from_a_file_or_the_current_folder_without_pythonpath(tmp_path, monkeypatch):
    """``path/to/file.py:Class`` loads the file; ``module:Class`` finds a module in the current folder."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "file_driver.py").write_text(USER_DRIVER)
    (tmp_path / "here_driver.py").write_text(USER_DRIVER)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".", str(tmp_path))])
    try:
        assert resolve_driver("sub/file_driver.py:MyDriver").__name__ == "MyDriver"
        cls = resolve_driver("./sub/file_driver.py:MyDriver")
        assert cls is resolve_driver("sub/file_driver.py:MyDriver")
        assert resolve_driver(driver_spec(cls)) is cls  # the pytest plugin's spec of a class loaded from a file
        assert load_driver("here_driver:MyDriver").act({}) == 3
    finally:
        sys.modules.pop("here_driver", None)
    with pytest.raises(DriverError, match=r"^driver './nope\.py:MyDriver': no file './nope\.py'"):
        resolve_driver("./nope.py:MyDriver")
    with pytest.raises(DriverError, match=r"file 'sub/file_driver\.py' has no attribute 'Nope'"):
        resolve_driver("sub/file_driver.py:Nope")
    with pytest.raises(DriverError, match=r"cannot import module 'nowhere_driver': no such module in the current"):
        resolve_driver("nowhere_driver:MyDriver")
    (tmp_path / "broken.py").write_text("def oops(:\n")
    with pytest.raises(DriverError, match=r"running broken\.py failed: SyntaxError"):
        resolve_driver("broken.py:MyDriver")


def test_cli_user_driver_by_file_and_by_module_in_two_workers(tmp_path):
    """What a new user types, from the folder of their driver, no PYTHONPATH for it (``-P``: the current
    folder is not on the path, as with the installed ``garage-mj`` script); workers load it too."""
    import os
    import subprocess

    from garage_mj.generation.library import Library
    from garage_mj.grid.painters import paint_garage

    (tmp_path / "my_driver.py").write_text(USER_DRIVER)
    with Library(tmp_path / "lib.sqlite") as lib:
        for i in range(2):
            lib.add(paint_garage("tiny_7x11", seed=i + 1), map="tiny_7x11", run="test", seed=i, episode=0,
                    timestep=0)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p and p != str(tmp_path))}

    def cruise(driver, out):
        return subprocess.run([sys.executable, "-P", "-m", "garage_mj", "cruise", "--library", "lib.sqlite",
                               "--tests", "1", "--workers", "2", "--quiet", "--driver", driver, "--out", out],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)

    for driver, out in (("my_driver:MyDriver", "a"), ("./my_driver.py:MyDriver", "b")):
        done = cruise(driver, out)
        assert done.returncode == 0, done.stderr
        assert "2 tests on 2 garages (2 new)" in done.stdout
    done = cruise("./missing.py:MyDriver", "c")
    assert done.returncode == 2
    assert done.stderr.strip() == (f"garage-mj cruise: error: driver './missing.py:MyDriver': no file "
                                   f"'./missing.py' (from the current folder {tmp_path})")
