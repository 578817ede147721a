"""Driving: the testbed where a driver takes the car from the entrance to a stall.

- ``sim``: the simulated car and its test, ``GarageDrive-v0``.
  - ``sim.vehicle``: the car in MuJoCo (actuation, discrete and continuous actions).
  - ``sim.sensors``: the front camera (depth + segmentation, offscreen).
  - ``sim.observations``: the observation table (``OBSERVATIONS``): each key's space, privilege, meaning and fill.
  - ``sim.outcomes``: how a test ends and why; every outcome kind declared once, in ``OUTCOMES``.
  - ``sim.drive_env``: ``GarageDrive-v0``, one garage, one test per episode.
  - ``sim.case_env``: ``CaseDriveEnv``, the park test of one case from elsewhere (a problem file).
- ``actors``: the adverse events of a test.
  - ``actors.config``: ``ScenarioConfig``, how many adverse events (pedestrians, moving cars, clutter) a test gets;
    ``SCENARIOS``, the named ones.
  - ``actors.scenario``: a test's drawn ``Scenario`` and the car's swept path (``Corridor``) actors are checked on.
  - ``actors.placement``: ``draw_scenario``, the actors' trajectories and triggers around a test's route.
  - ``actors.park_placement``: ``draw_park_scenario``, a park or AVP test's actors around its stall and park plan.
  - ``actors.judging``: ``judge``, whether every event stays avoidable (decided before the drive).
- ``drivers``: the built-in drivers (``oracle``, ``waypoint``, ``vision``, ``park_assist``, ``learned``: the cruise,
  parking and AVP models) and user drivers.
- ``learning``: training a learned driver.
  - ``learning.observation``: what a learned driver sees (camera, waypoint, speed, route left, steering; a parking
    driver both cameras, the ultrasonic ranges and the slot detector; nothing privileged).
  - ``learning.network``: the learned driver's network body (NatureCNN-shaped convolutions over the camera, joined with the route vector).
  - ``learning.fleet_env``: ``FleetDriveEnv``, one garage of a set per episode, with the oracle's action as a label.
  - ``learning.park_actions``: the learned parking driver's 90 park commands.
  - ``learning.train``: ``train-driver``, a DQN (cruise, or park over the park commands) on the unprivileged
    observation, trained by DAgger.
- ``difficulty``: relating outcomes to difficulty.
  - ``difficulty.regression``: Pearson r and the regression of success on difficulty, the paper's table; bootstrap r, AUC.
  - ``difficulty.fit``: fit and score the route-aware difficulty on recorded cruise outcomes.
  - ``difficulty.rating``: the route difficulty of many garages, computed once each and kept (a library's, a cruise run's).
  - ``difficulty.park``: fit and score the park difficulty on park and AVP runs, beside HOPE's levels.
  - ``difficulty.park_rating``: a park or AVP run's park model (the driver's shipped one, else the default) and its
    tests' ``park_difficulty`` cells.
- The test runner, at the top level:
  - ``sources``: what a cruise run tests (``CruiseSource``), its settings and each test's seed.
  - ``park_geometries``: ``PARK_GEOMETRIES``, park geometries by name (stalls, aisle, parked fleet).
  - ``garage_set``: ``GarageSet``, the garages a learned driver trains or is tested on, and where they came from.
  - ``episode``: one cruise test driven to its row, with the scene and driver a process keeps.
  - ``results``: a cruise run's folder: ``run.json``, ``tests.csv`` read back and repaired, the summaries.
  - ``cruise``: batch cruise tests over packs or library garages, resumable.
  - ``replay``: a cruise test driven again from its OpenSCENARIO file (``replay_xosc``).
  - ``cases``: park tests from problem files (TPCAP's cases, exported park problems), resumable.
  - ``hunt``: the search for garages that break a given driver.
"""
