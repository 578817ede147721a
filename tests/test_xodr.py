"""garage.xodr: CARLA parses it and routes entrance -> exit, the ASAM checker finds zero issues.

The real tools run once per session on one batch of files (their start-up dominates); if
either tool is missing the tests fail with the install hint (``make install``), never skip.
"""

from __future__ import annotations

import math
from collections import Counter

import networkx as nx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from garage_mj import evaluate
from garage_mj.export.validate import (
    ToolFailed,
    ToolMissing,
    check_asam_batch,
    check_carla_batch,
    qc_executable,
)
from garage_mj.export.xodr import write_xodr
from garage_mj.grid.painters import paint_garage
from garage_mj.grid.road_segments import analyse
from garage_mj.scene.opendrive_lanes import lane_graph_of
from garage_mj.scene.opendrive_roads import IMPLICIT_ROAD, build_road_model
from garage_mj.scene.stalls import stall_layout

BROKEN = "broken_shifted_connecting_road"


@pytest.fixture(scope="session")
def corpus(painted_tiny, painted_maps, junction_garage, tmp_path_factory):
    """name -> XodrResult for the test corpus: tiny garages, one painted garage per shipped map."""
    out = tmp_path_factory.mktemp("xodr")
    garages = {"painted_tiny": painted_tiny, "junctions_7x11": junction_garage}
    garages |= {f"tiny_seed_{s}": paint_garage("tiny_7x11", seed=s) for s in (4, 11)}
    garages |= painted_maps
    return {name: write_xodr(g, out / f"{name}.xodr") for name, g in garages.items()}


@pytest.fixture(scope="session")
def broken_file(corpus, tmp_path_factory):
    """The junction garage with one connecting road moved 1 m: the checker must notice."""
    root = etree.fromstring(corpus["junctions_7x11"].text.encode())
    geo = root.xpath("road[@junction!='-1']/planView/geometry")[0]
    geo.set("x", str(float(geo.get("x")) + 1.0))
    path = tmp_path_factory.mktemp("broken") / f"{BROKEN}.xodr"
    path.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return path


@pytest.fixture(scope="session")
def asam_reports(corpus, broken_file):
    paths = [r.path for r in corpus.values()] + [broken_file]
    return {p.stem: rep for p, rep in zip(paths, check_asam_batch(paths))}


@pytest.fixture(scope="session")
def carla_reports(corpus):
    reps = check_carla_batch([r.text for r in corpus.values()], list(corpus))
    return dict(zip(corpus, reps))


def test_asam_checker_finds_zero_issues(corpus, asam_reports):
    for name in corpus:
        rep = asam_reports[name]
        assert rep.completed >= 20 and rep.errored == 0, name
        assert rep.issues == [], f"{name}: {rep.issues[:5]}"


def test_asam_checker_catches_a_gap(asam_reports):
    issues = asam_reports[BROKEN].issues
    assert issues and any("gap" in i.description for i in issues)


def test_carla_parses_and_routes(corpus, carla_reports):
    for name, r in corpus.items():
        rep = carla_reports[name]
        assert rep.roads == tuple(sorted(r.model.roads)), name
        assert rep.roads_without_waypoints == [], f"{name}: roads without waypoints"
        assert rep.entrance_reaches_exit, f"{name}: CARLA's lanes do not lead from the entrance to the exit"
        assert rep.topology_edges > 0


def test_carla_crash_is_reported(corpus, monkeypatch, tmp_path):
    import garage_mj.export.validate as v

    crash = tmp_path / "crash.py"
    crash.write_text("import os\nos.abort()\n")  # what a segfaulting parser looks like from outside
    monkeypatch.setattr(v, "_PROBE", crash)
    with pytest.raises(ToolFailed, match="crashed"):
        check_carla_batch([corpus["painted_tiny"].text])


def test_missing_checker_names_the_fix(monkeypatch, tmp_path):
    import garage_mj.export.validate as v

    monkeypatch.setattr(v, "_REPO", tmp_path)
    monkeypatch.delenv(v.QC_ENV, raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ToolMissing, match="make install"):
        qc_executable()
    monkeypatch.setattr(v, "find_spec", lambda name: None)
    with pytest.raises(ToolMissing, match="make install"):
        v.check_carla("<OpenDRIVE/>")


