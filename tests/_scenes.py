"""Tiny hand-made arenas with the ego car, a closed-loop test runner, and distinct painted garages, for tests."""

from __future__ import annotations

import mujoco
import numpy as np
from dm_control import mjcf

from garage_mj.driving.sim.outcomes import OutcomeMonitor, ego_contacts
from garage_mj.driving.sim.sensors import Camera, CameraConfig
from garage_mj.driving.sim.vehicle import Car, attach_car, compile_mjcf
from garage_mj.grid.painters import paint_garage
from garage_mj.scene.route_line import Route, to_car_frame
from garage_mj.scene.semantics import geom_classes

LOOKAHEAD = 4.0  # [m] waypoint distance ahead of the car's route projection


def arena(boxes=(), timestep: float = 0.005) -> mjcf.RootElement:
    """A floor plus named boxes ``(name, (x, y, z), (hx, hy, hz))``, radians, implicitfast."""
    root = mjcf.RootElement(model="arena")
    root.compiler.angle = "radian"
    root.option.timestep = timestep
    root.option.integrator = "implicitfast"
    root.worldbody.add("light", pos=[0, 0, 10], dir=[0, 0, -1], directional=True, castshadow=False)
    root.worldbody.add("geom", name="floor", type="plane", size=[60, 60, 5], rgba=[0.5, 0.5, 0.5, 1])
    for name, pos, half in boxes:
        root.worldbody.add("geom", name=name, type="box", pos=list(pos), size=list(half), rgba=[0.3, 0.4, 0.8, 1])
    return root


def build(boxes=(), pose=(0.0, 0.0, 0.0), timestep: float = 0.005):
    """Compiled (model, data, car) with the car reset at ``pose``."""
    root = arena(boxes, timestep)
    attach_car(root, 0.0, 0.0, 0.0)
    model = compile_mjcf(root)
    data = mujoco.MjData(model)
    car = Car(model)
    car.reset(data, *pose)
    return model, data, car


def run_test(boxes, route_points, driver, seed: int = 0, action_type: str = "continuous",
             dt: float = 0.1, max_time: float = 60.0):
    """Drive ``driver`` along the route from its start; returns (outcome, trajectory (T, 2))."""
    route = Route(route_points)
    p0, p1 = route.points[0], route.points[1]
    yaw = float(np.arctan2(p1[1] - p0[1], p1[0] - p0[0]))
    model, data, car = build(boxes, (float(p0[0]), float(p0[1]), yaw))
    camera = Camera(model, CameraConfig(rate_hz=1.0 / dt))
    classes = geom_classes(model)
    monitor = OutcomeMonitor(route)
    driver.reset({"seed": seed, "action_type": action_type, "dt": dt})
    n_sub = round(dt / model.opt.timestep)
    traj = []
    try:
        while data.time < max_time:
            x, y, yaw = car.pose(data)
            target = route.point_at(monitor.progress + LOOKAHEAD)
            s, _ = route.project((x, y), monitor.progress - 2.0, monitor.progress + 6.0)
            obs = {**camera.render(data), "waypoint": to_car_frame(target, x, y, yaw),
                   "speed": np.array([car.speed(data)]), "goal": to_car_frame(route.goal, x, y, yaw),
                   "remaining": np.array([route.length - s]), "pose": np.array([x, y, yaw])}
            car.act(data, driver.act(obs), dt)
            contacts = []
            for _ in range(n_sub):
                mujoco.mj_step(model, data)
                contacts += ego_contacts(model, data, car.geom_mask, classes)
            x, y, yaw = car.pose(data)
            traj.append((x, y))
            out = monitor.update(data.time, (x, y), car.speed(data), contacts, yaw=yaw)
            if out is not None:
                return out, np.array(traj)
    finally:
        camera.close()
    raise AssertionError("test did not end")


def distinct_painted(map_name: str, seeds) -> list:
    """The scripted painter's garages of ``map_name`` for ``seeds``, repeats dropped, in seed order."""
    out, seen = [], set()
    for seed in seeds:
        g = paint_garage(map_name, seed=seed)
        if g.canonical_hash() not in seen:
            seen.add(g.canonical_hash())
            out.append(g)
    return out
