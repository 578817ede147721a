"""Testing: garage-mj inside a user's own test suite (the ``pytest_garage_mj`` plugin's machinery).

- ``garages``: the garages tests run on: the painted tiny garage, painted garages of maps, a library and
  asset packs of a few garages, and what a ``garages`` argument may name (maps, packs, a library, garages).
- ``driver_tests``: cruise tests of a driver class, their results table, and an assertion whose message
  lists each failed test with how it failed, its MP4 and its ``.xosc``.

The pytest plugin itself (fixtures, the ``garage_mj`` marker, the ``--garage-*`` options) is the
top-level module ``pytest_garage_mj``, outside this package: pytest loads it in every run of anyone who
installed garage-mj, so it imports nothing but pytest and reaches this package only inside fixtures.
"""

from garage_mj.testing.driver_tests import DriverTestError, DriverTests, driver_spec, run_driver_tests

__all__ = ["DriverTestError", "DriverTests", "driver_spec", "run_driver_tests"]
