"""Child process for :func:`garage_mj.export.validate.check_carla`: load maps with CARLA's parser.

Run as ``python -m garage_mj.export.carla_probe`` with a JSON list on stdin, one job per map:
``{"name", "text", "entrance": [road, lane], "exit": [road, lane]}``. Prints one JSON list of
results. It lives in its own process because a malformed file can crash ``carla.Map``; the
parent then reports the crash instead of dying with it. Imports only ``carla`` and the
standard library, so it starts fast.
"""

from __future__ import annotations

import json
import sys
from collections import Counter, deque

WAYPOINT_DISTANCE = 1.0  # [m] spacing for generate_waypoints
STEP = 2.0  # [m] waypoint.next step when following lanes
MAX_VISITS = 200_000  # waypoints followed before giving up on entrance -> exit


def _key(w) -> tuple[int, int, int]:
    return (w.road_id, w.lane_id, int(round(w.s * 2)))


def _connects(cmap, entrance: list[int], exit_: list[int]) -> tuple[bool, int]:
    """Follow ``waypoint.next`` from the entrance lane start; True when the exit lane is reached."""
    road, lane = entrance
    start = cmap.get_waypoint_xodr(road, lane, 0.0)
    if start is None:
        return False, 0
    seen = {_key(start)}
    queue = deque([start])
    while queue and len(seen) < MAX_VISITS:
        w = queue.popleft()
        if (w.road_id, w.lane_id) == tuple(exit_):
            return True, len(seen)
        for n in w.next(STEP):
            k = _key(n)
            if k not in seen:
                seen.add(k)
                queue.append(n)
    return False, len(seen)


def probe(job: dict) -> dict:
    import carla

    cmap = carla.Map(job["name"], job["text"])
    waypoints = cmap.generate_waypoints(WAYPOINT_DISTANCE)
    per_road = Counter(w.road_id for w in waypoints)
    topology = cmap.get_topology()
    ok, visited = _connects(cmap, job["entrance"], job["exit"])
    return {
        "name": job["name"],
        "waypoints": len(waypoints),
        "waypoints_per_road": {str(k): v for k, v in sorted(per_road.items())},
        "topology_edges": len(topology),
        "entrance_reaches_exit": ok,
        "visited": visited,
    }


def main() -> None:
    jobs = json.load(sys.stdin)
    json.dump([probe(j) for j in jobs], sys.stdout)


if __name__ == "__main__":
    main()
