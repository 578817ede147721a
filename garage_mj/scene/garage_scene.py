"""GarageScene: the 3D world of one garage, derived once and shared by every consumer.

The road network matrix, the stall layout, the road model (what OpenDRIVE spells), the lane
graph and the scene layout (boxes and placements) are all computed lazily, at most once per
garage, from one another: the exporters and the drive env take them from here instead of
deriving their own copies. What is built on top of a scene lives with its builder and takes
the scene as its argument: the MuJoCo scene (:func:`garage_mj.scene.mjcf_scene.build_scene`)
and the ego car's route planner (:func:`garage_mj.scene.drivable.drive_planner`, cached per
car and margins in :attr:`GarageScene._planners`).
"""

from __future__ import annotations

from functools import cached_property
from typing import Any

import networkx as nx

from garage_mj.grid.garage import Garage
from garage_mj.scene.layout import SceneLayout, build_layout
from garage_mj.scene.opendrive_lanes import entrance_pose as lane_entrance_pose
from garage_mj.scene.opendrive_lanes import lane_graph as build_lane_graph
from garage_mj.scene.opendrive_roads import RoadModel, build_road_model
from garage_mj.scene.road_matrix import RoadNetwork, road_network
from garage_mj.scene.stalls import StallLayout, stall_layout
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig


class GarageScene:
    """Everything 3D about ``garage`` in ``world``, each part built on first use."""

    def __init__(self, garage: Garage, world: WorldConfig = DEFAULT_WORLD) -> None:
        self.garage = garage
        self.world = world
        #: (car geometry, drive config) -> DrivePlanner, filled by :func:`garage_mj.scene.drivable.drive_planner`.
        self._planners: dict[tuple[Any, Any], Any] = {}

    @property
    def name(self) -> str:
        return self.garage.name

    @cached_property
    def network(self) -> RoadNetwork:
        """The road network matrix (:mod:`garage_mj.scene.road_matrix`)."""
        return road_network(self.garage, self.world)

    @cached_property
    def stalls(self) -> StallLayout:
        """Stalls and obstruction pillars (:mod:`garage_mj.scene.stalls`)."""
        return stall_layout(self.garage, self.world)

    @cached_property
    def road_model(self) -> RoadModel:
        """Roads, junctions and parking spaces as OpenDRIVE sees them."""
        return build_road_model(self.garage, self.world, network=self.network, stalls=self.stalls)

    @cached_property
    def lane_graph(self) -> nx.DiGraph:
        """Right-hand lane waypoints of the road model (:mod:`garage_mj.scene.opendrive_lanes`)."""
        return build_lane_graph(self.garage, self.world, model=self.road_model)

    @cached_property
    def layout(self) -> SceneLayout:
        """Named, classified boxes and model placements (no ceiling)."""
        return build_layout(self.garage, self.world, network=self.network, stalls=self.stalls)

    @cached_property
    def entrance_pose(self) -> tuple[float, float, float]:
        """(x, y, yaw) at the start of the entrance lane, heading inward."""
        return lane_entrance_pose(self.road_model)


def as_scene(garage: Garage | GarageScene, world: WorldConfig = DEFAULT_WORLD) -> GarageScene:
    """``garage`` as a :class:`GarageScene` (itself when it is one; ``world`` applies to a bare garage)."""
    return garage if isinstance(garage, GarageScene) else GarageScene(garage, world)
