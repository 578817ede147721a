"""The reverse gear (docs/spec.md section 8): park actions back the car up, gears change only at rest, cruise is untouched."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from garage_mj.driving.sim.vehicle import (
    DISCRETE_COMMANDS,
    PARK_DISCRETE_COMMANDS,
    Car,
    DiscreteAction,
    Gear,
    ParkAction,
    clip,
    park_action_space,
    park_command_from_action,
)
from tests._scenes import build

DT = 0.1  # [s] control period


def step(model, data, n: int = 0) -> None:
    for _ in range(n or round(DT / model.opt.timestep)):
        mujoco.mj_step(model, data)


def park_drive(model, data, car, seconds: float, action) -> list[tuple[float, Gear, float]]:
    """Apply the park ``action`` for ``seconds``; per period (speed before, gear after, speed after)."""
    rows = []
    for _ in range(round(seconds / DT)):
        before = car.speed(data)
        car.park_act(data, action, DT)
        step(model, data)
        rows.append((before, car.gear, car.speed(data)))
    return rows


def test_reverse_from_rest_backs_up_at_the_capped_speed():
    model, data, car = build()
    assert car.gear is Gear.D
    rows = park_drive(model, data, car, 6.0, [1.0, 0.0, -1.0])
    assert rows[0][1] is Gear.R  # at rest: the first request is honoured
    x, y, yaw = car.pose(data)
    cap = car.config.max_reverse_speed
    assert cap == 1.5
    assert car.speed(data) == pytest.approx(-cap, abs=0.1)
    assert min(r[2] for r in rows) > -cap - 0.1  # never faster than the cap
    assert x < -6.0 and abs(y) < 0.05 and abs(yaw) < 0.01


def test_steering_left_in_reverse_turns_like_a_real_car():
    """Left lock while backing up: the rear swings left, the heading turns clockwise (yaw rate v tan(d) / L)."""
    model, data, car = build()
    park_drive(model, data, car, 4.0, [1.0, 1.0, -1.0])
    _, y_back, yaw_back = car.pose(data)
    assert car.speed(data) < -1.0
    assert yaw_back < -0.5 and y_back > 0.5
    model, data, car = build()
    park_drive(model, data, car, 2.0, [1.0, 1.0, 0.0])  # the same steering forward turns the other way
    assert 0.5 < car.pose(data)[2] < math.pi


def test_gear_request_while_moving_brakes_until_at_rest():
    model, data, car = build()
    park_drive(model, data, car, 2.0, [1.0, 0.0, 0.0])
    assert car.gear is Gear.D and car.speed(data) > 3.0
    rows = park_drive(model, data, car, 4.0, [1.0, 0.0, -1.0])  # wants R at full pedal
    changed = [i for i, r in enumerate(rows) if r[1] is Gear.R]
    assert changed, "the car never reached rest"
    first = changed[0]
    assert first > 3  # braking from 4 m/s takes more than a few periods
    assert rows[first][0] < car.config.gear_change_speed  # the change happened at rest
    for before, gear, after in rows[:first]:
        assert gear is Gear.D and after < before  # still in D, and braking despite the full pedal
    assert car.speed(data) < -0.5  # then it backs up


def test_wheel_brakes_are_on_while_a_gear_request_waits():
    model, data, car = build()
    park_drive(model, data, car, 1.0, [1.0, 0.0, 0.0])
    car.park_act(data, [1.0, 0.3, -1.0], DT)
    assert car.gear is Gear.D
    assert np.all(data.ctrl[car._brake] == car.config.brake_gain)
    assert car.steer_angle > 0.0  # the steering still applies


def test_drive_after_reverse_and_braking_in_reverse():
    model, data, car = build()
    park_drive(model, data, car, 3.0, [1.0, 0.0, -1.0])
    assert car.speed(data) < -1.0
    rows = park_drive(model, data, car, 2.0, [-1.0, 0.0, -1.0])  # brake, staying in R
    assert all(r[1] is Gear.R for r in rows)
    assert abs(car.speed(data)) < 0.05 and max(r[2] for r in rows) < 0.05  # stops, never rolls forward
    x_stop = car.pose(data)[0]
    rows = park_drive(model, data, car, 3.0, [1.0, 0.0, 1.0])
    assert rows[0][1] is Gear.D
    assert car.speed(data) > 2.0 and car.pose(data)[0] > x_stop + 2.0
    car.reset(data, 0.0, 0.0, 0.0)
    assert car.gear is Gear.D and car.cruise_speed == 0.0


def test_discrete_park_actions_select_gears_and_drive_in_them():
    model, data, car = build()
    park_drive(model, data, car, 0.1, int(ParkAction.SELECT_REVERSE))
    assert car.gear is Gear.R
    park_drive(model, data, car, 3.0, int(ParkAction.ACCELERATE))
    assert car.gear is Gear.R and car.speed(data) < -1.0
    rows = park_drive(model, data, car, 3.0, int(ParkAction.SELECT_DRIVE))
    assert car.gear is Gear.D and abs(car.speed(data)) < 0.05
    assert all(r[1] is Gear.R for r in rows if abs(r[0]) >= car.config.gear_change_speed)
    park_drive(model, data, car, 2.0, int(ParkAction.ACCELERATE))
    assert car.speed(data) > 1.0


def test_park_actions_map_to_commands_and_spaces():
    for a in DiscreteAction:  # the cruise actions keep their numbers and commands, and the gear
        assert PARK_DISCRETE_COMMANDS[ParkAction(int(a))] == (*DISCRETE_COMMANDS[a], None)
        assert ParkAction(int(a)).name == a.name
    assert park_command_from_action(ParkAction.SELECT_REVERSE) == (-1.0, 0.0, Gear.R)
    assert park_command_from_action(np.int64(5)) == (-1.0, 0.0, Gear.D)
    assert park_command_from_action([2.0, -0.5, -0.01]) == (1.0, -0.5, Gear.R)
    assert park_command_from_action(np.array([0.5, 0.5, 0.0], np.float32)) == (0.5, 0.5, Gear.D)
    with pytest.raises(ValueError, match="park action 6"):
        park_command_from_action(6)
    with pytest.raises(ValueError, match="pedal, steer, gear"):
        park_command_from_action([1.0, 0.0])
    for bad in (float("nan"), np.float32("inf"), [math.nan, 0.0, 0.0], [0.0, 0.0, -math.inf]):
        with pytest.raises(ValueError, match="not finite"):  # refused, as a cruise action is: never a command
            park_command_from_action(bad)
    with pytest.raises(ValueError, match="three numbers"):
        park_command_from_action(np.array(["a", "b", "c"]))
    assert park_action_space("discrete").n == 6
    box = park_action_space("continuous")
    assert box.shape == (3,) and box.dtype == np.float32 and box.low.min() == -1.0 and box.high.max() == 1.0
    with pytest.raises(ValueError, match="park action type"):
        park_action_space("multi")
    assert len(DiscreteAction) == 4  # cruise keeps the paper's 4 actions


def _forward_only_control(car: Car, data, throttle: float, steer: float, dt: float) -> None:
    """``Car.control`` as it was before the reverse gear, verbatim: the cruise reference."""
    cfg = car.config
    u = clip(throttle, -1.0, 1.0)
    s = clip(steer, -1.0, 1.0)
    rate = cfg.max_accel if u >= 0 else cfg.max_decel
    v = car.cruise_speed + u * rate * dt
    ceiling = min(cfg.max_speed, max(car.speed(data), 0.0) + cfg.speed_lead)
    car.cruise_speed = clip(v, 0.0, max(ceiling, 0.0))
    step_ = cfg.steer_rate * dt
    car.steer_angle += clip(s * cfg.max_steer - car.steer_angle, -step_, step_)
    tan_d = math.tan(car.steer_angle)
    half = car.track / 2
    data.ctrl[car._steer[0]] = math.atan(car.wheelbase * tan_d / (car.wheelbase - half * tan_d))
    data.ctrl[car._steer[1]] = math.atan(car.wheelbase * tan_d / (car.wheelbase + half * tan_d))
    omega = car.cruise_speed / car.wheel_radius
    curvature = tan_d / car.wheelbase
    data.ctrl[car._drive[0]] = omega * (1 - half * curvature)
    data.ctrl[car._drive[1]] = omega * (1 + half * curvature)
    data.ctrl[car._brake] = max(0.0, -u) * cfg.brake_gain


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_cruise_actions_drive_bit_for_bit_as_before(kind):
    """300 periods of cruise actions through ``Car.act``: the same ctrl, qpos and qvel to the bit."""
    model, data, car = build(pose=(1.0, -2.0, 0.3))
    ref_data = mujoco.MjData(model)
    ref = Car(model)
    ref.reset(ref_data, 1.0, -2.0, 0.3)
    rng = np.random.default_rng(7)
    for k in range(300):
        if kind == "discrete":
            action = int(rng.integers(0, 4)) if k % 7 else 0
            command = DISCRETE_COMMANDS[DiscreteAction(action)]
        else:
            action = rng.uniform(-1.2, 1.2, 2).astype(np.float32)
            command = (clip(action[0], -1.0, 1.0), clip(action[1], -1.0, 1.0))
        car.act(data, action, DT)
        _forward_only_control(ref, ref_data, *command, DT)
        assert data.ctrl.tobytes() == ref_data.ctrl.tobytes(), k
        step(model, data)
        step(model, ref_data)
        assert car.gear is Gear.D
        assert data.qpos.tobytes() == ref_data.qpos.tobytes() and data.qvel.tobytes() == ref_data.qvel.tobytes(), k
    assert car.cruise_speed == ref.cruise_speed and car.steer_angle == ref.steer_angle
