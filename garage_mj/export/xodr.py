"""OpenDRIVE writer: ``garage.xodr`` (ASAM OpenDRIVE 1.8) from the road model, with lxml.

Everything geometric comes from :mod:`garage_mj.scene.opendrive_roads`; this module only spells
it in XML: header, roads (plan view, flat elevation and lateral profiles, one lane section
with lanes 1/0/-1), junctions with their connections and lane links, and one
``<object type="parkingSpace">`` per stall on the road it faces.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from garage_mj.core.fsutil import atomic_write
from garage_mj.grid.garage import Garage
from garage_mj.scene.garage_scene import GarageScene, as_scene
from garage_mj.scene.opendrive_roads import Link, ParkingSpace, Road, RoadModel
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

REV_MAJOR, REV_MINOR = 1, 8
VENDOR = "garage-mj"
MARK_WIDTH = 0.15  # [m] painted lines (matches WorldConfig.marking_width)


@dataclass(frozen=True)
class XodrResult:
    """What :func:`write_xodr` produced: the text, the model it spells, and where it went."""

    text: str
    model: RoadModel
    path: Path | None


def _num(v: float) -> str:
    """Compact, exact-enough decimal (1e-9 m) without '-0'."""
    r = round(v, 9)
    return repr(0.0 if r == 0 else r)


def _sub(parent: etree._Element, tag: str, **attrs: object) -> etree._Element:
    return etree.SubElement(
        parent, tag, {k: (_num(v) if isinstance(v, float) else str(v)) for k, v in attrs.items()}
    )


def _link(parent: etree._Element, tag: str, link: Link | None) -> None:
    if link is None:
        return
    if link.contact is None:
        _sub(parent, tag, elementType=link.element, elementId=link.id)
    else:
        _sub(parent, tag, elementType=link.element, elementId=link.id, contactPoint=link.contact)


def _lane(parent: etree._Element, road: Road, lane_id: int, world: WorldConfig) -> None:
    lane = _sub(parent, "lane", id=lane_id, type="driving", level="false")
    pred, succ = road.lane_predecessor.get(lane_id), road.lane_successor.get(lane_id)
    if pred is not None or succ is not None:
        link = _sub(lane, "link")
        if pred is not None:
            _sub(link, "predecessor", id=pred)
        if succ is not None:
            _sub(link, "successor", id=succ)
    _sub(lane, "width", sOffset=0.0, a=world.drive_lane_width, b=0.0, c=0.0, d=0.0)
    outer = "none" if road.kind == "connecting" else "solid"
    _sub(lane, "roadMark", sOffset=0.0, type=outer, weight="standard", color="white", width=MARK_WIDTH)


def road_name(model: RoadModel, road: Road) -> str:
    """``road_<id>``, ``implicit_<id>`` or ``connecting_<id>``; gate roads say ``entrance``/``exit``."""
    gates = [g for g, rid in (("entrance", model.entrance_road), ("exit", model.exit_road)) if rid == road.id]
    return "_".join([*gates, road.kind, str(road.id)])


def _road(root: etree._Element, model: RoadModel, road: Road, spaces: list[ParkingSpace]) -> None:
    world = model.world
    el = _sub(
        root, "road", name=road_name(model, road), length=road.length, id=road.id, junction=road.junction
    )
    el.set("rule", "RHT")
    if road.predecessor or road.successor:
        link = _sub(el, "link")
        _link(link, "predecessor", road.predecessor)
        _link(link, "successor", road.successor)
    _sub(_sub(el, "type", s=0.0, type="town"), "speed", max=10, unit="km/h")
    plan = _sub(el, "planView")
    for seg in road.segments:
        g = _sub(plan, "geometry", s=seg.s, x=seg.x, y=seg.y, hdg=seg.hdg, length=seg.length)
        if seg.curvature == 0.0:
            _sub(g, "line")
        else:
            _sub(g, "arc", curvature=seg.curvature)
    _sub(_sub(el, "elevationProfile"), "elevation", s=0.0, a=0.0, b=0.0, c=0.0, d=0.0)
    _sub(el, "lateralProfile")
    lanes = _sub(el, "lanes")
    section = _sub(lanes, "laneSection", s=0.0)
    if 1 in road.lanes:
        _lane(_sub(section, "left"), road, 1, world)
    center = _sub(_sub(section, "center"), "lane", id=0, type="none", level="false")
    mark = "none" if road.kind == "connecting" else "broken"
    _sub(center, "roadMark", sOffset=0.0, type=mark, weight="standard", color="white", width=MARK_WIDTH)
    _lane(_sub(section, "right"), road, -1, world)
    if spaces:
        objects = _sub(el, "objects")
        for p in spaces:
            obj = _sub(
                objects,
                "object",
                id=f"stall_{p.stall.id}",
                name=f"stall_{p.stall.id}" + ("_obstructed" if p.stall.obstructed else ""),
                type="parkingSpace",
                s=min(max(p.s, 0.0), road.length),
                t=p.t,
                zOffset=0.0,
                hdg=p.hdg,
                pitch=0.0,
                roll=0.0,
                orientation="none",
                length=p.stall.length,
                width=p.stall.width,
                height=0.0,
                validLength=0.0,
            )
            outline = _sub(_sub(obj, "outlines"), "outline", id=0, closed="true", fillType="paint")
            hl, hw = p.stall.length / 2, p.stall.width / 2
            for k, (su, sv) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
                _sub(outline, "cornerLocal", id=k, u=p.du + su * hl, v=p.dv + sv * hw, z=0.0, height=0.0)
            _sub(obj, "parkingSpace", access="all", restrictions="none")
            if not world.is_default_geometry:  # the stall's angle to its aisle [deg] (docs/spec.md section 9)
                _sub(obj, "userData", code="garage-mj:stallAngle", value=f"{p.stall.angle:g}")


def to_tree(model: RoadModel) -> etree._ElementTree:
    """The OpenDRIVE document of ``model`` as an lxml tree."""
    world = model.world
    root = etree.Element("OpenDRIVE")
    width, height = model.cols * world.block, model.rows * world.block
    header = _sub(
        root,
        "header",
        revMajor=REV_MAJOR,
        revMinor=REV_MINOR,
        name=model.name,
        version="1",
        north=float(height),
        south=0.0,
        east=float(width),
        west=0.0,
        vendor=VENDOR,
    )
    # Local metric frame: x east, y north, origin at the grid's south-west corner (docs/spec.md section 6).
    etree.SubElement(header, "geoReference").text = etree.CDATA("+proj=tmerc +lat_0=0 +lon_0=0 +units=m")
    by_road: dict[int, list[ParkingSpace]] = {}
    for p in model.parking:
        by_road.setdefault(p.road, []).append(p)
    for rid in sorted(model.roads):
        _road(root, model, model.roads[rid], by_road.get(rid, []))
    for jid in sorted(model.junctions):
        j = model.junctions[jid]
        el = _sub(root, "junction", id=j.id, name=f"junction_{j.cell[0]}_{j.cell[1]}", type="default")
        for c in j.connections:
            conn = _sub(
                el,
                "connection",
                id=c.id,
                incomingRoad=c.incoming,
                connectingRoad=c.connecting,
                contactPoint=c.contact,
            )
            for a, b in c.lane_links:
                _sub(conn, "laneLink", **{"from": a, "to": b})
    return etree.ElementTree(root)


def to_string(model: RoadModel) -> str:
    """The OpenDRIVE document of ``model`` as pretty-printed UTF-8 text."""
    return etree.tostring(to_tree(model), pretty_print=True, xml_declaration=True, encoding="UTF-8").decode()


def write_xodr(
    garage: Garage | GarageScene, path: str | Path | None = None, world: WorldConfig = DEFAULT_WORLD
) -> XodrResult:
    """Build ``garage``'s OpenDRIVE map; write it to ``path`` (atomically) when given."""
    model = as_scene(garage, world).road_model
    text = to_string(model)
    out = None
    if path is not None:
        out = atomic_write(path, text)
    return XodrResult(text, model, out)
