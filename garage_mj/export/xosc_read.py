"""Reading back a cruise, park or AVP test written as OpenSCENARIO by :func:`garage_mj.export.xosc.write_xosc` (with lxml).

Where each field comes from is the table of :mod:`garage_mj.export.xosc`. Both forms of the
*near* condition are read: a ``ReachPositionCondition`` (OpenSCENARIO 1.0/1.1) and its 1.2
replacement, a euclidean ``DistanceCondition`` between reference points. A static actor (one
waypoint, no trigger) reads back with ``trigger_radius`` 0. :func:`read_xosc` rebuilds everything
from the file alone and raises :class:`~garage_mj.export.xosc.XoscError` (one line naming the file
and the problem) on anything malformed or inconsistent; :meth:`XoscTest.pack` loads the pack it
refers to. A park or AVP test's file also gives back its task, maneuver and reference park plan
(:meth:`XoscTest.park_plan`: poses and gears, the gear of each step from the vertex heading against the
direction to the next vertex).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from garage_mj.core.words import a_noun
from garage_mj.export.pack import load_pack
from garage_mj.export.xosc import EGO, FORMAT, PARKED_PREFIX, XoscError
from garage_mj.scene.actor_spec import BEHAVIOURS, KINDS, ActorSpec
from garage_mj.scene.park_planning import MANEUVERS

#: meta keys promoted to :class:`XoscTest` fields
KNOWN_META = ("garage_hash", "seed", "driver", "action_type")
PARK_TASKS = ("park", "avp")  # the tasks whose files carry a park plan (a cruise test's file names no task)
_ENTITY_TAG = {"pedestrian": "Pedestrian", "moving_car": "Vehicle", "clutter": "MiscObject"}
_SAFE_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False,
                               remove_comments=True)


@dataclass
class XoscTest:
    """One cruise test read from a ``.xosc`` (the table of :mod:`garage_mj.export.xosc` says where each field
    comes from)."""

    path: Path
    pack_dir: Path
    xodr_path: Path
    garage_hash: str | None
    target_stall: int
    occupied: list[int]
    start: tuple[float, float, float]  # x, y, yaw of the ego's centre
    goal: tuple[float, float, float]
    route: np.ndarray  # (N, 2) centre path [m]
    actors: list[ActorSpec]
    parked: dict[int, tuple[float, float, float]]  # stall -> pose of its parked car
    seed: int | None = None
    driver: str | None = None
    action_type: str | None = None
    meta: dict[str, Any] = field(default_factory=dict)  # every other gmj_ parameter
    route_heading: np.ndarray | None = None  # (N,) the route's vertex headings [rad]

    @property
    def task(self) -> str:
        """``cruise``, ``park`` or ``avp`` (``gmj_task``; a cruise test's file has none)."""
        return str(self.meta.get("task", "cruise"))

    def park_plan(self) -> dict[str, Any] | None:
        """A park or AVP test's reference park plan as the env's reset info gives it (``poses`` (N, 3), ``directions``
        (N,) +1 forward / -1 reverse, driving from pose i to i + 1, the last as the one before); None for a cruise
        test, or a test without a plan (``plan_start`` -1: infeasible or unproven)."""
        start = int(self.meta.get("plan_start", -1))
        if self.task == "cruise" or start < 0 or self.route_heading is None:
            return None
        poses = np.column_stack([self.route, self.route_heading])[start:]
        return {"poses": poses, "directions": step_directions(poses), "stall_pose": self.goal}

    def pack(self):
        """The verified pack (:func:`garage_mj.export.pack.load_pack`), checked against ``gmj_garage_hash``."""
        pack = load_pack(self.pack_dir)
        if self.garage_hash is not None and pack.manifest["garage_hash"] != self.garage_hash:
            raise XoscError(f"scenario file {self.path}: gmj_garage_hash {self.garage_hash[:12]} is not the garage of pack "
                            f"{self.pack_dir} ({pack.manifest['garage_hash'][:12]})")
        return pack


def step_directions(poses: np.ndarray) -> np.ndarray:
    """(N,) gear of each step of (N, 3) poses: +1 where the heading points towards the next pose, -1 where it
    points away (reverse); a step that does not move keeps the gear before it (the first: +1)."""
    d = np.diff(poses[:, :2], axis=0)
    along = d[:, 0] * np.cos(poses[:-1, 2]) + d[:, 1] * np.sin(poses[:-1, 2])
    out = np.ones(len(poses), dtype=np.int8)
    for i, a in enumerate(along):
        out[i] = out[i - 1] if abs(a) < 1e-9 and i > 0 else (1 if a >= -1e-9 else -1)
    out[-1] = out[-2] if len(out) > 1 else 1
    return out


class _Bad(Exception):
    """What is wrong, without the file name (added once by :func:`read_xosc`)."""


def _attr_f(el, name: str, where: str) -> float:
    v = el.get(name)
    if v is None:
        raise _Bad(f"{where} has no {name} attribute")
    try:
        x = float(v)
    except ValueError:
        raise _Bad(f"{where} {name}={v[:40]!r} is not a number") from None
    if not math.isfinite(x):
        raise _Bad(f"{where} {name}={v[:40]!r} is not finite")
    return x


def _world(el, where: str) -> tuple[float, float, float]:
    wp = el.find("Position/WorldPosition") if el.tag != "Position" else el.find("WorldPosition")
    if wp is None:
        raise _Bad(f"{where} has no Position/WorldPosition")
    h = wp.get("h")
    return _attr_f(wp, "x", where), _attr_f(wp, "y", where), 0.0 if h is None else _attr_f(wp, "h", where)


def _polyline(ft, where: str, timed: bool) -> np.ndarray:
    poly = ft.findall(".//Shape/Polyline")
    if len(poly) != 1:
        raise _Bad(f"{where} needs one Trajectory/Shape/Polyline, found {len(poly)}")
    rows = []
    for i, v in enumerate(poly[0].findall("Vertex")):
        x, y, h = _world(v, f"{where} vertex {i}")
        if timed:
            rows.append((_attr_f(v, "time", f"{where} vertex {i}"), x, y, h))
        else:
            rows.append((x, y, h))
    if len(rows) < 2:
        raise _Bad(f"{where}: its Polyline has {len(rows)} vertices (2 or more needed)")
    return np.asarray(rows, dtype=float)


def _reach(cond_parent, where: str) -> tuple[tuple[float, float, float], float, str]:
    """(position, radius, triggering entity) of the one "entity near a point" condition under ``cond_parent``:
    a ReachPositionCondition (tolerance) or a euclidean DistanceCondition between reference points
    (rule lessThan / lessOrEqual, value)."""
    conds = cond_parent.findall(".//EntityCondition/*")
    if len(conds) != 1 or conds[0].tag not in ("ReachPositionCondition", "DistanceCondition"):
        raise _Bad(f"{where} needs one ReachPositionCondition or DistanceCondition, found "
                   f"{[c.tag for c in conds] or 'none'}")
    c = conds[0]
    if c.tag == "ReachPositionCondition":
        tol = _attr_f(c, "tolerance", f"{where} ReachPositionCondition")
    else:
        if (c.get("freespace"), c.get("relativeDistanceType", "euclidianDistance")) != ("false", "euclidianDistance") \
                or c.get("rule") not in ("lessThan", "lessOrEqual"):
            raise _Bad(f"{where} DistanceCondition must be euclidean between reference points (freespace false, "
                       f"relativeDistanceType euclidianDistance, rule lessThan or lessOrEqual)")
        tol = _attr_f(c, "value", f"{where} DistanceCondition")
    if tol < 0:
        raise _Bad(f"{where} {c.tag}: distance {tol} is negative")
    refs = [e.get("entityRef") for e in cond_parent.findall(".//ByEntityCondition/TriggeringEntities/EntityRef")]
    return _world(c, f"{where} {c.tag}"), tol, refs[0] if len(refs) == 1 else ""


def _params(root) -> dict[str, tuple[str, str]]:
    out = {}
    for p in root.findall("ParameterDeclarations/ParameterDeclaration"):
        name = p.get("name")
        if name is None or p.get("value") is None:
            raise _Bad("a ParameterDeclaration lacks its name or value")
        if name.startswith("gmj_"):
            out[name] = (p.get("parameterType", "string"), p.get("value"))
    return out


def _typed(name: str, typ: str, value: str) -> Any:
    try:
        if typ in ("int", "integer", "unsignedInt", "unsignedShort"):
            return int(value)
        if typ == "double":
            return float(value)
        if typ == "boolean":
            if value not in ("true", "false"):
                raise ValueError(value)
            return value == "true"
        if name.startswith("gmj_json_"):
            return json.loads(value)
        return value
    except ValueError:
        raise _Bad(f"parameter {name}: {value[:40]!r} is not a valid {typ}") from None


def _int_list(name: str, text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",")] if text.strip() else []
    except ValueError:
        raise _Bad(f"parameter {name}: {text[:40]!r} is not a comma-separated list of stall ids") from None


