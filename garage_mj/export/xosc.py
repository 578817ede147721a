"""Cruise, park and AVP tests written as OpenSCENARIO XML 1.2 files (with ``scenariogeneration``).

One ``.xosc`` holds one test, exactly enough to replay it in garage-mj. The world frame
is the pack's OpenDRIVE frame (x east, y north, origin at the grid's south-west corner: the
same as :mod:`garage_mj.scene.world`), so poses are written as they are, with z = 0.

=================================================  ==============================================
OpenSCENARIO element                               carries
=================================================  ==============================================
``RoadNetwork/LogicFile@filepath``                 the pack's ``garage.xodr`` (relative to the
                                                   ``.xosc`` when possible); its folder is the pack
``ParameterDeclarations`` (``gmj_*``)              replay data: ``gmj_format``, ``gmj_garage_hash``,
                                                   ``gmj_target_stall``, ``gmj_occupied`` (stall
                                                   ids, comma separated), ``gmj_seed``,
                                                   ``gmj_driver``, ``gmj_action_type``, ``gmj_actors``
                                                   (actor names in order), per actor
                                                   ``gmj_actor_<name>_kind`` / ``_behaviour`` /
                                                   ``_stall``; every other ``meta`` entry as
                                                   ``gmj_<key>`` (typed; ``gmj_json_<key>`` for
                                                   lists, dicts and None)
``Entities/ScenarioObject[ego]``                   the ego: Vehicle, category car, 4.6 x 1.9 x 1.5 m
                                                   box centred on its reference point (the car's
                                                   centre, the point the poses and routes give)
``Entities/ScenarioObject[parkedcar_<stall>]``     a parked car in stall ``<stall>`` (Vehicle)
``Entities/ScenarioObject[<actor name>]``          an actor: pedestrian -> Pedestrian, moving_car ->
                                                   Vehicle, clutter -> MiscObject (obstacle); box
                                                   from :data:`garage_mj.scene.actor_spec.SHAPE_SIZE`
``Init`` ``TeleportAction/WorldPosition``          start pose of every entity (x, y, z=0, h=yaw);
                                                   an actor's is its first waypoint
``Init`` ego ``FollowTrajectoryAction``            the planned route: ``Polyline`` of the centre
                                                   path, no timing (``TimeReference/None``); a
                                                   vertex's h is the travel direction (cruise) or
                                                   the car's heading along the park plan, so h
                                                   opposite to the travel direction is a reverse
                                                   stretch (park, AVP: below)
``StopTrigger`` (*near* condition, below)          the goal pose (x, y, h=yaw), within 1.0 m,
                                                   triggering entity ``ego`` (park, AVP: the stall
                                                   pose)
``Story/Act/ManeuverGroup[<name>_group]``          a moving actor: one Event whose
                                                   ``FollowTrajectoryAction`` has a timed
                                                   ``Polyline`` (vertex time = waypoint t, relative
                                                   to the action start, scale 1, offset 0; h = yaw),
                                                   started by a *near* condition on the ego at the
                                                   trigger point, distance = ``trigger_radius``
=================================================  ==============================================

The *near* condition ("the ego's reference point within r of a point") is, in OpenSCENARIO 1.2
(the default, ``osc_minor=2``), a ``DistanceCondition`` (``value`` r, ``rule`` lessOrEqual,
``freespace`` false, ``relativeDistanceType`` euclidianDistance): 1.2 deprecates
``ReachPositionCondition`` and scenariogeneration refuses to write it there. With ``osc_minor=1``
(or 0) it is a ``ReachPositionCondition`` (``tolerance`` r); the reader reads both. The
ASAM checker runs all of its 17 checks on 1.2 files; on 1.1 only the XML and schema checks
apply (its rule checks are defined from 1.2 on).

A park or AVP test (``meta`` ``task`` "park" or "avp", ``maneuver`` "reverse" or "forward", the test's
own, and ``plan_start``, the vertex where the park plan begins: 0 for a park test, after the cruise route
for an AVP test) writes its route as rows (x, y, yaw): the reference park plan's car poses, one Polyline
(OpenSCENARIO 1.x has one shape per trajectory and no gear; a vertex's heading is the entity's
orientation, so a reverse stretch is one whose vertices face away from the next vertex). A cruise
test's file is as before park tests.

A static actor (one waypoint, no trigger) has no event. Reading a file back is
:mod:`garage_mj.export.xosc_read` (:func:`~garage_mj.export.xosc_read.read_xosc`); replaying it
in the drive env is :mod:`garage_mj.driving.replay`.
"""

