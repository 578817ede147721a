"""GarageScene: the 3D world of one garage, derived once and shared by every consumer.

The road network matrix, the stall layout, the road model (what OpenDRIVE spells), the lane
graph, the scene layout (boxes and placements) and the drivable routes of the ego car are all
computed lazily, at most once per garage, from one another: the exporters and the drive env
take them from here instead of deriving their own copies.
"""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING

from garage_mj.grid.garage import Garage
from garage_mj.scene.world import DEFAULT_WORLD, WorldConfig

if TYPE_CHECKING:
    import networkx as nx
    from dm_control import mjcf

    from garage_mj.scene.car import CarGeometry
    from garage_mj.scene.drivable import DriveConfig, DrivePlanner
    from garage_mj.scene.layout import SceneLayout
    from garage_mj.scene.roadmodel import RoadModel
    from garage_mj.scene.roadnet import RoadNetwork
    from garage_mj.scene.stalls import StallLayout


class GarageScene:
    """Everything 3D about ``garage`` in ``world``, each part built on first use."""

    def __init__(self, garage: Garage, world: WorldConfig = DEFAULT_WORLD) -> None:
        self.garage = garage
        self.world = world
        self._planners: dict[object, DrivePlanner] = {}

    @property
    def name(self) -> str:
        return self.garage.name

    @cached_property
    def network(self) -> RoadNetwork:
        """The road network matrix (:mod:`garage_mj.scene.roadnet`)."""
        from garage_mj.scene.roadnet import road_network

        return road_network(self.garage, self.world)

    @cached_property
    def stalls(self) -> StallLayout:
        """Stalls and obstruction pillars (:mod:`garage_mj.scene.stalls`)."""
        from garage_mj.scene.stalls import stall_layout

        return stall_layout(self.garage, self.world)

    @cached_property
    def road_model(self) -> RoadModel:
        """Roads, junctions and parking spaces as OpenDRIVE sees them."""
        from garage_mj.scene.roadmodel import build_road_model

        return build_road_model(self.garage, self.world, network=self.network, stalls=self.stalls)

    @cached_property
    def lane_graph(self) -> nx.DiGraph:
        """Right-hand lane waypoints of the road model (:mod:`garage_mj.scene.lanes`)."""
        from garage_mj.scene.lanes import lane_graph

        return lane_graph(self.garage, self.world, model=self.road_model)

    @cached_property
    def layout(self) -> SceneLayout:
        """Named, classified boxes and model placements (no ceiling)."""
        from garage_mj.scene.layout import build_layout

        return build_layout(self.garage, self.world, network=self.network, stalls=self.stalls)

    @cached_property
    def entrance_pose(self) -> tuple[float, float, float]:
        """(x, y, yaw) at the start of the entrance lane, heading inward."""
        from garage_mj.scene.lanes import entrance_pose

        return entrance_pose(self.road_model)

    def mjcf(self, parked=None) -> mjcf.RootElement:
        """The MuJoCo scene (:func:`garage_mj.scene.mjcf_scene.build_scene`) from this layout."""
        from garage_mj.scene.mjcf_scene import build_scene

        return build_scene(self.garage, world=self.world, parked=parked, layout=self.layout)

    def planner(self, car: CarGeometry | None = None, config: DriveConfig | None = None) -> DrivePlanner:
        """The ego car's route planner and drivability checks for ``car`` (default ``models/car``)."""
        from garage_mj.scene.car import car_geometry
        from garage_mj.scene.drivable import DEFAULT_DRIVE, DrivePlanner

        key = (car or car_geometry(), config or DEFAULT_DRIVE)
        if key not in self._planners:
            self._planners[key] = DrivePlanner(self, *key)
        return self._planners[key]


def as_scene(garage: Garage | GarageScene, world: WorldConfig = DEFAULT_WORLD) -> GarageScene:
    """``garage`` as a :class:`GarageScene` (itself when it is one; ``world`` applies to a bare garage)."""
    return garage if isinstance(garage, GarageScene) else GarageScene(garage, world)