def test_header_parking_spaces_and_lanes(corpus, junction_garage):
    r = corpus["junctions_7x11"]
    root = etree.fromstring(r.text.encode())
    h = root.find("header")
    assert (h.get("revMajor"), h.get("revMinor")) == ("1", "8")
    spaces = root.findall(".//object[@type='parkingSpace']")
    assert len(spaces) == evaluate(junction_garage).stalls == len(stall_layout(junction_garage).stalls)
    assert {float(o.get("length")) for o in spaces} == {4.5} and {float(o.get("width")) for o in spaces} == {
        2.5
    }
    for road in root.iter("road"):
        lanes = [int(la.get("id")) for la in road.iter("lane")]
        assert lanes == ([0, -1] if road.get("junction") != "-1" else [1, 0, -1])
        assert {float(w.get("a")) for w in road.iter("width")} == {3.5}


def test_parking_spaces_sit_on_their_stalls(corpus):
    for r in corpus.values():
        m = r.model
        for p in m.parking:
            road = m.roads[p.road]
            x, y, h = road.pose(p.s)
            ox, oy = x - p.t * math.sin(h), y + p.t * math.cos(h)
            yaw = p.stall.yaw
            cx = ox + p.du * math.cos(yaw) - p.dv * math.sin(yaw)
            cy = oy + p.du * math.sin(yaw) + p.dv * math.cos(yaw)
            assert abs(p.dv) < 1e-9 and abs(p.du) <= m.world.stall_length / 2  # only dead ends' far ends
            assert math.hypot(cx - p.stall.x, cy - p.stall.y) < 1e-6
            assert 0 <= p.s <= road.length + 1e-9
            assert abs(math.remainder(p.hdg + h - p.stall.yaw, 2 * math.pi)) < 1e-9


def test_adjacent_junctions_get_an_implicit_road(junction_garage):
    m = build_road_model(junction_garage)
    implicit = [r for r in m.roads.values() if r.kind == "implicit"]
    assert len(implicit) == 1 and implicit[0].length == pytest.approx(IMPLICIT_ROAD)
    a, b = implicit[0].predecessor, implicit[0].successor
    assert a.element == b.element == "junction" and a.id != b.id
    cells = {m.junctions[a.id].cell, m.junctions[b.id].cell}
    assert cells == {(3, 2), (3, 3)}
    assert Counter(len(j.connections) for j in m.junctions.values()) == Counter({6: 2, 12: 1})


def _model_edges(m) -> set[frozenset]:
    """Cell adjacency spelled by the road model: along roads, and roads into junctions."""
    jcell = {j.id: j.cell for j in m.junctions.values()}
    edges = set()
    for road in m.roads.values():
        if road.kind == "connecting":
            continue
        cells = list(road.spans)
        edges |= {frozenset(p) for p in zip(cells, cells[1:])}
        ends = [(road.predecessor, cells[:1]), (road.successor, cells[-1:])]
        if road.kind == "implicit":
            edges.add(frozenset((jcell[road.predecessor.id], jcell[road.successor.id])))
            continue
        for link, cell in ends:
            if link is not None and link.element == "junction":
                edges.add(frozenset((jcell[link.id], cell[0])))
            elif link is not None and link.element == "road":
                edges.add(frozenset((cells[0], cells[-1])))
    return edges


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), map_name=st.sampled_from(["tiny_7x11", "m5_13x13_aligned", "m6_13x13_s"]))
def test_road_model_round_trip(seed, map_name):
    """Road network matrix -> tiles -> roads/junctions: the connectivity equals the grid's road graph."""
    g = paint_garage(map_name, seed=seed)
    m = build_road_model(g)
    a = analyse(g.grid)
    assert _model_edges(m) == a.edges()
    covered = Counter(c for r in m.roads.values() for c in r.spans)
    covered.update(j.cell for j in m.junctions.values())
    assert set(covered) == set(a.masks) and set(covered.values()) == {1}
    for j in m.junctions.values():
        arms = bin(a.masks[j.cell]).count("1")
        assert len(j.connections) == arms * (arms - 1)
    assert len(m.parking) == evaluate(g).stalls
    assert nx.is_strongly_connected(lane_graph_of(m))  # every lane reaches every other