from __future__ import annotations

import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write
from garage_mj.export.artefacts import MANIFEST, XODR
from garage_mj.scene.actor_spec import BEHAVIOURS, KINDS, SHAPE_SIZE, ActorSpec
from garage_mj.scene.car import car_geometry

OSC_MINOR = 2  # OpenSCENARIO 1.2
FORMAT = 1  # gmj_format: bumped when the mapping above changes
EGO = "ego"
EGO_SIZE = (4.6, 1.9, 1.5)  # length, width, height [m]
PARKED_PREFIX = "parkedcar_"
GOAL_TOLERANCE = 1.0  # [m]
_RESERVED = ("format", "target_stall", "occupied", "actors")  # gmj_ names the writer sets itself
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
_KEY = re.compile(r"[a-z][a-z0-9_]*\Z")


class XoscError(GarageMJError, ValueError):
    """A ``.xosc`` file cannot be written or read back as a garage-mj cruise test."""


def _f(v: Any, what: str) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise XoscError(f"{what} must be a number, got {v!r}") from None
    if not math.isfinite(x):
        raise XoscError(f"{what} must be finite, got {v!r}")
    return x


def _pose(p: Sequence[float], what: str) -> tuple[float, float, float]:
    try:
        x, y, yaw = p
    except (TypeError, ValueError):
        raise XoscError(f"{what} must be (x, y, yaw), got {p!r}") from None
    return _f(x, f"{what} x"), _f(y, f"{what} y"), _f(yaw, f"{what} yaw")


def _parked_table(parked_poses: Any) -> dict[int, tuple[float, ...]]:
    """stall -> pose from a mapping stall -> (x, y, yaw) or from layout placements (x, y, yaw, stall_id); a mapping's
    value may also be a parked car's body (``x``, ``y``, ``yaw``, ``length``, ``width``, ``height``, as
    :class:`~garage_mj.scene.parked_fleet.ParkedBody` has them): pose then size (x, y, yaw, length, width, height)."""
    out: dict[int, tuple[float, ...]] = {}
    if isinstance(parked_poses, Mapping):
        for k, v in parked_poses.items():
            if hasattr(v, "length"):  # a body as it stands: its pose and its size
                size = tuple(_f(getattr(v, n), f"parked car {k} {n}") for n in ("length", "width", "height"))
                out[int(k)] = (*_pose((v.x, v.y, v.yaw), f"parked car {k}"), *size)
            else:
                out[int(k)] = _pose(v, f"parked car {k}")
        return out
    for p in parked_poses or ():
        sid = getattr(p, "stall_id", None)
        if sid is None:
            continue
        out[int(sid)] = _pose((p.x, p.y, p.yaw), f"parked car {sid}")
    return out


