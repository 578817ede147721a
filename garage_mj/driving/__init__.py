"""Driving: the testbed where a driver takes the car from the entrance to a stall.

- ``vehicle``: the car in MuJoCo (actuation, discrete and continuous actions).
- ``sensors``: the front camera (depth + segmentation, offscreen).
- ``outcomes``: how a test ends (success, collision, timeout, deadlock, missed_goal) and why.
- ``actor_config``: ``ScenarioConfig``, how many adverse events (pedestrians, moving cars, clutter) a test gets.
- ``actors``: a test's drawn ``Scenario`` and the car's swept path (``Corridor``) actors are checked on.
- ``actor_placement``: ``draw_scenario``, the actors' trajectories and triggers around a test's route.
- ``actor_judging``: ``judge``, whether every event stays avoidable (decided before the drive).
- ``drive_env``: ``GarageDrive-v0``, one garage, one test per episode.
- ``drivers``: the built-in drivers (``oracle``, ``waypoint``, ``vision``) and user drivers.
- ``sources``: what a cruise run tests (``CruiseSource``), its settings and each test's seed.
- ``learned_obs``: what a learned driver sees (camera, waypoint, speed, route left, steering; nothing privileged).
- ``learned_net``: the learned driver's network body (NatureCNN-shaped convolutions over the camera, joined with the route vector).
- ``fleet_env``: ``FleetDriveEnv``, one garage of a set per episode, with the oracle's action as a label.
- ``train_driver``: ``train-driver``, DQN on the unprivileged observation, warm-started by DAgger.
- ``garage_set``: ``GarageSet``, the garages a learned driver trains or is tested on, and where they came from.
- ``episode``: one cruise test driven to its row, with the scene and driver a process keeps.
- ``regression``: Pearson r and the regression of success on difficulty, the paper's table; bootstrap r, AUC.
- ``difficulty_fit``: fit and score the route-aware difficulty on recorded cruise outcomes.
- ``route_rating``: the route difficulty of many garages, computed once each and kept (a library's, a cruise run's).
- ``results``: a cruise run's folder: ``run.json``, ``tests.csv`` read back and repaired, the summaries.
- ``cruise``: batch cruise tests over packs or library garages, resumable.
- ``replay``: a cruise test driven again from its OpenSCENARIO file (``replay_xosc``).
- ``hunt``: the search for garages that break a given driver.
"""