class _Params:
    """The file's typed ``gmj_`` parameters; the reader takes each one it uses out of :attr:`left`."""

    def __init__(self, root) -> None:
        self.left = {name: _typed(name, typ, value) for name, (typ, value) in _params(root).items()}

    def need(self, name: str, kind: type) -> Any:
        """Take out the required parameter ``name``, an ``int`` or a ``str``."""
        if name not in self.left:
            raise _Bad(f"parameter {name} is missing; not a garage-mj cruise test")
        v = self.left.pop(name)
        if kind is int and (not isinstance(v, int) or isinstance(v, bool)):
            raise _Bad(f"parameter {name} must be an integer")
        if kind is str and not isinstance(v, str):
            raise _Bad(f"parameter {name} must be a string")
        return v

    def promoted(self) -> dict[str, Any]:
        """The optional fields of :class:`XoscTest` (:data:`KNOWN_META`) and ``meta``: every parameter left."""
        meta = self.left
        garage_hash = meta.pop("gmj_garage_hash", None)
        seed = meta.pop("gmj_seed", None)
        driver = meta.pop("gmj_driver", None)
        action_type = meta.pop("gmj_action_type", None)
        if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)):
            raise _Bad("parameter gmj_seed must be an integer")
        for n, v in (("gmj_garage_hash", garage_hash), ("gmj_driver", driver), ("gmj_action_type", action_type)):
            if v is not None and not isinstance(v, str):
                raise _Bad(f"parameter {n} must be a string")
        leftover = [n for n in meta if n.startswith("gmj_actor_")]
        if leftover:
            raise _Bad(f"parameters {leftover[:3]} name no actor of gmj_actors")
        rest = {(n[len("gmj_json_"):] if n.startswith("gmj_json_") else n[len("gmj_"):]): v for n, v in meta.items()}
        return {"garage_hash": garage_hash, "seed": seed, "driver": driver, "action_type": action_type, "meta": rest}


