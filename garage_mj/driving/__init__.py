"""Driving: the testbed where a driver takes the car from the entrance to a stall.

- ``vehicle``: the car in MuJoCo (actuation, discrete and continuous actions).
- ``sensors``: the front camera (depth + segmentation, offscreen).
- ``outcomes``: how a test ends (success, collision, timeout, deadlock) and why.
- ``actors``: adverse events (pedestrians, moving cars, clutter): behaviours, placement, judging.
- ``drive_env``: ``GarageDrive-v0``, one garage, one test per episode.
- ``drivers``: the built-in drivers (``oracle``, ``waypoint``, ``vision``) and user drivers.
- ``cruise``: batch cruise tests over packs or library garages, resumable.
- ``hunt``: the search for garages that break a given driver.
"""
