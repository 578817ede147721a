"""Park tests of your own parking stack with garage-mj's pytest plugin: copy this file and my_parker.py into your
tests/ (the plugin comes with garage-mj; nothing to configure). Run it as

    pytest test_my_parker.py                            # 3 reverse-in park tests on a painted tiny_7x11 garage
    pytest test_my_parker.py --garage-maps m5_13x13_aligned --garage-per-map 3 --garage-tests 10 --garage-workers 2

A failing test lists each failed park test (outcome, reason, position and heading error) with the path of its
MP4 and its OpenSCENARIO file (.xosc) in pytest's tmp folder.
"""

from __future__ import annotations

import pytest
from my_parker import MyParker  # your stack: reset(info), act(obs), action_type, tasks = ("park",)


@pytest.mark.garage_mj(maps=["tiny_7x11"], tests=3, task="park", maneuver="reverse")  # --garage-* options override
def test_my_parker_parks(garage_cruise):
    results = garage_cruise(MyParker)  # .rows (tests.csv: position_error_m, plan_length_m, ...), .summary, .failures
    print(results)  # pytest -s shows the per-garage table
    results.assert_success()  # every feasible park test parked, else each failure with its MP4 and .xosc
