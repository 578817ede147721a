"""The scene: the 3D world derived from a garage, computed once per garage as a :class:`GarageScene`.

The writers in :mod:`garage_mj.export` and the drive env read this package; it imports neither.
Public names load lazily (``from garage_mj.scene import GarageScene``).

- ``world``: the world frame (x east, y north, metres) and the sizes of blocks, lanes, stalls, pillars.
- ``garage_scene``: :class:`GarageScene`, every part below built on first use, at most once per garage.
- ``road_matrix``: the road network matrix: per road cell its tile type, rotation and world position.
- ``stalls``: where every stall (and obstruction pillar) lies in the world.
- ``opendrive_roads``: roads, junctions and parking spaces as OpenDRIVE spells them, before any XML.
- ``planview``: plan-view geometry (lines, arcs, poses along them) shared by the road model and lanes.
- ``opendrive_lanes``: the lane graph (right-hand lane waypoints of the road model), routes on it, gate poses.
- ``route_line``: a route as a 2D polyline: length, projection of the car, lookahead points.
- ``cruise_routes``: the ego car's forward routes on the road network matrix, filleted into turns it can steer.
- ``clearance``: obstacles as rectangles, the car's footprint and its swept clearance along a path.
- ``drivable``: the planned test to each stall (goal, route, checks) and a garage's drivability.
- ``park_planning``: park tests: the stall pose, the success geometry, and the reference Reeds-Shepp planner
  (OMPL) that decides a park test's feasibility and gives the path a reference driver tracks.
- ``body_outlines``: solid bodies as floor outlines of any orientation, the footprint's clearance to them, and
  what a straight segment crosses (what section 9 judges a park test against).
- ``park_levels``: a park test's level (normal, complex, extreme), after the HOPE parking planner's rules.
- ``route_features``: what a test asks of a driver, from its planned route (turns, curvature, clearance, ...).
- ``route_difficulty``: the route-aware difficulty, a monotone logistic model of failure on route features.
- ``park_difficulty``: the park difficulty, the same monotone logistic model on a park test's features known before
  its drive (bay margin, aisle, plan, start distance, stall angle, maneuver, actors, jitter), in a format of its own.
- ``park_rating``: a garage's park difficulty without a drive: the mean over a few seeded target stalls' park tests
  (their reference plans and geometry), what ``generate --metric park`` rates garages by.
- ``car``: the ego car's model file and geometry (outline, axles, steering limit, camera poses).
- ``vehicles``: the fleet table of vehicle classes (compact, sedan, SUV, van; TPCAP's car): outline, axles, steering.
- ``case_scene``: a park case from elsewhere (a problem file's obstacle polygons, start and goal): its convex pieces,
  stall, reference planner and MuJoCo scene.
- ``layout``: the garage as named, classified boxes and model placements (pure, no MuJoCo).
- ``templates``: the models of ``models/`` as stamps for scene builders.
- ``mjcf_scene``: the MuJoCo scene (``build_scene``) and parked-car occupancy and placement on a compiled model.
- ``parked_fleet``: a test's parked cars as real bodies: their classes (uniform or mixed fleet) and jittered poses.
- ``semantics``: the semantic classes and the geom naming rule that carries them.
- ``actor_spec``: what an actor of a cruise test is (kind, shape, size, trajectory, trigger).
- ``actor_bodies``: the actors' kinematic mocap bodies in the MuJoCo scene.

Four modules describe the roads, each for its own reader. ``garage_mj.grid.road_segments`` (grid
stage) is the road graph on the grid: road-like cells, their tile by degree, key nodes and the
segments between them, the counts the paper's metrics use; it knows no world coordinates.
``road_matrix`` is the road network matrix, one entry per road cell: its tile type (dead end,
straight, curve, T, cross, gate), the rotation of the tile's model and its world position;
every exporter reads road cells from it. ``opendrive_roads`` turns it (with ``stalls``) into roads,
junctions with connecting roads and parking spaces as OpenDRIVE spells them; the
``garage.xodr`` writer spells exactly this. ``opendrive_lanes`` samples the road model's right-hand
lanes into waypoints in driving direction, linked across junctions, for driving: routes between
two points as a car in CARLA would drive them (``opendrive_lanes.route``), the pose the ego car starts from and
the lane centre lines a test's goal must lie on. The ego car's planned route itself
(``cruise_routes``) follows the right-hand lane lines of ``road_matrix`` cells, filleted into turns the
car can steer.
"""

from __future__ import annotations

from garage_mj.core.lazy import lazy_exports

__getattr__, __all__ = lazy_exports(__name__, {
    "GarageScene": "garage_scene",
    "WorldConfig": "world",
    "DEFAULT_WORLD": "world",
    "road_network": "road_matrix",
    "stall_layout": "stalls",
    "build_road_model": "opendrive_roads",
    "RoadModel": "opendrive_roads",
    "lane_graph": "opendrive_lanes",
    "route": "opendrive_lanes",
    "entrance_pose": "opendrive_lanes",
    "exit_pose": "opendrive_lanes",
    "Route": "route_line",
    "build_layout": "layout",
    "build_scene": "mjcf_scene",
    "compile_scene": "mjcf_scene",
    "set_parked": "mjcf_scene",
    "ParkedCars": "mjcf_scene",
    "DrivePlanner": "drivable",
    "TestPlan": "drivable",
    "drive_planner": "drivable",
    "drivability": "drivable",
    "ParkPlanner": "park_planning",
    "ParkPlan": "park_planning",
    "ParkConfig": "park_planning",
    "park_pose": "park_planning",
    "in_stall": "park_planning",
    "Semantic": "semantics",
    "geom_classes": "semantics",
})