def _root(path: Path):
    """The ``OpenSCENARIO`` root element of a 1.x file."""
    try:
        root = etree.parse(str(path), _SAFE_PARSER).getroot()
    except etree.XMLSyntaxError as exc:
        raise _Bad(f"not well-formed XML ({exc.msg}, line {exc.lineno})") from None
    if root.tag != "OpenSCENARIO":
        raise _Bad(f"the root element is <{root.tag}>, not <OpenSCENARIO>")
    hdr = root.find("FileHeader")
    if hdr is None or hdr.get("revMajor") != "1":
        raise _Bad("no FileHeader of OpenSCENARIO 1.x")
    return root


def _road_network(root, path: Path) -> Path:
    """The OpenDRIVE file the scenario names (relative to the ``.xosc``); its folder is the pack."""
    lf = root.find("RoadNetwork/LogicFile")
    if lf is None or not lf.get("filepath"):
        raise _Bad("RoadNetwork/LogicFile@filepath is missing")
    fp = Path(lf.get("filepath"))
    xodr = (fp if fp.is_absolute() else path.resolve().parent / fp).resolve()
    if not xodr.is_file():
        raise _Bad(f"its road network {lf.get('filepath')} ({xodr}) does not exist")
    return xodr


def _entities(root) -> dict[str, str]:
    """Entity name -> its tag (Vehicle, Pedestrian or MiscObject); the ego must be a Vehicle."""
    ents: dict[str, str] = {}
    for so in root.findall("Entities/ScenarioObject"):
        name = so.get("name")
        kids = [c.tag for c in so if isinstance(c.tag, str)]
        tag = next((t for t in kids if t in ("Vehicle", "Pedestrian", "MiscObject")), None)
        if name is None or tag is None:
            raise _Bad(f"ScenarioObject {name!r} is not a Vehicle, Pedestrian or MiscObject")
        if name in ents:
            raise _Bad(f"entity {name!r} is declared twice")
        ents[name] = tag
    if ents.get(EGO) != "Vehicle":
        raise _Bad("no Vehicle entity named 'ego'")
    return ents


