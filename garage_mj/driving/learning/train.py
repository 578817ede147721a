"""Train a learned cruise driver: SB3 DQN on the unprivileged observation, warm-started by DAgger.

The model is a stable-baselines3 ``DQN`` with ``MultiInputPolicy`` (a CNN over the camera's depth
and segmentation, an MLP over the vector: :mod:`garage_mj.driving.learning.observation`) and the paper's
four discrete actions. It is trained over a set of garages (:class:`FleetDriveEnv`, one garage per
episode) in two stages:

1. **Imitation (DAgger).** Deep RL from scratch on camera images is out of reach of a 2-core CPU,
   so the Q-network is first trained as a classifier of the privileged ``oracle``'s action (the
   oracle reads the plan and the exact pose; the model sees only its own observation). Iteration
   0 drives with the oracle; iteration ``i`` lets the model drive with probability
   ``1 - beta0 * beta_decay**i`` per step while the oracle labels every state it visits (Ross et
   al., 2011), so the model learns to recover from its own mistakes. After each iteration the
   network is trained ``epochs`` passes over all states so far (cross-entropy on the Q-values'
   softmax, so the greedy action is the oracle's) and validated on held-out garages.
2. **DQN fine-tuning** (``rl_timesteps``, default 0): ``model.learn`` on the env's reward
   (route progress, success bonus, collision penalty), starting from the imitated network, with
   5% exploration; episodes in ``rl_monitor.csv``, validation after it in ``run.json``. This stage
   is not checkpointed: interrupted, it starts again from the last imitation iteration.

What it draws garages by (``curriculum``): ``uniform``; ``difficulty`` (iteration ``i`` of ``n``
draws from the easiest ``(i + 1) / n`` of the set, by the library's difficulty); or
``adversarial`` (failure-prioritised replay: before each iteration after the first, the garages
where the current model failed most in its last iteration's own drives are drawn more: weight
``1 + 4 * failure rate``); or ``hunt`` (unsupervised environment design with the testbed's own
adversary: before each iteration after the first, :func:`~garage_mj.driving.hunt.hunt` spends
``hunt_budget`` cruise tests searching, by mutating painted garages of the training set's map, for
garages where the current model fails; the ``hunt_keep`` worst it found join the set and get
``hunt_share`` of the draws of that iteration; the hunts are in ``hunt/iter_NNN``).

The run folder (resumable: every iteration is checkpointed, an interrupted run continues from
the last finished one, with the same result; resuming with more ``iterations`` or another
``rl_timesteps`` extends a run, and its ``model.zip`` is made again):

- ``run.json``: config, garages' origin, progress, the validation curve and timings;
- ``garages.json`` and ``validation_garages.json``: the sets trained and validated on;
- ``curve.csv``: per iteration: states, loss, agreement with the oracle, validation success;
- ``data/iter_NNN.npz``: the states and labels of each iteration; ``checkpoints/iter_NNN.zip``;
- ``model.zip``: the final model (``--driver learned:RUN/model.zip``): the iteration with the best
  validation success (the later of equals; ``run.json``'s ``selected_iteration``), then the DQN
  stage if any. Validation garages are not test garages: test on others (``eval/bench_learned.py``).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.backends import Compute, process_end
from garage_mj.core.config import bounded, check_bounds, load_config, refuse_other_settings
from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import atomic_write, write_json
from garage_mj.core.model_file import ModelFileError
from garage_mj.driving.actors.config import SCENARIOS
from garage_mj.driving.cruise import run_test
from garage_mj.driving.drivers.park_tracking import ACTOR_FORESIGHT, ParkTrackConfig
from garage_mj.driving.episode import close_cached_env
from garage_mj.driving.garage_set import garage_map
from garage_mj.driving.hunt import HuntConfig, hunt
from garage_mj.driving.learning.observation import PARK_SENSORS, PARK_VECTOR_KEYS, SPEED_RANGE
from garage_mj.driving.learning.park_actions import PARK_COMMANDS
from garage_mj.driving.learning.saved_model import load_driver_model
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sim.outcomes import OutcomeKind
from garage_mj.driving.sim.park_guide import MAX_REPLANS
from garage_mj.driving.sim.park_task import MANEUVER_CHOICES, MAX_HANDOVER_START
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.scene.world import GeometryError

MANIFEST = "run.json"
CURVE = "curve.csv"
MODEL = "model.zip"
RL_MONITOR = "rl_monitor.csv"
AT_REST = ParkTrackConfig.at_rest  # [m/s] a parking driver's state slower than this is at rest (start_weight)
CURRICULA = ("uniform", "difficulty", "adversarial", "hunt")
TRAIN_TASKS = ("cruise", "park")  # what train-driver trains: a cruise driver or a parking driver
#: ``validate``'s count of the tests of a garage that cannot be built in its park geometry (not driven, not counted).
UNBUILDABLE = "unbuildable"
#: The outcomes the training curve counts apart (``val_<kind>``); the other failures are ``val_other``.
CURVE_KINDS = (OutcomeKind.COLLISION.value, OutcomeKind.TIMEOUT.value)
CURVE_FIELDS = ("iteration", "states", "beta", "loss", "agreement", "own_drive_success", "val_success",
                *(f"val_{k}" for k in CURVE_KINDS), "val_other", "wall_s")


class TrainDriverError(GarageMJError):
    """A driver training run cannot start or resume (bad folder, config that differs from the run's)."""


@dataclass(frozen=True)
class DriverTrainConfig:
    """How a learned driver is trained (TOML-loadable, unknown keys rejected)."""

    iterations: int = bounded(6, ge=1, le=10_000)  # DAgger iterations
    steps_per_iteration: int = bounded(6000, ge=1, le=10_000_000)  # [env steps] driven (and labelled) per iteration
    beta0: float = bounded(1.0, ge=0.0, le=1.0)  # share of steps the oracle drives in iteration 0 ...
    # ... and beta0 * beta_decay**i in iteration i (0: the model drives from iteration 1)
    beta_decay: float = bounded(0.5, ge=0.0, le=1.0)
    # passes over all states so far, per iteration (3 underfit: 69% agreement, no success)
    epochs: int = bounded(10, ge=1, le=10_000)
    batch_size: int = bounded(128, ge=1, le=1_000_000)
    learning_rate: float = bounded(1e-3, gt=0.0, le=1.0)
    n_envs: int = bounded(2, ge=1, le=256)  # worker processes driving
    val_tests: int = bounded(20, ge=0, le=1_000_000)  # validation tests per iteration (the curve)
    curriculum: str = bounded("uniform", choices=CURRICULA)
    rl_timesteps: int = bounded(0, ge=0, le=10**10)  # DQN fine-tuning after imitation
    occupancy: float = bounded(0.5, ge=0.0, le=1.0)  # share of non-target stalls with a parked car
    torch_threads: int = bounded(2, ge=1, le=1024)
    hunt_budget: int = bounded(40, ge=1, le=10_000_000)  # [cruise tests] per iteration the hunt spends (curriculum "hunt")
    hunt_keep: int = bounded(8, ge=1, le=100_000)  # hunted garages (with a failure, worst first) added per iteration
    hunt_share: float = bounded(0.5, ge=0.0, le=1.0)  # share of an iteration's draws that go to the hunted garages
    # the network (garage_mj.driving.learning.network): NatureCNN-shaped convolutions with cnn_channels filters over
    # the image to cnn_features, concatenated with the vector, then net_arch. A narrow image feature keeps the 5
    # route/speed numbers from being drowned by 256 image features (with 256: 94% agreement with the oracle but
    # 35-50% validation success)
    cnn_features: int = bounded(32, ge=1, le=65_536)
    # filters of the 3 convolutions (NatureCNN's)
    cnn_channels: tuple[int, ...] = bounded((32, 64, 64), ge=1, le=4096, length=3, why="one per convolution")
    # weight of the states within 2 m of the goal in the imitation loss: the stop is a tenth of the states but,
    # at weight 1, all of the shipped model's held-out failures (stops 1 m short of or past the goal)
    stop_weight: float = bounded(4.0, gt=0.0, le=1e6)
    net_arch: tuple[int, ...] = bounded((128, 128), ge=1, le=65_536)  # hidden layer widths after the features
    # a parking driver: weight of the states where the oracle asks for the other gear. They are about 1% of the
    # states, and at weight 1 the model never changed gear: it waited in D at the start of a reverse-in test
    gear_change_weight: float = bounded(20.0, gt=0.0, le=1e6)
    # a parking driver: weight of the states at rest where the oracle moves off. Moving off is one state and the
    # waits before it many: in a run at weight 1, 8% of the at-rest labels moved off, and the model stood still
    start_weight: float = bounded(20.0, gt=0.0, le=1e6)
    # a parking driver: observe the park route too (the waypoint ahead on the test's reference plan and the route
    # left, as the cruise driver reads its route); without it, it parks from its sensors alone
    park_route: bool = False
    # a parking driver: the expert plans again from the car's pose when the car has left its plan (FleetDriveEnv's
    # replan); tracking the first plan, its labels off it were brakes, and the model learned to stop
    replan: bool = False
    # a parking driver: observe the park route stretch by stretch too (the drive env's park_guide: the gear of the
    # stretch the car is on, the offset and heading off it, its bend ahead, the stretch left); the expert drives the
    # stretch it shows. With park_route alone, whose waypoint points back along the way at a cusp, no model parked
    park_guide: bool = False
    # a parking driver with actors: what the expert yields to, "trajectory" (where each actor will go: the oracle's
    # foresight, which a camera cannot share) or "present" (where each actor is now, which the cameras show)
    expert_foresight: str = bounded("trajectory", choices=ACTOR_FORESIGHT)
    # a parking driver: [m] each training (and validation) park test starts up to this far before or after its plan's
    # start, where an AVP test's cruise hands the car over (the drive env's handover_start; learned:avp hands over
    # within 1.5 m of it); 0: on the plan's start, as every park test
    handover_start: float = bounded(0.0, ge=0.0, le=MAX_HANDOVER_START)
    # a parking driver with the park guide: new plans the guide may show a training (and validation) test, each from
    # where the car stands at rest outside the stall (the drive env's guide_replans); the expert drives the plan shown
    guide_replans: int = bounded(MAX_REPLANS, ge=0, le=10)
    # what the driver learns to do: cruise tests (a DQN over the paper's 4 actions) or park tests (a DQN over 90 park
    # commands, learning.park_actions, from both cameras, the ultrasonic ranges and the slot detector); an AVP test
    # is driven by the two together (learned:avp)
    task: str = bounded("cruise", choices=TRAIN_TASKS)
    maneuver: str = bounded("any", choices=MANEUVER_CHOICES)  # park tests: reverse, forward or any (drawn per test)
    # the park geometries the garages are built in (garage k: the (k mod n)th), by name
    # (garage_mj.driving.park_geometries), for a cruise or a parking driver; none: the default geometry
    geometries: tuple[str, ...] = bounded((), choices=tuple(PARK_GEOMETRIES))
    # park tests: the actor scenarios drawn with each geometry, by name (garage_mj.driving.actors.config
    # SCENARIOS; "none": no actors): garage k gets the (k mod n)th of every geometry x scenario pair
    scenarios: tuple[str, ...] = bounded((), choices=("none", *(n for n in SCENARIOS if n.startswith("park_"))))

    def __post_init__(self) -> None:
        check_bounds(self)  # built in code, held to the ranges a loaded config is (load_config checks them first)
        if self.task != "cruise" and self.rl_timesteps:
            raise ValueError("rl_timesteps: the RL stage fine-tunes cruise drivers only; a parking driver is trained "
                             "by imitation (leave rl_timesteps at 0)")
        if self.task != "cruise" and self.curriculum == "hunt":
            raise ValueError("curriculum: the hunt curriculum searches cruise tests; give uniform, difficulty or "
                             "adversarial for a parking driver")
        if self.park_guide and self.replan:
            raise ValueError("park_guide, replan: the guide shows the test's plan and a replanning expert drives "
                             "another; set one of them")
        if self.task == "cruise" and (self.park_guide or self.park_route or self.replan
                                      or self.expert_foresight != "trajectory" or self.handover_start
                                      or self.guide_replans != MAX_REPLANS):
            raise ValueError("park_route, park_guide, replan, expert_foresight, handover_start, guide_replans: these "
                             "are a parking driver's (task = \"park\")")
        if self.task == "cruise" and self.scenarios:
            raise ValueError("scenarios: the park actor scenarios are for a parking driver (task = \"park\"); a "
                             "cruise driver's actors: --scenario")

    def fleet_options(self) -> dict[str, Any]:
        """The worker envs' park observation and expert options (:class:`FleetDriveEnv`'s ``park_route``,
        ``replan``, ``park_guide`` and ``actor_foresight``)."""
        return {"park_route": self.park_route, "replan": self.replan, "park_guide": self.park_guide,
                "actor_foresight": self.expert_foresight}

    @property
    def parking(self) -> bool:
        """Whether this trains a parking driver: park tests, the parking observation and the 90 park commands."""
        return self.task != "cruise"

    def variants(self) -> list[dict[str, Any]]:
        """The env settings of each garage's geometry and actors (:class:`FleetDriveEnv`'s ``variants``): every
        pair of :attr:`geometries` and :attr:`scenarios`, the scenarios varying fastest."""
        geometries = [PARK_GEOMETRIES[name].env_kwargs() for name in self.geometries] or [{}]
        scenarios = [{} if name == "none" else {"scenario": name} for name in self.scenarios] or [{}]
        pairs = [{**g, **a} for g in geometries for a in scenarios]
        return [] if pairs == [{}] else pairs


def _weights(cfg: DriverTrainConfig, sources: list[CruiseSource], iteration: int,
             failures: np.ndarray, drives: np.ndarray) -> np.ndarray:
    """Draw weights of the training garages for ``iteration`` (module docstring, ``curriculum``)."""
    n = len(sources)
    if cfg.curriculum == "difficulty":
        order = np.argsort([s.difficulty for s in sources], kind="stable")
        keep = max(1, math.ceil(n * (iteration + 1) / cfg.iterations))
        w = np.zeros(n)
        w[order[:keep]] = 1.0
        return w
    if cfg.curriculum == "adversarial" and drives.sum() > 0:
        rate = np.divide(failures, drives, out=np.zeros(n), where=drives > 0)
        return 1.0 + 4.0 * rate
    return np.ones(n)


def _progress_bar(total: int):
    """A tqdm bar over the DQN stage's timesteps (SB3's own needs ``rich``, which is not a dependency)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class Bar(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, desc="DQN", unit="step")

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return Bar()


def _selected(curve: list[dict[str, Any]]) -> int:
    """The iteration whose model becomes ``model.zip``: the best validation success, the later of equals
    (the last iteration when there is no validation)."""
    scored = [(float(r["val_success"]), int(r["iteration"])) for r in curve if r.get("val_success") not in ("", None)]
    return max(scored)[1] if scored else int(curve[-1]["iteration"])


def _hunted(out: Path, it: int, sources: list[CruiseSource], cfg: DriverTrainConfig, seed: int,
            env_kwargs: dict[str, Any]) -> list[CruiseSource]:
    """The garages a hunt against iteration ``it - 1``'s model found it failing on (worst first)."""
    from collections import Counter

    map_name = Counter(garage_map(s) for s in sources).most_common(1)[0][0]
    model = (out / "checkpoints" / f"iter_{it - 1:03d}.zip").resolve()
    hunt_cfg = HuntConfig(budget=cfg.hunt_budget, tests=2, population=8, elites=2, worst=0)
    settings = CruiseSettings.from_env_kwargs(f"learned:{model}", env_kwargs, seed=seed * 1_000 + it,
                                              action_type="discrete")
    result = hunt(settings, out / "hunt" / f"iter_{it:03d}", map=map_name, config=hunt_cfg,
                  compute=Compute(workers=cfg.n_envs, progress=False))
    return [s.source for s in result.ranked if s.failures][: cfg.hunt_keep]


def _make_venv(sources: list[CruiseSource], n_envs: int, env_kwargs: dict[str, Any], expert: bool,
               variants: list[dict[str, Any]] | None = None, fleet: dict[str, bool] | None = None):
    """``n_envs`` :class:`FleetDriveEnv` workers; ``fleet``: their park observation and expert options
    (:meth:`DriverTrainConfig.fleet_options`)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from garage_mj.driving.learning.fleet_env import FleetDriveEnv

    def make():
        return FleetDriveEnv(sources, expert=expert, env_kwargs=env_kwargs, variants=variants, **(fleet or {}))

    if n_envs == 1:
        return DummyVecEnv([make])
    return SubprocVecEnv([make] * n_envs, start_method="forkserver")


def _collect(model, venv, steps: int, beta: float, seed: int, weights: np.ndarray, n_garages: int):
    """Drive ``steps`` env steps (oracle with probability ``beta`` per step, else the model); the states,
    the oracle's labels, and per garage the model-driven episodes and their failures."""
    n = venv.num_envs
    venv.env_method("set_weights", weights)
    venv.seed(seed)
    obs = venv.reset()
    labels = np.array([i["expert_action"] for i in venv.reset_infos])
    rng = np.random.default_rng(seed)
    images, vectors, acts = [], [], []
    own = np.zeros(n, dtype=bool)  # the current episode saw a model-driven step
    drives, failures = np.zeros(n_garages), np.zeros(n_garages)
    outcomes: list[tuple[bool, str]] = []
    for _ in range(math.ceil(steps / n)):
        images.append(obs["image"].copy())
        vectors.append(obs["vector"].copy())
        acts.append(labels.copy())
        use_model = rng.random(n) >= beta
        own |= use_model
        actions = labels
        if use_model.any():  # one forward pass on one thread: the workers have the cores
            mine, _ = model.predict(obs, deterministic=True)
            actions = np.where(use_model, mine, labels)
        obs, _, dones, infos = venv.step(actions)
        labels = np.array([i["expert_action"] for i in infos])
        for e in np.flatnonzero(dones):
            k = infos[e]["garage_index"]
            outcomes.append((bool(own[e]), infos[e]["outcome"]))
            if own[e]:
                drives[k] += 1
                failures[k] += infos[e]["outcome"] != "success"
            labels[e] = venv.reset_infos[e]["expert_action"]
            own[e] = False
    return (np.concatenate(images), np.concatenate(vectors), np.concatenate(acts).astype(np.int64),
            drives, failures, outcomes)


def _near(cfg: DriverTrainConfig, vectors: np.ndarray) -> np.ndarray:
    """Which states are the last metres of the test, where the stop (or the stall) is close: a cruise driver's
    within :data:`~garage_mj.driving.learning.observation.NEAR_RANGE` of the goal, a parking driver's with the stall
    centre within :data:`~garage_mj.driving.learning.observation.SLOT_NEAR` ahead and aside."""
    from garage_mj.driving.learning.observation import PARK_VECTOR_KEYS, VECTOR_KEYS

    if cfg.parking:
        x, y = PARK_VECTOR_KEYS.index("slot_near_x"), PARK_VECTOR_KEYS.index("slot_near_y")
        return (np.abs(vectors[:, x]) < 1.0) & (np.abs(vectors[:, y]) < 1.0)
    return vectors[:, VECTOR_KEYS.index("near_goal")] < 1.0


def _state_weights(cfg: DriverTrainConfig, vectors: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Each state's weight in the imitation loss: ``stop_weight`` in the last metres (:func:`_near`), else 1; a
    parking driver's states where the oracle asks for the other gear than the one engaged ``gear_change_weight``,
    and those at rest where it moves off ``start_weight``."""
    weights = np.where(_near(cfg, vectors), cfg.stop_weight, 1.0).astype(np.float32)
    if cfg.parking:
        change = (PARK_COMMANDS[labels, 2] < 0) != (vectors[:, PARK_VECTOR_KEYS.index("gear")] < 0)
        weights = np.where(change, cfg.gear_change_weight, weights).astype(np.float32)
        at_rest = np.abs(vectors[:, PARK_VECTOR_KEYS.index("speed")] * SPEED_RANGE) < AT_REST
        weights = np.where(at_rest & (PARK_COMMANDS[labels, 0] > 0), cfg.start_weight, weights).astype(np.float32)
    return weights


def _fit(model, images: np.ndarray, vectors: np.ndarray, labels: np.ndarray, cfg: DriverTrainConfig,
         seed: int) -> tuple[float, float]:
    """``epochs`` passes of cross-entropy on the Q-network over the states (weighted by :func:`_state_weights`), so
    the greedy action is the oracle's (a parking driver's: the park command nearest the
    oracle's); (mean loss, agreement) of the last."""
    import torch

    torch.manual_seed(seed)
    q_net = model.policy.q_net
    q_net.train()
    opt = torch.optim.Adam(q_net.parameters(), lr=cfg.learning_rate)
    rng = np.random.default_rng(seed)
    n = len(labels)
    weights = _state_weights(cfg, vectors, labels)
    loss_sum = agree = 0.0
    for _ in range(cfg.epochs):
        order = rng.permutation(n)
        loss_sum = agree = 0.0
        for lo in range(0, n, cfg.batch_size):
            idx = np.sort(order[lo: lo + cfg.batch_size])
            obs = {"image": torch.as_tensor(images[idx]), "vector": torch.as_tensor(vectors[idx])}
            y = torch.as_tensor(labels[idx])
            q = q_net(obs)
            w = torch.as_tensor(weights[idx])
            loss = (torch.nn.functional.cross_entropy(q, y, reduction="none") * w).sum() / w.sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum += loss.item() * len(idx)
            agree += float((q.argmax(1) == y).sum())
    q_net.eval()
    model.policy.q_net_target.load_state_dict(q_net.state_dict())
    return loss_sum / n, agree / n


def validate(model_path: str | Path, sources: list[CruiseSource], tests: int, seed: int,
             env_kwargs: dict[str, Any] | None = None, variants: list[dict[str, Any]] | None = None) -> dict[str, int]:
    """Outcome counts of ``tests`` tests of the model saved at ``model_path`` on ``sources``, dealt
    round-robin over the garages: test ``k`` of a garage is its cruise (park: ``env_kwargs``' ``task``) test
    ``k`` (:func:`~garage_mj.driving.cruise.run_test` with the driver ``learned:PATH``, as ``garage-mj cruise``
    would drive it; garage ``g`` with ``variants[g % len(variants)]`` over ``env_kwargs``; ``infeasible`` and
    ``unproven`` count the tests that are not driven, :data:`UNBUILDABLE` those of a garage that cannot be built in
    its geometry)."""
    env = dict(env_kwargs or {})
    task = {k: env.pop(k) for k in ("task", "maneuver") if k in env}
    parking = task.get("task", "cruise") != "cruise"
    counts: dict[str, int] = {}
    try:
        for g, src in enumerate(sources[:tests]):
            variant = variants[g % len(variants)] if variants else {}
            settings = CruiseSettings.from_env_kwargs(f"learned:{Path(model_path).resolve()}", {**env, **variant},
                                                      seed=seed, action_type="continuous" if parking else "discrete",
                                                      **task).with_sensors(PARK_SENSORS if parking else ())
            for index in range(len(range(g, tests, len(sources)))):  # this garage's share of the tests
                try:
                    outcome = run_test(src, index, settings)["outcome"]
                except GeometryError:  # the garage cannot be built in its variant's geometry (the draw leaves it out)
                    outcome = UNBUILDABLE
                counts[outcome] = counts.get(outcome, 0) + 1
    finally:
        close_cached_env()
    return counts


def _success(counts: dict[str, int]) -> float | None:
    """Success over the feasible tests of ``validate``'s counts (None: no feasible test)."""
    feasible = sum(v for k, v in counts.items() if k not in ("infeasible", "unproven", UNBUILDABLE))
    return round(counts.get("success", 0) / feasible, 4) if feasible else None


def _load_checkpoint(path: Path, venv, cfg: DriverTrainConfig, **kwargs: Any):
    """A checkpoint saved by :func:`_save` on ``venv`` (None: none), ``kwargs`` set on the model, read as data
    (:func:`~garage_mj.driving.learning.saved_model.load_driver_model`: weights and plain settings, nothing in
    it unpickled or run)."""
    try:
        from stable_baselines3 import DQN

        return load_driver_model(path, DQN, env=venv, **kwargs)
    except ModelFileError as exc:
        raise TrainDriverError(f"checkpoint {path} cannot be resumed: {exc}; "
                               "run garage-mj train-driver again with another --out") from None


def _save(model, path: Path, **kwargs: Any) -> None:
    """``model.save`` to ``path`` atomically (a temporary zip beside it, then renamed)."""
    tmp = path.with_name(path.stem + ".tmp.zip")
    model.save(tmp, **kwargs)
    os.replace(tmp, path)


def _write_curve(path: Path, rows: list[dict[str, Any]]) -> None:
    text = io.StringIO()
    w = csv.DictWriter(text, fieldnames=CURVE_FIELDS)
    w.writeheader()
    w.writerows(rows)
    atomic_write(path, text.getvalue())


def _write_manifest(out: Path, manifest: dict[str, Any], state: dict[str, Any]) -> None:
    write_json(out / MANIFEST, {**manifest, "state": state}, indent=1)


class _Workers:
    """The worker envs a run drives, made again when the garages they draw from change; closed once at the end.
    A worker process that dies under the run (``kill -9``, the OOM killer, a segfault) is :meth:`lost`: one line."""

    def __init__(self, pool: list[CruiseSource], n_envs: int, env_kwargs: dict[str, Any],
                 variants: list[dict[str, Any]] | None = None, fleet: dict[str, bool] | None = None) -> None:
        self.pool, self.n_envs, self.env_kwargs, self.variants, self.fleet = pool, n_envs, env_kwargs, variants, fleet
        self.venv = None
        self.venv = self._open(lambda: _make_venv(pool, n_envs, env_kwargs, expert=True, variants=variants,
                                                  fleet=fleet))

    def _open(self, make: Callable[[], Any]) -> Any:
        try:
            return make()
        except _LOST:  # one died while they started
            raise self.lost() from None

    def draw_from(self, pool: list[CruiseSource]) -> None:
        """Expert-labelled workers over ``pool`` (the same ones when they already draw from it)."""
        if pool is not self.pool:  # the workers hold other garages than this iteration draws from
            self.pool = pool
            self.close()
            self.venv = self._open(lambda: _make_venv(pool, self.n_envs, self.env_kwargs, expert=True,
                                                      variants=self.variants, fleet=self.fleet))

    def remake(self, make: Callable[[], Any]) -> Any:
        """Close the workers, then run on those ``make()`` returns."""
        self.close()
        self.venv = self._open(make)
        return self.venv

    def close(self) -> None:
        """Close the workers; when one of them died, stop the others (a pipe to a dead one refuses the goodbye)."""
        venv, self.venv = self.venv, None
        if venv is None:
            return
        try:
            venv.close()
        except _LOST:
            for proc in getattr(venv, "processes", []):
                proc.kill()
                proc.join()

    def lost(self) -> TrainDriverError:
        """The one line for a worker process that died under the run, naming it and how when it can."""
        procs = getattr(self.venv, "processes", []) if self.venv is not None else []
        deadline = time.monotonic() + 2.0  # the pipe breaks a moment before the exit status is there
        while procs and all(p.exitcode is None for p in procs) and time.monotonic() < deadline:
            time.sleep(0.05)
        ends = [f"{i} {process_end(p.exitcode)}" for i, p in enumerate(procs) if p.exitcode is not None]
        which = f" (worker {', '.join(ends)})" if ends else ""
        return TrainDriverError(f"a worker process driving the training envs died{which}; the iterations saved in "
                                f"checkpoints/ are kept: run the same command with --resume to continue")


#: What the pipe to a worker process that died raises (EOFError on a read, BrokenPipeError ... on a write).
_LOST = (EOFError, ConnectionError)


def train_driver(garages, out_dir: str | Path, *, validation=None, config: DriverTrainConfig | dict | None = None,
                 seed: int = 0, resume: bool = True, progress: bool = True,
                 env_kwargs: dict[str, Any] | None = None, init: str | Path | None = None) -> Path:
    """Train a learned driver on ``garages`` (a :class:`~garage_mj.driving.garage_set.GarageSet`) into
    ``out_dir`` (module docstring); ``validation``: the garages of the curve (default: the training
    ones). Returns the final model's path. Same seed and config, same model, interrupted or not.

    ``init``: a model zip of the same task and network to start from instead of a new network (fine-tuning a
    trained driver on other garages): a run's checkpoint (``RUN/checkpoints/iter_NNN.zip``) brings that run's
    states up to its iteration too, and DAgger goes on over them and this run's (:func:`init_states`); any other
    zip (a ``model.zip``, a shipped model) its network only."""
    import torch
    from stable_baselines3 import DQN  # noqa: F401  (here: a missing stable-baselines3 fails before the folder is made)

    cfg = config if isinstance(config, DriverTrainConfig) else load_config(DriverTrainConfig, config)
    out = Path(out_dir)
    sources = list(garages)
    val_sources = list(validation) if validation is not None else sources
    if not sources:
        raise TrainDriverError("no garages to train on: check the garage set's filters")
    env_kwargs = dict(env_kwargs or {})
    env_kwargs.setdefault("occupancy", cfg.occupancy)
    if cfg.parking:
        env_kwargs.update(task=cfg.task, maneuver=cfg.maneuver)
        if cfg.handover_start:
            env_kwargs["handover_start"] = cfg.handover_start
        if cfg.guide_replans != MAX_REPLANS:
            env_kwargs["guide_replans"] = cfg.guide_replans
    manifest = _new_manifest(garages, validation, sources, cfg, seed, env_kwargs)
    if init is not None:
        manifest["init"] = {"model": str(init), "sha256": _sha256(Path(init)),
                            "states_from": [str(p) for p in init_states(Path(init))]}
    state = _resumed_state(out, manifest, cfg, resume)
    with _undone_if_no_run(out):
        _prepare_folder(out, garages, validation)
        torch.set_num_threads(cfg.torch_threads)
        workers = _Workers(sources, cfg.n_envs, env_kwargs, cfg.variants(), cfg.fleet_options())  # the garages the worker envs draw from (the hunt adds some)
        try:
            model = _start_model(out, state["iterations_done"], workers.venv, cfg, seed, init)
            state = _dagger(model, workers, out, manifest, state, sources, val_sources, cfg, seed, env_kwargs,
                            progress)
            state["selected_iteration"] = _selected(state["curve"])
            _write_manifest(out, manifest, state)
            _final_model(workers, out, manifest, state, sources, val_sources, cfg, seed, env_kwargs, progress)
        except _LOST:
            raise workers.lost() from None
        finally:
            workers.close()
    return out / MODEL


def _new_manifest(garages, validation, sources: list[CruiseSource], cfg: DriverTrainConfig, seed: int,
                  env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The run's ``run.json`` without its ``state``: what it trains, on what, with which settings."""
    algorithm = ("DQN (MultiInputPolicy) over 90 park commands, trained by DAgger" if cfg.parking
                 else "DQN (MultiInputPolicy), DAgger warm start")
    return {"kind": "garage-mj driver", "algorithm": algorithm, "task": cfg.task,
            "seed": seed, "config": dataclasses.asdict(cfg), "env": env_kwargs,
            "garages": getattr(garages, "origin", f"{len(sources)} garages"),
            "garage_hashes": [s.hash for s in sources],
            "validation": getattr(validation, "origin", "the training garages") if validation is not None
            else "the training garages"}


#: The manifest's keys a run resumes only under (more iterations or a DQN stage extend a run: not compared).
_RESUME_KEYS = ("seed", "config", "env", "garage_hashes", "init")
_EXTENDS = {"iterations": 0, "rl_timesteps": 0}


def _resumed_state(out: Path, manifest: dict[str, Any], cfg: DriverTrainConfig, resume: bool) -> dict[str, Any]:
    """The state of the run already in ``out`` (a fresh one when there is none), once it is known that this
    call may continue it: ``resume`` asked, the same settings, no fewer iterations. An extended run's
    ``model.zip`` is deleted, to be made again."""
    state: dict[str, Any] = {"iterations_done": 0, "curve": [], "wall_s": 0.0}
    if not (out / MANIFEST).exists():
        return state
    try:
        old = json.loads((out / MANIFEST).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise TrainDriverError(f"{out / MANIFEST} is not readable JSON ({exc}); remove the folder or use another --out") from None
    if not resume:
        raise TrainDriverError(f"{out} already holds a driver run; pass --resume to continue it or use another --out")
    wanted = {k: manifest.get(k) for k in _RESUME_KEYS}
    wanted["config"] = {**wanted["config"], **_EXTENDS}
    # a key the stored config lacks was added since the run began: it ran with that key's default
    defaults = json.loads(json.dumps(dataclasses.asdict(DriverTrainConfig())))
    stored = {**old, "config": {**defaults, **old["config"], **_EXTENDS}} if isinstance(old.get("config"), dict) \
        else old
    refuse_other_settings(stored, wanted, lambda diff: TrainDriverError(
        f"{out} holds a run with another {diff[0]}; use another --out, or the same settings to resume"), _RESUME_KEYS)
    state = old.get("state", state)
    if state["iterations_done"] > cfg.iterations:
        raise TrainDriverError(f"{out} has already run {state['iterations_done']} iterations; ask for at least as many")
    if state["iterations_done"] < cfg.iterations or (state.get("rl") or {}).get("timesteps", 0) != cfg.rl_timesteps:
        (out / MODEL).unlink(missing_ok=True)  # extended: the final model is made again
    return state


#: What a run writes into its folder before its first ``run.json``.
_GARAGE_SETS = ("garages.json", "validation_garages.json")
_SUBFOLDERS = ("data", "checkpoints", "hunt")


def _prepare_folder(out: Path, garages, validation) -> None:
    """The run folder with ``data/`` and ``checkpoints/``, and the garage sets it trains and validates on
    (a new run writes them anew: another run's start that failed or was killed may have left others)."""
    fresh = not (out / MANIFEST).exists()
    out.mkdir(parents=True, exist_ok=True)
    (out / "data").mkdir(exist_ok=True)
    (out / "checkpoints").mkdir(exist_ok=True)
    for name, group in zip(_GARAGE_SETS, (garages, validation)):
        if group is not None and hasattr(group, "to_json") and (fresh or not (out / name).exists()):
            group.to_json(out / name)


@contextlib.contextmanager
def _undone_if_no_run(out: Path):
    """A start that fails leaves the folder as it was: when the body raises (Ctrl-C included) before the
    run's first ``run.json``, the garage sets get back what they held (or go), and ``data/``,
    ``checkpoints/``, ``hunt/`` and ``out`` itself go when this start made them."""
    if (out / MANIFEST).exists():
        yield
        return
    made = [p for p in (out, *(out / n for n in _SUBFOLDERS)) if not p.exists()]
    held = {n: (out / n).read_bytes() if (out / n).is_file() else None for n in _GARAGE_SETS}
    try:
        yield
    except BaseException:
        if not (out / MANIFEST).exists():
            for name, data in held.items():
                if data is None:
                    (out / name).unlink(missing_ok=True)
                elif not (out / name).is_file() or (out / name).read_bytes() != data:
                    atomic_write(out / name, data)
            for path in made:
                shutil.rmtree(path, ignore_errors=True)
        raise


def _start_model(out: Path, done: int, venv, cfg: DriverTrainConfig, seed: int, init: str | Path | None = None):
    """The model after ``done`` iterations: the last checkpoint's, ``init``'s (:func:`_init_model`) or a new one
    seeded with ``seed``."""
    from stable_baselines3 import DQN

    if done:
        return _load_checkpoint(out / "checkpoints" / f"iter_{done - 1:03d}.zip", venv, cfg)
    if init is not None:
        return _init_model(Path(init), venv, cfg, seed)
    from garage_mj.driving.learning.network import CameraRouteExtractor

    policy_kwargs = {"net_arch": list(cfg.net_arch), "features_extractor_class": CameraRouteExtractor,
                     "normalize_images": False,  # the extractor scales the image itself
                     "features_extractor_kwargs": {"channels": tuple(cfg.cnn_channels),
                                                   "cnn_features": cfg.cnn_features}}
    return DQN("MultiInputPolicy", venv, seed=seed, device="cpu", verbose=0, buffer_size=1,
               learning_starts=0, policy_kwargs=policy_kwargs)


def _init_model(path: Path, venv, cfg: DriverTrainConfig, seed: int):
    """The model zip at ``path`` to start a run from, on ``venv``: its observation and actions must be this run's
    and its network the one ``cfg`` describes (else a :class:`TrainDriverError` naming the difference)."""
    from stable_baselines3 import DQN

    try:
        model = load_driver_model(path, DQN, env=venv)
    except ModelFileError as exc:
        raise TrainDriverError(f"--init {path} cannot start this run: {exc}") from None
    kwargs = model.policy_kwargs or {}
    have = {"net_arch": list(kwargs.get("net_arch") or []),
            "cnn_channels": list((kwargs.get("features_extractor_kwargs") or {}).get("channels") or []),
            "cnn_features": (kwargs.get("features_extractor_kwargs") or {}).get("cnn_features")}
    want = {"net_arch": list(cfg.net_arch), "cnn_channels": list(cfg.cnn_channels), "cnn_features": cfg.cnn_features}
    diff = [k for k in want if have[k] != want[k]]
    if diff:
        k = diff[0]
        raise TrainDriverError(f"--init {path} has {k} {have[k]}, this run's config {want[k]}: give the config the "
                               "model was trained with (for a shipped model, models/drivers/<name>.toml)")
    model.set_random_seed(seed)
    return model


def init_states(model: Path) -> list[Path]:
    """The states a run started from ``model`` trains on besides its own: for a checkpoint of a driver run
    (``RUN/checkpoints/iter_NNN.zip`` beside ``RUN/run.json``), the states its network was fitted on: the states
    that run started from itself (its ``run.json``'s ``init``, a run carried on from another's checkpoint), then its
    ``data/iter_000.npz`` to ``iter_NNN.npz`` (a missing one: a :class:`TrainDriverError`); for any other file
    none."""
    run = model.parent.parent
    stem = model.stem
    if model.parent.name != "checkpoints" or not (run / MANIFEST).is_file() or not stem.startswith("iter_") \
            or not stem[5:].isdigit():
        return []
    try:
        inherited = json.loads((run / MANIFEST).read_text()).get("init") or {}
    except (OSError, ValueError) as exc:
        raise TrainDriverError(f"--init {model}: its run's {MANIFEST} cannot be read ({exc}); restore it or start "
                               "from the run's model.zip (its network only)") from None
    shards = [Path(p) for p in inherited.get("states_from") or []]
    shards += [run / "data" / f"iter_{i:03d}.npz" for i in range(int(stem[5:]) + 1)]
    missing = [p for p in shards if not p.is_file()]
    if missing:
        raise TrainDriverError(f"--init {model}: its run's states {missing[0]} are missing; start from the run's "
                               "model.zip (its network only) or restore the run's data/")
    return shards


def _sha256(path: Path) -> str:
    """The SHA-256 of the file at ``path`` (a missing one: a :class:`TrainDriverError`)."""
    import hashlib

    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise TrainDriverError(f"--init {path}: {exc.strerror or exc}; name a model zip") from None


def _dagger(model, workers: _Workers, out: Path, manifest: dict[str, Any], state: dict[str, Any],
            sources: list[CruiseSource], val_sources: list[CruiseSource], cfg: DriverTrainConfig, seed: int,
            env_kwargs: dict[str, Any], progress: bool) -> dict[str, Any]:
    """The imitation iterations still to do (module docstring, stage 1), each checkpointed with its
    states, its curve row and the manifest; returns the run's state after the last."""
    import torch

    done = state["iterations_done"]
    before = [Path(p) for p in manifest.get("init", {}).get("states_from", [])]
    shards = [_load_shard(p, p.parents[1]) for p in before]
    shards += [_load_shard(out / "data" / f"iter_{i:03d}.npz", out) for i in range(done)]
    images = [s["image"] for s in shards]
    vectors = [s["vector"] for s in shards]
    labels = [s["label"] for s in shards]
    failures = np.asarray(state.get("failures", np.zeros(len(sources))), dtype=float)
    drives = np.asarray(state.get("drives", np.zeros(len(sources))), dtype=float)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=cfg.iterations, initial=done, desc="DAgger", unit="iter")
    for it in range(done, cfg.iterations):
        t0 = time.perf_counter()
        beta = cfg.beta0 * (cfg.beta_decay ** it) if it else cfg.beta0
        weights = _weights(cfg, sources, it, failures, drives)
        torch.set_num_threads(1)
        hunted: list[CruiseSource] = []
        if cfg.curriculum == "hunt" and it >= 1:
            hunted = _hunted(out, it, sources, cfg, seed, env_kwargs)
            if hunted:
                weights = np.array([(1 - cfg.hunt_share) / len(sources)] * len(sources)
                                   + [cfg.hunt_share / len(hunted)] * len(hunted))
        workers.draw_from(sources + hunted if hunted else sources)
        im, vec, lab, drives, failures, outcomes = _collect(model, workers.venv, cfg.steps_per_iteration, beta,
                                                             seed * 1_000 + it, weights, len(workers.pool))
        drives, failures = drives[: len(sources)], failures[: len(sources)]
        tmp = out / "data" / f"iter_{it:03d}.tmp.npz"
        np.savez(tmp, image=im, vector=vec, label=lab)
        os.replace(tmp, out / "data" / f"iter_{it:03d}.npz")
        images.append(im)
        vectors.append(vec)
        labels.append(lab)
        torch.set_num_threads(cfg.torch_threads)
        loss, agreement = _fit(model, np.concatenate(images), np.concatenate(vectors), np.concatenate(labels),
                               cfg, seed * 1_000 + it)
        ckpt = out / "checkpoints" / f"iter_{it:03d}.zip"
        _save(model, ckpt)
        val = (validate(ckpt, val_sources, cfg.val_tests, seed + 7_919, env_kwargs, cfg.variants())
               if cfg.val_tests else {})
        row = _curve_row(it, sum(len(x) for x in labels), beta, loss, agreement, outcomes, val, t0)
        state = {"iterations_done": it + 1, "curve": [*state["curve"], row],
                 "wall_s": state["wall_s"] + row["wall_s"], "failures": failures.tolist(),
                 "drives": drives.tolist(),
                 "hunted": {**state.get("hunted", {}), **({str(it): [h.hash for h in hunted]} if hunted else {})}}
        _write_curve(out / CURVE, state["curve"])
        _write_manifest(out, manifest, state)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(val=row["val_success"], agree=row["agreement"])
    if bar is not None:
        bar.close()
    return state


#: The arrays of a data shard (``data/iter_NNN.npz``) and how many axes each has.
_SHARD_ARRAYS = {"image": (4,), "vector": (2,), "label": (1,)}


def _load_shard(path: Path, out: Path) -> dict[str, np.ndarray]:
    """The states and labels of a finished iteration, read whole; a shard that is missing, truncated or not
    one (other arrays, shapes or lengths) is a :class:`TrainDriverError` naming it and the fix."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in _SHARD_ARRAYS}
        if any(a.ndim not in _SHARD_ARRAYS[k] or a.dtype.kind not in "biuf" for k, a in arrays.items()):
            raise ValueError("arrays of other shapes or types")
        if len({len(a) for a in arrays.values()}) != 1:
            raise ValueError("arrays of unequal lengths")
    except Exception as exc:  # noqa: BLE001  (zip, zlib, npy header and key errors: the file is damaged)
        detail = " ".join(str(exc).split())[:160]
        why = "missing" if isinstance(exc, FileNotFoundError) else f"damaged ({type(exc).__name__}: {detail})"
        raise TrainDriverError(f"{path} is {why}: the run cannot resume without its iteration's states; "
                               f"start it again in another --out (or remove {out})") from None
    return arrays


def _curve_row(it: int, states: int, beta: float, loss: float, agreement: float,
               outcomes: list[tuple[bool, str]], val: dict[str, int], t0: float) -> dict[str, Any]:
    """Iteration ``it``'s row of ``curve.csv`` (:data:`CURVE_FIELDS`); ``t0``: when the iteration began."""
    success = _success(val)
    own = [o for m, o in outcomes if m]
    return {"iteration": it, "states": int(states), "beta": round(beta, 4),
            "loss": round(loss, 4), "agreement": round(agreement, 4),
            "own_drive_success": round(own.count("success") / len(own), 4) if own else "",
            "val_success": "" if success is None else success,
            **{f"val_{k}": val.get(k, 0) for k in CURVE_KINDS},
            "val_other": sum(v for k, v in val.items()
                             if k not in ("success", *CURVE_KINDS, "infeasible", "unproven", UNBUILDABLE)),
            "wall_s": round(time.perf_counter() - t0, 1)}


def _final_model(workers: _Workers, out: Path, manifest: dict[str, Any], state: dict[str, Any],
                 sources: list[CruiseSource], val_sources: list[CruiseSource], cfg: DriverTrainConfig, seed: int,
                 env_kwargs: dict[str, Any], progress: bool) -> None:
    """``model.zip`` unless it is there: the selected iteration's network, then the DQN stage when
    ``rl_timesteps`` asks for one (module docstring, stage 2; validated into the manifest's ``rl``)."""
    import torch

    last = out / "checkpoints" / f"iter_{state['selected_iteration']:03d}.zip"
    if cfg.rl_timesteps > 0 and not (out / MODEL).exists():
        from stable_baselines3.common.vec_env import VecMonitor

        venv = workers.remake(lambda: VecMonitor(_make_venv(sources, cfg.n_envs, env_kwargs, expert=False),
                                                 str(out / RL_MONITOR)))
        venv.seed(seed * 1_000 + cfg.iterations)
        torch.set_num_threads(cfg.torch_threads)
        model = _load_checkpoint(last, venv, cfg, exploration_initial_eps=0.05, exploration_final_eps=0.05,
                         exploration_fraction=1.0, learning_starts=min(1_000, cfg.rl_timesteps // 2),
                         buffer_size=50_000, batch_size=64, learning_rate=1e-4, target_update_interval=1_000)
        model.set_random_seed(seed + cfg.iterations)
        model.learn(cfg.rl_timesteps, callback=_progress_bar(cfg.rl_timesteps) if progress else None,
                    reset_num_timesteps=True)
        _save(model, out / MODEL)
        val = validate(out / MODEL, val_sources, cfg.val_tests, seed + 7_919, env_kwargs) if cfg.val_tests else {}
        state["rl"] = {"timesteps": cfg.rl_timesteps, "val": val, "val_success": _success(val)}
        _write_manifest(out, manifest, state)
    elif not (out / MODEL).exists():
        _save(_load_checkpoint(last, None, cfg), out / MODEL, exclude=["replay_buffer"])
        if state.pop("rl", None) is not None:  # a DQN stage asked for before and not now
            _write_manifest(out, manifest, state)