def _meta_params(meta: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    """(name, OpenSCENARIO parameter type, value) of each meta entry."""
    out = []
    for key, v in meta.items():
        if not isinstance(key, str) or not _KEY.match(key) or key in _RESERVED or key.startswith(("actor_", "json_")):
            raise XoscError(f"meta key {key!r} is not allowed (lower-case identifier, not a reserved name)")
        if key == "seed" and (not isinstance(v, (int, np.integer)) or isinstance(v, bool)):
            raise XoscError(f"meta seed must be an integer, got {v!r}")
        if key in ("garage_hash", "driver", "action_type") and not isinstance(v, str):
            raise XoscError(f"meta {key} must be a string, got {v!r}")
        if isinstance(v, bool):
            out.append((f"gmj_{key}", "boolean", "true" if v else "false"))
        elif isinstance(v, (int, np.integer)):
            out.append((f"gmj_{key}", "integer", str(int(v))))
        elif isinstance(v, (float, np.floating)):
            out.append((f"gmj_{key}", "double", repr(_f(v, f"meta {key}"))))
        elif isinstance(v, str):
            out.append((f"gmj_{key}", "string", v))
        else:
            try:
                text = json.dumps(v, sort_keys=True, allow_nan=False)
            except (TypeError, ValueError) as exc:
                raise XoscError(f"meta {key!r} cannot be stored: {exc}") from None
            out.append((f"gmj_json_{key}", "string", text))
    return out


def _check_actor(a: ActorSpec) -> None:
    if not isinstance(a.name, str) or not _NAME.match(a.name) or a.name == EGO or a.name.startswith(PARKED_PREFIX):
        raise XoscError(f"actor name {a.name!r} must be an identifier other than {EGO!r} and {PARKED_PREFIX}*")
    if a.kind not in KINDS or a.behaviour not in BEHAVIOURS[a.kind]:
        raise XoscError(f"actor {a.name}: unknown kind/behaviour {a.kind!r}/{a.behaviour!r}")
    w = np.asarray(a.waypoints, dtype=float)
    if w.ndim != 2 or w.shape[1] != 4 or not len(w) or not np.isfinite(w).all() or (np.diff(w[:, 0]) < 0).any():
        raise XoscError(f"actor {a.name}: waypoints must be finite (K, 4) rows (t, x, y, yaw) with non-decreasing t")
    if a.trigger is None and len(w) > 1:
        raise XoscError(f"actor {a.name}: {len(w)} waypoints but no trigger; a moving actor needs one")
    if a.trigger is not None and len(w) < 2:
        raise XoscError(f"actor {a.name}: a trigger but one waypoint; a static actor has no trigger")
    if a.trigger is not None:
        _pose((*a.trigger, 0.0), f"actor {a.name} trigger")
        if _f(a.trigger_radius, f"actor {a.name} trigger_radius") < 0:
            raise XoscError(f"actor {a.name}: trigger_radius must be >= 0")


def _wpos(xosc, x: float, y: float, yaw: float):
    return xosc.WorldPosition(float(x), float(y), 0.0, float(yaw))


def _box(xosc, length: float, width: float, height: float):
    return xosc.BoundingBox(width, length, height, 0.0, 0.0, height / 2)


def _car(xosc, name: str, length: float, width: float, height: float):
    g = car_geometry()
    front = xosc.Axle(g.max_steer, 0.65, 1.6, g.rear_axle + g.wheelbase, 0.325)
    rear = xosc.Axle(0.0, 0.65, 1.6, g.rear_axle, 0.325)
    return xosc.Vehicle(name, xosc.VehicleCategory.car, _box(xosc, length, width, height), front, rear,
                        g.max_speed, g.max_accel, g.max_decel, mass=1500.0)


def _actor_entity(xosc, a: ActorSpec):
    hx, hy, hz = SHAPE_SIZE[a.shape]
    if a.kind == "pedestrian":
        return xosc.Pedestrian(a.name, 80.0, xosc.PedestrianCategory.pedestrian, _box(xosc, 2 * hx, 2 * hy, 2 * hz),
                               model=a.shape)
    if a.kind == "moving_car":
        return _car(xosc, a.name, 2 * hx, 2 * hy, 2 * hz)
    return xosc.MiscObject(a.name, 10.0, xosc.MiscObjectCategory.obstacle, _box(xosc, 2 * hx, 2 * hy, 2 * hz))


def _near(xosc, minor: int, position, radius: float):
    """The condition "the ego's reference point within ``radius`` of ``position``": a ReachPositionCondition
    up to OpenSCENARIO 1.1, its 1.2 replacement (a euclidean DistanceCondition between reference points) after."""
    if minor < 2:
        return xosc.ReachPositionCondition(position, radius)
    return xosc.DistanceCondition(radius, xosc.Rule.lessOrEqual, position, freespace=False,
                                  distance_type=xosc.RelativeDistanceType.euclidianDistance,
                                  coordinate_system=xosc.CoordinateSystem.entity)


def _logic_path(xosc_path: Path, xodr: Path) -> str:
    try:
        return Path(os.path.relpath(xodr.resolve(), xosc_path.resolve().parent)).as_posix()
    except ValueError:  # another drive (Windows)
        return xodr.resolve().as_posix()

def _checked_minor(osc_minor: int) -> int:
    minor = int(osc_minor)
    if minor not in (0, 1, 2):
        raise XoscError(f"OpenSCENARIO 1.{minor} is not written here; use 1.0, 1.1 or 1.2")
    return minor


def _with_garage_hash(meta: Mapping[str, Any] | None, pack_dir: Path) -> dict[str, Any]:
    """A copy of ``meta``; without a ``garage_hash``, the one of the pack's manifest (when it can be read)."""
    meta = dict(meta or {})
    if "garage_hash" not in meta:
        try:
            meta["garage_hash"] = json.loads((pack_dir / MANIFEST).read_text())["garage_hash"]
        except (OSError, ValueError, KeyError, TypeError):
            pass
    return meta


def travel_headings(pts: np.ndarray) -> np.ndarray:
    """(N,) direction of travel at each of (N, 2) points: towards the next one (the last: as the one before)."""
    d = np.diff(pts[:, :2], axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    return np.append(heading, heading[-1])


def _route_points(route: Any) -> np.ndarray:
    """The route as (N, 3) finite rows (x, y, vertex heading), N >= 2: given (N, 3) rows keep their yaw, (N, 2)
    points get the travel direction (:func:`travel_headings`)."""
    pts = np.asarray(route, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3) or len(pts) < 2 or not np.isfinite(pts).all():
        raise XoscError(f"route must be (N, 2) points or (N, 3) poses, finite, with N >= 2, got shape {pts.shape}")
    if pts.shape[1] == 3:
        return pts
    return np.column_stack([pts, travel_headings(pts)])


def _checked_actors(actors: Sequence[ActorSpec]) -> list[ActorSpec]:
    actors = list(actors)
    names = [a.name for a in actors]
    for a in actors:
        _check_actor(a)
    if len(set(names)) != len(names):
        raise XoscError(f"actor names must be unique, got {names}")
    return actors


def _parameters(xosc, minor: int, target: int, occupied: list[int], actors: list[ActorSpec],
                meta: Mapping[str, Any]):
    """The ``gmj_`` parameter declarations: the test's stalls, its actors, then every meta entry."""
    params = xosc.ParameterDeclarations()
    plist = [("gmj_format", "integer", str(FORMAT)), ("gmj_target_stall", "integer", str(target)),
             ("gmj_occupied", "string", ",".join(map(str, occupied))),
             ("gmj_actors", "string", ",".join(a.name for a in actors))]
    for a in actors:
        plist += [(f"gmj_actor_{a.name}_kind", "string", a.kind),
                  (f"gmj_actor_{a.name}_behaviour", "string", a.behaviour),
                  (f"gmj_actor_{a.name}_stall", "integer", str(int(a.stall)))]
    plist += _meta_params(meta)
    for name, typ, value in plist:
        if typ == "integer" and minor >= 2:
            typ = "int"  # renamed in OpenSCENARIO 1.2
        params.add_parameter(xosc.Parameter(name, getattr(xosc.ParameterType, typ), value))
    return params


def _add_ego(xosc, entities, init, start: tuple[float, float, float], pts: np.ndarray) -> None:
    """The ego: its entity, its start pose and its planned route (a Polyline without timing; ``pts`` rows
    (x, y, vertex heading))."""
    entities.add_scenario_object(EGO, _car(xosc, EGO, *EGO_SIZE))
    init.add_init_action(EGO, xosc.TeleportAction(_wpos(xosc, *start)))
    ego_traj = xosc.Trajectory("ego_route", False)
    ego_traj.add_shape(xosc.Polyline([], [_wpos(xosc, x, y, h) for x, y, h in pts]))
    init.add_init_action(EGO, xosc.FollowTrajectoryAction(ego_traj, xosc.FollowingMode.position))


def _add_parked(xosc, entities, init, occupied: list[int], parked: dict[int, tuple[float, ...]]) -> None:
    """A parked car entity, at its pose (and with its size, where given), in every occupied stall."""
    for s in occupied:
        name = f"{PARKED_PREFIX}{s}"
        hx, hy, hz = SHAPE_SIZE["car"]
        length, width, height = parked[s][3:] or (2 * hx, 2 * hy, 2 * hz)
        entities.add_scenario_object(name, _car(xosc, name, length, width, height))
        init.add_init_action(name, xosc.TeleportAction(_wpos(xosc, *parked[s][:3])))


def _actor_group(xosc, minor: int, a: ActorSpec, w: np.ndarray):
    """A moving actor's ManeuverGroup: one Event following its timed trajectory, started near the trigger."""
    traj = xosc.Trajectory(f"{a.name}_trajectory", False)
    traj.add_shape(xosc.Polyline([float(t) for t in w[:, 0]], [_wpos(xosc, *row[1:]) for row in w]))
    follow = xosc.FollowTrajectoryAction(traj, xosc.FollowingMode.position, xosc.ReferenceContext.relative,
                                         1.0, 0.0)
    trig = xosc.EntityTrigger(
        f"{a.name}_trigger", 0, xosc.ConditionEdge.rising,
        _near(xosc, minor, _wpos(xosc, float(a.trigger[0]), float(a.trigger[1]), 0.0), float(a.trigger_radius)),
        EGO)
    event = xosc.Event(f"{a.name}_event", xosc.Priority.parallel)  # the only event of its maneuver
    event.add_action(f"{a.name}_follow", follow)
    event.add_trigger(trig)
    man = xosc.Maneuver(f"{a.name}_maneuver")
    man.add_event(event)
    group = xosc.ManeuverGroup(f"{a.name}_group")
    group.add_actor(a.name)
    group.add_maneuver(man)
    return group


def _add_actors(xosc, minor: int, entities, init, actors: list[ActorSpec]):
    """Every actor's entity and first pose; the Act holding the moving ones' maneuver groups."""
    act = xosc.Act("gmj_actors", xosc.ValueTrigger(
        "gmj_start", 0, xosc.ConditionEdge.none,
        xosc.SimulationTimeCondition(0, xosc.Rule.greaterOrEqual if minor >= 2 else xosc.Rule.greaterThan)))
    for a in actors:
        w = np.asarray(a.waypoints, dtype=float)
        entities.add_scenario_object(a.name, _actor_entity(xosc, a))
        init.add_init_action(a.name, xosc.TeleportAction(_wpos(xosc, *w[0, 1:])))
        if a.trigger is not None:
            act.add_maneuver_group(_actor_group(xosc, minor, a, w))
    return act


def _storyboard(xosc, minor: int, init, act, goal: tuple[float, float, float]):
    """Init, the actors' story (when one moves) and the stop trigger: the ego near the goal."""
    stop = xosc.EntityTrigger("gmj_goal", 0, xosc.ConditionEdge.rising,
                              _near(xosc, minor, _wpos(xosc, *goal), GOAL_TOLERANCE), EGO, triggeringpoint="stop")
    board = xosc.StoryBoard(init, stop)
    if act.maneuvergroup:
        story = xosc.Story("gmj_test", xosc.ParameterDeclarations())
        story.add_act(act)
        board.add_story(story)
    return board


def write_xosc(
    path: str | Path,
    *,
    pack_dir: str | Path,
    xodr_path: str | Path | None = None,
    target_stall: int,
    occupied: Iterable[int],
    start: Sequence[float],
    route: Any,
    goal: Sequence[float],
    actors: Sequence[ActorSpec] = (),
    parked_poses: Any = None,
    meta: Mapping[str, Any] | None = None,
    osc_minor: int = OSC_MINOR,
) -> Path:
    """Write one cruise test as OpenSCENARIO 1.``osc_minor`` (default 1.2) to ``path`` (atomically); returns it.

    ``xodr_path`` defaults to ``pack_dir/garage.xodr``. ``parked_poses``: stall -> (x, y, yaw) or a parked car's
    body (its pose and size), or the scene layout's ``parked_cars`` placements; a parked car is written for every stall of
    ``occupied``. ``route``: (N, 2) centre points (vertex heading: the travel direction) or (N, 3) poses
    (x, y, yaw: a park plan's, reverse stretches included). ``meta``: ``garage_hash`` (else read from the pack's manifest), ``seed``,
    ``driver``, ``action_type`` and any other scalar / JSON-able entries, all kept as ``gmj_``
    parameters.
    """
    from scenariogeneration import xosc

    minor = _checked_minor(osc_minor)
    path = Path(path)
    pack_dir = Path(pack_dir)
    xodr = Path(xodr_path) if xodr_path is not None else pack_dir / XODR
    meta = _with_garage_hash(meta, pack_dir)
    occ = sorted({int(s) for s in occupied})
    target = int(target_stall)
    if target in occ:
        raise XoscError(f"the target stall {target} is among the occupied stalls")
    start_p, goal_p = _pose(start, "start"), _pose(goal, "goal")
    pts = _route_points(route)
    parked = _parked_table(parked_poses)
    missing = [s for s in occ if s not in parked]
    if missing:
        raise XoscError(f"no parked-car pose for occupied stall(s) {missing}")
    actors = _checked_actors(actors)

    params = _parameters(xosc, minor, target, occ, actors, meta)
    entities, init = xosc.Entities(), xosc.Init()
    _add_ego(xosc, entities, init, start_p, pts)
    _add_parked(xosc, entities, init, occ, parked)
    act = _add_actors(xosc, minor, entities, init, actors)
    board = _storyboard(xosc, minor, init, act, goal_p)
    road = xosc.RoadNetwork(roadfile=_logic_path(path, xodr))
    title = f"garage-mj {meta.get('task', 'cruise')} test: stall {target}"
    sce = xosc.Scenario(title, "garage-mj", params, entities, board, road, xosc.Catalog(), osc_minor_version=minor)
    el = sce.get_element()
    ET.indent(el)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(path, ET.tostring(el, encoding="utf-8", xml_declaration=True))


__all__ = ["XoscError", "write_xosc", "travel_headings", "EGO", "PARKED_PREFIX"]