def _init(root, ents: dict[str, str]) -> tuple[dict[str, tuple[float, float, float]], np.ndarray]:
    """From ``Init``: every entity's start pose, and the ego's route (rows x, y, vertex heading)."""
    poses: dict[str, tuple[float, float, float]] = {}
    route = None
    for priv in root.findall("Storyboard/Init/Actions/Private"):
        ref = priv.get("entityRef")
        if ref not in ents:
            raise _Bad(f"Init acts on unknown entity {ref!r}")
        for tp in priv.findall("PrivateAction/TeleportAction"):
            poses[ref] = _world(tp, f"the TeleportAction of {ref}")
        for ft in priv.findall("PrivateAction/RoutingAction/FollowTrajectoryAction"):
            if ref != EGO:
                raise _Bad(f"Init gives {ref!r} a FollowTrajectoryAction; only the ego's route goes there")
            route = _polyline(ft, "the ego's route", timed=False)
    missing = [n for n in ents if n not in poses]
    if missing:
        raise _Bad(f"no Init TeleportAction for {missing[:5]}")
    if route is None:
        raise _Bad("the ego has no FollowTrajectoryAction (its route) in Init")
    return poses, route


def _check_park(meta: dict[str, Any], route_vertices: int) -> None:
    """A park or AVP test's task, maneuver and ``plan_start`` (the meta entries the writer sets for it)."""
    task = meta.get("task", "cruise")
    if task == "cruise" and "task" not in meta:
        return
    if task not in PARK_TASKS:
        raise _Bad(f"parameter gmj_task: {str(task)[:40]!r} is not a park or AVP test ({', '.join(PARK_TASKS)})")
    if meta.get("maneuver") not in MANEUVERS:
        raise _Bad(f"parameter gmj_maneuver: {str(meta.get('maneuver'))[:40]!r} is not one of {', '.join(MANEUVERS)}")
    start = meta.get("plan_start")
    if not isinstance(start, int) or isinstance(start, bool) or not -1 <= start < route_vertices - 1:
        raise _Bad(f"parameter gmj_plan_start: {start!r} is not a vertex of the ego's route where a plan of 2 or "
                   "more poses begins (-1: none)")


def _goal(root) -> tuple[float, float, float]:
    """The goal pose: the StopTrigger's condition on the ego."""
    stop = root.find("Storyboard/StopTrigger")
    if stop is None:
        raise _Bad("the Storyboard has no StopTrigger (the goal)")
    goal, _, who = _reach(stop, "the StopTrigger")
    if who != EGO:
        raise _Bad(f"the goal condition is on {who or 'no single entity'}, not on the ego")
    return goal


def _parked(ents: dict[str, str], poses: dict[str, tuple[float, float, float]],
            occupied: list[int]) -> dict[int, tuple[float, float, float]]:
    """Stall -> pose of its parked car, which must be the stalls of ``gmj_occupied``."""
    parked: dict[int, tuple[float, float, float]] = {}
    for name in ents:
        if name.startswith(PARKED_PREFIX):
            try:
                sid = int(name[len(PARKED_PREFIX):])
            except ValueError:
                raise _Bad(f"entity {name!r} does not name a stall id") from None
            parked[sid] = poses[name]
    if sorted(parked) != occupied:
        raise _Bad(f"gmj_occupied {occupied} does not match the parked cars {sorted(parked)}")
    return parked


def _actor_events(root, actor_names: list[str]) -> dict[str, Any]:
    """Actor -> the one Event of its ManeuverGroup (moving actors only)."""
    events: dict[str, Any] = {}
    for group in root.findall("Storyboard/Story/Act/ManeuverGroup"):
        refs = [e.get("entityRef") for e in group.findall("Actors/EntityRef")]
        if len(refs) != 1 or refs[0] not in actor_names:
            raise _Bad(f"ManeuverGroup {group.get('name')!r} does not move exactly one declared actor")
        evs = group.findall("Maneuver/Event")
        if len(evs) != 1 or refs[0] in events:
            raise _Bad(f"actor {refs[0]} needs exactly one Event")
        events[refs[0]] = evs[0]
    return events


def _check_all_known(ents: dict[str, str], actor_names: list[str]) -> None:
    known = {EGO, *(n for n in ents if n.startswith(PARKED_PREFIX))}
    extra = [n for n in ents if n not in known and n not in actor_names]
    if extra:
        raise _Bad(f"entities {extra[:5]} are neither the ego, parked cars nor listed in gmj_actors")


def _trajectory(name: str, ev, first: tuple[float, float, float]) -> np.ndarray:
    """A moving actor's (K, 4) waypoints (t, x, y, yaw) from its Event's timed trajectory."""
    fts = ev.findall("Action/PrivateAction/RoutingAction/FollowTrajectoryAction")
    if len(fts) != 1:
        raise _Bad(f"actor {name}: its Event needs one FollowTrajectoryAction")
    tr = fts[0].find("TimeReference/Timing")
    if tr is None or tr.get("domainAbsoluteRelative") != "relative" \
            or _attr_f(tr, "scale", f"actor {name} Timing") != 1.0 \
            or _attr_f(tr, "offset", f"actor {name} Timing") != 0.0:
        raise _Bad(f"actor {name}: its trajectory timing must be relative, scale 1, offset 0")
    w = _polyline(fts[0], f"actor {name}'s trajectory", timed=True)
    if (np.diff(w[:, 0]) < 0).any():
        raise _Bad(f"actor {name}: vertex times decrease")
    if not np.allclose(w[0, 1:], first, atol=1e-9):
        raise _Bad(f"actor {name}: its TeleportAction is not its first waypoint")
    return w


