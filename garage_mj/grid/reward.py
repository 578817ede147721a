"""The painter's reward (paper Sec. "Reward Function Design"): constraint amounts and utility weights.

The utility weights ``w_x`` and ``w_y`` are also what :mod:`garage_mj.grid.metrics` scores road
lengths and intersections with; the painter env (:mod:`garage_mj.generation.gen_env`) reads the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class RewardConfig:
    """Reward R = k_c * R_c + k_u * R_u of the painter MDP (paper Sec. "Reward Function Design").

    Constraint terms (R_c) are fixed amounts per event. Utility terms (R_u) are weighted
    differences of the performance values P_s (stalls per initial FREE cell), P_r (road-length
    utility) and P_c (intersection utility) before and after the step.
    """

    k_c: float = 1.0
    k_u: float = 1.0
    collision_penalty: float = -5.0  # step into a wall, obstacle, entrance or off the grid
    square_penalty: float = -5.0  # painting would complete a 2x2 road-like square
    backward_penalty: float = -1.0  # move opposite to the heading (not an error)
    step_penalty: float = -0.1  # every step, so that dawdling costs
    exit_bonus: float = 100.0  # reaching the exit (the garage becomes usable)
    failure_penalty: float = -50.0  # errors exceeded max_errors
    w_s: float = 100.0  # weight of P_s (stalls per initial FREE cell)
    w_r: float = 20.0  # weight of P_r (road-length utility)
    w_c: float = 20.0  # weight of P_c (intersection utility)
    # Utility weights per value of X (segment length, cells) and Y (intersection degree):
    # long straight roads and T-junctions are favoured.
    w_x: dict[int, float] = field(
        default_factory=lambda: {2: 0.2, 3: 0.4, 4: 0.6, 5: 0.8, 6: 1.0}
    )
    w_y: dict[int, float] = field(default_factory=lambda: {2: 0.3, 3: 1.0, 4: 0.6})
