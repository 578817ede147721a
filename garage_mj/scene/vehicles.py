"""The vehicle classes of park tests (docs/spec.md section 9): the fleet table, real dimensions.

A :class:`VehicleClass` is what a planner, a monitor or an exporter needs to know of a car's body: its
outline (length, width, height), where its axles sit (wheelbase, front and rear overhangs) and how
sharply it steers. :data:`FLEET` holds the classes a park test draws from: the car under test is one of
them (``--vehicle``; ``sedan`` is the car of ``models/car``, section 6), and with a ``mixed`` fleet every
parked car is drawn from them per test. Dimensions are those of a common car of each class (a VW Golf, the
project's own car, a BMW X5, a Mercedes-Benz Vito), rounded to the centimetre.

:data:`TPCAP_VEHICLE` is the car of the TPCAP parking benchmark's cases, as that benchmark publishes it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from garage_mj.scene.car import CarConfig, CarGeometry, car_geometry


@dataclass(frozen=True)
class VehicleClass:
    """One class of car: outline, axles and steering (units in the comments; the car frame of
    :class:`~garage_mj.scene.car.CarGeometry`: origin at the outline's centre, x forward, y left)."""

    name: str
    length: float  # [m] bumper to bumper
    width: float  # [m] body, without mirrors
    height: float  # [m]
    wheelbase: float  # [m] front to rear axle
    front_overhang: float  # [m] front axle to front bumper
    max_steer: float  # [rad] road-wheel angle at full lock (bicycle model)

    def __post_init__(self) -> None:
        for name in ("length", "width", "height", "wheelbase", "front_overhang", "max_steer"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"vehicle {self.name!r}: {name} must be a positive number, got {getattr(self, name)}")
        if not self.rear_overhang > 0:
            raise ValueError(f"vehicle {self.name!r}: wheelbase + front overhang ({self.wheelbase + self.front_overhang:g} m) "
                             f"must be shorter than the length ({self.length:g} m)")
        if not self.max_steer < math.pi / 2:
            raise ValueError(f"vehicle {self.name!r}: max_steer must be below pi/2, got {self.max_steer}")

    @property
    def rear_overhang(self) -> float:
        """[m] rear axle to rear bumper."""
        return self.length - self.wheelbase - self.front_overhang

    @property
    def min_radius(self) -> float:
        """[m] smallest turning radius of the rear-axle midpoint (bicycle model)."""
        return self.wheelbase / math.tan(self.max_steer)

    def geometry(self, config: CarConfig | None = None) -> CarGeometry:
        """This class as the planners and monitors see a car: the :class:`CarGeometry` of the project's car
        (its speed and actuation limits, those of ``config``) with this class's outline, axles and steering."""
        base = car_geometry(config)
        half = self.length / 2
        return CarGeometry(wheelbase=self.wheelbase, rear_axle=round(-half + self.rear_overhang, 9), half_width=self.width / 2,
                           front=half, rear=-half, max_steer=self.max_steer, steer_rate=base.steer_rate,
                           max_speed=base.max_speed, max_accel=base.max_accel, max_decel=base.max_decel)

    def car_config(self, config: CarConfig | None = None) -> CarConfig:
        """``config`` (default: :class:`CarConfig`'s) with this class's full lock: what drives this class in MuJoCo.

        A ``config`` that sets another full lock than the class's is refused: the class is the one source of
        it (give a :class:`VehicleClass` of its own for another one)."""
        cfg = config or CarConfig()
        if cfg.max_steer not in (CarConfig.max_steer, self.max_steer):
            raise ValueError(f"vehicle {self.name!r} steers to {self.max_steer:g} rad at full lock, and the car config "
                             f"asks for {cfg.max_steer:g}; leave car max_steer out (or use a vehicle class with it)")
        return dataclasses.replace(cfg, max_steer=self.max_steer)


#: The fleet table: the classes a park test's cars are drawn from, smallest first.
FLEET: dict[str, VehicleClass] = {
    v.name: v
    for v in (
        VehicleClass("compact", length=4.28, width=1.79, height=1.45, wheelbase=2.63, front_overhang=0.87,
                     max_steer=0.72),
        # the project's own car (models/car): 4.6 x 1.9 m, wheelbase 2.7 m, centred axles, 0.7 rad at full lock
        VehicleClass("sedan", length=4.6, width=1.9, height=1.5, wheelbase=2.7, front_overhang=0.95, max_steer=0.7),
        VehicleClass("suv", length=4.92, width=2.0, height=1.75, wheelbase=2.97, front_overhang=0.95, max_steer=0.6),
        VehicleClass("van", length=5.14, width=1.93, height=1.9, wheelbase=3.2, front_overhang=0.93, max_steer=0.56),
    )
}
#: The car under test unless a run names another (the car of ``models/car``).
DEFAULT_VEHICLE = "sedan"

#: The car of the TPCAP benchmark's cases (its published vehicle: wheelbase 2.8 m, overhangs 0.96 m front and
#: 0.929 m rear, width 1.942 m). TPCAP publishes no steering limit: its benchmark repository, its MATLAB and Python
#: demos and its site give the body alone (the competition's tracking controller, which held one, was never
#: published). 0.75 rad (a 3.02 m turning radius of the rear axle) is this project's choice, and no height is
#: published either. Planners published for this body use other limits (its author's LIOM demo, 0.5 rad; another
#: public planner, 0.7), so a result on TPCAP's cases names the limit it was planned with.
TPCAP_VEHICLE = VehicleClass("tpcap", length=0.96 + 2.8 + 0.929, width=1.942, height=1.5, wheelbase=2.8,
                             front_overhang=0.96, max_steer=0.75)


def vehicle_class(name: str | VehicleClass) -> VehicleClass:
    """The fleet's class ``name`` (one line naming the choices when there is none); a :class:`VehicleClass` as it is."""
    if isinstance(name, VehicleClass):
        return name
    try:
        return FLEET[name]
    except KeyError:
        raise ValueError(f"vehicle {name!r} is not in the fleet; choose one of {', '.join(FLEET)}") from None