def _trigger(name: str, ev) -> tuple[tuple[float, float], float]:
    """A moving actor's trigger point and radius: its Event's StartTrigger, a condition on the ego."""
    st = ev.find("StartTrigger")
    if st is None:
        raise _Bad(f"actor {name}: its Event has no StartTrigger")
    (tx, ty, _), radius, who = _reach(st, f"actor {name}'s StartTrigger")
    if who != EGO:
        raise _Bad(f"actor {name}: its trigger watches {who or 'no single entity'}, not the ego")
    return (tx, ty), radius


def _actor(name: str, ents: dict[str, str], poses: dict[str, tuple[float, float, float]], events: dict[str, Any],
           params: _Params) -> ActorSpec:
    """One actor of ``gmj_actors``: its parameters, its entity and, when it moves, its Event."""
    if name not in ents:
        raise _Bad(f"actor {name!r} of gmj_actors has no entity")
    kind = params.need(f"gmj_actor_{name}_kind", str)
    behaviour = params.need(f"gmj_actor_{name}_behaviour", str)
    stall = params.need(f"gmj_actor_{name}_stall", int)
    if kind not in KINDS or behaviour not in BEHAVIOURS[kind]:
        raise _Bad(f"actor {name}: unknown kind/behaviour {kind!r}/{behaviour!r}")
    if ents[name] != _ENTITY_TAG[kind]:
        raise _Bad(f"actor {name} ({kind}) is {a_noun(ents[name])}, expected {a_noun(_ENTITY_TAG[kind])}")
    ev = events.get(name)
    if ev is None:
        return ActorSpec(name, kind, behaviour, np.array([[0.0, *poses[name]]]), None, 0.0, stall)
    w = _trajectory(name, ev, poses[name])
    trigger, radius = _trigger(name, ev)
    return ActorSpec(name, kind, behaviour, w, trigger, radius, stall)


def _read(path: Path) -> XoscTest:
    root = _root(path)
    params = _Params(root)
    fmt = params.need("gmj_format", int)
    if fmt != FORMAT:
        raise _Bad(f"gmj_format {fmt} is not the supported {FORMAT}")
    target = params.need("gmj_target_stall", int)
    occupied = _int_list("gmj_occupied", params.need("gmj_occupied", str))
    actor_names = [n for n in params.need("gmj_actors", str).split(",") if n]
    xodr = _road_network(root, path)
    ents = _entities(root)
    poses, route = _init(root, ents)
    goal = _goal(root)
    parked = _parked(ents, poses, occupied)
    events = _actor_events(root, actor_names)
    _check_all_known(ents, actor_names)
    actors = [_actor(name, ents, poses, events, params) for name in actor_names]
    promoted = params.promoted()
    _check_park(promoted["meta"], len(route))
    return XoscTest(path=path, pack_dir=xodr.parent, xodr_path=xodr, target_stall=target, occupied=occupied,
                    start=poses[EGO], goal=goal, route=route[:, :2], actors=actors, parked=parked,
                    route_heading=route[:, 2], **promoted)


def read_xosc(path: str | Path) -> XoscTest:
    """The cruise, park or AVP test of a ``.xosc`` written by :func:`~garage_mj.export.xosc.write_xosc`; :class:`XoscError` if it is
    not one."""
    path = Path(path)
    try:
        if not path.is_file():
            raise _Bad("no such file")
        return _read(path)
    except _Bad as exc:
        msg = " ".join(str(exc).split())
        raise XoscError(f"scenario file {path}: {msg}") from None
    except (ValueError, TypeError, KeyError, IndexError, AttributeError) as exc:  # a structure not foreseen above
        msg = " ".join(str(exc).split())[:200]
        raise XoscError(f"scenario file {path}: not a garage-mj cruise test ({type(exc).__name__}: {msg})") from None
    except OSError as exc:
        raise XoscError(f"scenario file {path}: cannot read it ({exc.strerror or exc})") from None


__all__ = ["PARK_TASKS", "XoscTest", "read_xosc", "step_directions"]
