"""``learned``: a deep-RL driver, a stable-baselines3 model acting from the unprivileged observation.

The model (a DQN or PPO ``.zip`` saved by ``garage-mj train-driver``, ``MultiInputPolicy`` over
:func:`~garage_mj.driving.learning.observation.learned_space`) sees what
:func:`~garage_mj.driving.learning.observation.learned_observation` makes of the drive env's observation
(camera depth and segmentation, the next route waypoint, speed, route left, steer) and picks one of
the paper's 4 actions by argmax, so the same test gives the same drive. ``--driver learned`` runs
the shipped model ``models/drivers/<DEFAULT_MODEL>.zip``; ``--driver learned:PATH`` another one.

A model file is data: its weights and plain settings are read, nothing in it is unpickled or run
(:mod:`~garage_mj.core.model_file`, the one loading door). A process loads each model file once (:func:`load_model`, keyed by path and modification time),
so a cruise worker that drives many tests reads the zip and imports torch once.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from garage_mj.core.model_file import ModelFileError
from garage_mj.driving.drivers import DriverError
from garage_mj.driving.learning.observation import (
    PARK_SENSORS,
    learned_observation,
    learned_space,
    park_observation,
    park_space,
    park_vector_size,
)
from garage_mj.driving.learning.park_actions import PARK_COMMANDS, park_command
from garage_mj.driving.learning.saved_model import (  # noqa: F401  (the shipped models' names, read here too)
    AVP_CRUISE_MODEL,
    DEFAULT_MODEL,
    DRIVER_MODELS,
    NAMED,
    PARK_MODEL,
    default_model,
    learned_kind,
    load_driver_model,
    model_path,
)
from garage_mj.driving.sim.park_guide import START_RADIUS
from garage_mj.driving.sim.vehicle import DISCRETE_COMMANDS, DiscreteAction

N_ACTIONS = len(DiscreteAction)  # the paper's 4 actions
#: The SB3 algorithm that loads a zip, by the module of the policy class its ``data`` records.
ALGORITHMS = {"stable_baselines3.dqn.policies": "DQN", "stable_baselines3.common.policies": "PPO"}
#: Intra-op torch threads while the model picks an action (set around each call, then given back, so
#: the host process keeps its own setting). One: a cruise worker is one process per core, and one
#: 64x64 frame through NatureCNN gains nothing from more: measured per act on the 2-core machine
#: with others' training on it, 1 thread 0.40-0.65 ms, 2 threads 5-70 ms (a thread waits for a busy
#: core); ``vision`` takes 0.2-0.4 ms, an env step 0.7-1.2 ms.
TORCH_THREADS = 1
#: Whether an act runs the convolutions through oneDNN (PyTorch's default on CPU). No: between two acts
#: the renderer and the physics evict oneDNN's kernels from the caches, and a cold oneDNN convolution
#: costs more than PyTorch's own (im2col + GEMM). Measured inside a drive loop on the 2-core machine,
#: an act of the shipped model took 0.21 ms with oneDNN and 0.15 ms without (``eval/bench_driver_step.py``).
#: The Q-values differ from oneDNN's in the 7th digit; every act of a process takes the same path.
MKLDNN_IN_ACT = False
_MODEL_CACHE_SIZE = 4  # models a process keeps loaded (a retrained file is a new entry)
_MODELS: dict[tuple[str, int, int], Any] = {}


def _no_model(path: Path, why: str = "") -> DriverError:
    return DriverError(f"no learned driver model at {path}{why}: train one with `garage-mj train-driver` "
                       "(see README) or give learned:PATH")


def _one_line(exc: BaseException, limit: int = 160) -> str:
    """``exc`` as one short line, so the fix after it is never cut off."""
    line = " ".join(f"{type(exc).__name__}: {exc}".split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _algorithm(path: Path) -> str:
    """``"DQN"`` or ``"PPO"``: which SB3 class saved ``path`` (read from the zip's ``data`` JSON)."""
    try:
        with zipfile.ZipFile(path) as z:
            data = json.loads(z.read("data"))
        module = data["policy_class"]["__module__"]
    except (OSError, zipfile.BadZipFile, KeyError, TypeError, ValueError) as exc:
        raise _no_model(path, f" (not a stable-baselines3 model zip: {_one_line(exc)})") from None
    if module not in ALGORITHMS:
        raise DriverError(f"learned driver model {path}: its policy is from {module}; the learned driver runs "
                          f"DQN or PPO models ({', '.join(sorted(ALGORITHMS.values()))}) from `garage-mj train-driver`")
    return ALGORITHMS[module]


def load_model(path: str | Path, parking: bool = False) -> Any:
    """The SB3 model at ``path`` on the CPU, loaded once per process and file version.

    The file is read as data (:func:`~garage_mj.driving.learning.saved_model.load_driver_model`): weights and plain
    settings, nothing in it unpickled or run. Checks that it acts with the paper's 4 actions (``parking``: with the
    90 park commands of :mod:`~garage_mj.driving.learning.park_actions`); a missing, unreadable, corrupt or
    code-carrying file, or another action space, is a one-line :class:`DriverError` naming the file, what is wrong
    and the fix.
    """
    path = Path(path).expanduser()
    try:
        stat = path.resolve().stat()
    except OSError:
        raise _no_model(path) from None
    if not path.is_file():
        raise _no_model(path, " (not a file)")
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    if key in _MODELS:
        return _MODELS[key]
    algo = _algorithm(path)
    import stable_baselines3  # heavy (torch): only when a learned driver is built

    try:  # the file read as data: weights and plain settings, nothing in it unpickled or run
        model = load_driver_model(path, getattr(stable_baselines3, algo), acting=True)
    except ModelFileError as exc:
        raise _no_model(path, f" (cannot load it as {algo}: {exc})") from None
    except Exception as exc:  # torch/zip errors of a damaged file: name the file, keep one short line
        raise _no_model(path, f" (cannot load it as {algo}: {_one_line(exc)})") from None
    space = model.action_space
    want = len(PARK_COMMANDS) if parking else N_ACTIONS
    if type(space).__name__ != "Discrete" or int(space.n) != want or int(getattr(space, "start", 0)) != 0:
        if parking:
            raise DriverError(f"learned parking driver model {path}: its actions are {space}, the park commands' are "
                              f"Discrete({want}); train it with garage-mj train-driver --task park")
        raise DriverError(f"learned driver model {path}: its actions are {space}, the paper's are Discrete({N_ACTIONS}); "
                          "train it on a discrete GarageDriveEnv (garage-mj train-driver)")
    _check_finite_weights(model, path)
    while len(_MODELS) >= _MODEL_CACHE_SIZE:
        _MODELS.pop(next(iter(_MODELS)))
    _MODELS[key] = model
    return model


def _check_finite_weights(model: Any, path: Path) -> None:
    """Refuse a model with a NaN or infinite weight (a run that diverged): its Q-values would be NaN and
    its argmax a constant action, which would pass as the model's driving."""
    for name, tensor in model.policy.state_dict().items():
        if tensor.is_floating_point() and not bool(tensor.isfinite().all()):
            raise DriverError(f"learned driver model {path}: its weight {name} holds NaN or infinite values (the "
                              "training diverged); retrain it (garage-mj train-driver) or use another model")


def _space_difference(got, want) -> str | None:
    """What differs between a model's observation space ``got`` and the driver's ``want`` (None: same)."""
    if type(got).__name__ != "Dict" or set(got.spaces) != set(want.spaces):
        keys = sorted(got.spaces) if hasattr(got, "spaces") else got
        return f"it observes {keys}, a learned driver {sorted(want.spaces)}"
    for name, w in want.spaces.items():
        g = got.spaces[name]
        if g.shape != w.shape or g.dtype != w.dtype:
            return f"its {name!r} is {g.shape} {g.dtype}, the camera gives {w.shape} {w.dtype}"
        if not (np.array_equal(g.low, w.low) and np.array_equal(g.high, w.high)):
            return f"its {name!r} bounds differ from learned_space's"
    return None


def greedy_action(model: Any, obs: dict[str, np.ndarray]) -> int:
    """The model's greedy action for one observation (a dict of arrays): the policy's own greedy step on a batch of
    one, as ``model.predict`` does, without its checks and copies (half the time of predict per step; same action:
    tests compare them), on :data:`TORCH_THREADS` threads and with oneDNN as :data:`MKLDNN_IN_ACT` says, both given
    back after it."""
    import torch  # loaded with the model already: a dict lookup

    threads, mkldnn = torch.get_num_threads(), torch.backends.mkldnn.enabled
    torch.set_num_threads(TORCH_THREADS)  # ~0.2 us a swap
    torch.backends.mkldnn.enabled = MKLDNN_IN_ACT
    try:
        with torch.inference_mode():
            batch = {k: torch.from_numpy(v).unsqueeze(0) for k, v in obs.items()}
            return int(model.policy._predict(batch, deterministic=True).reshape(-1)[0])
    finally:
        torch.set_num_threads(threads)
        torch.backends.mkldnn.enabled = mkldnn


class LearnedDriver:
    """A trained SB3 model driving with the paper's 4 actions, deterministically (argmax)."""

    action_type = "discrete"  # the paper's actions (see garage_mj.driving.drivers)

    def __init__(self, model: str | Path | None = None) -> None:
        self.path = model_path(model)
        self.model = load_model(self.path)
        self.discrete = True
        self._checked: tuple[int, ...] | None = None  # the camera shape the model was checked against

    def reset(self, info: dict[str, Any]) -> None:
        """Start a test. Nothing is random (argmax); with continuous actions the chosen action's
        ``[throttle, steer]`` command is sent (:data:`~garage_mj.driving.sim.vehicle.DISCRETE_COMMANDS`)."""
        self.discrete = info.get("action_type", "discrete") == "discrete"

    def _check(self, shape: tuple[int, ...]) -> None:
        why = _space_difference(self.model.observation_space, learned_space(*shape))
        if why:
            raise DriverError(f"learned driver model {self.path} does not fit this camera ({shape[0]}x{shape[1]}): "
                              f"{why}; drive with the camera it was trained on or train one for this camera")
        self._checked = shape

    def act(self, obs: dict[str, Any]):
        """The model's action for ``obs`` (a drive env observation, depth in metres)."""
        o = learned_observation(obs)
        if self._checked != o["image"].shape[1:]:
            self._check(o["image"].shape[1:])
        action = greedy_action(self.model, o)
        if self.discrete:
            return action
        return np.array(DISCRETE_COMMANDS[DiscreteAction(action)], dtype=np.float32)


class LearnedParkDriver:
    """A trained parking model (``train-driver --task park``) sending the continuous park action.

    It sees :func:`~garage_mj.driving.learning.observation.park_observation`: both cameras, the 12 ultrasonic
    ranges, the slot detector, the heading to end in, speed, steering and gear, and the park route or its guide
    where the model was trained with them (nothing privileged); a
    run turns on the sensors it declares (:data:`sensors`). It picks one of the 90 park commands by argmax (so the
    same test gives the same drive) and sends it: ``[pedal, steer, gear]``
    (:data:`~garage_mj.driving.learning.park_actions.PARK_COMMANDS`). ``learned:park`` runs the shipped model.
    """

    action_type = "continuous"  # [pedal, steer, gear] (garage_mj.driving.sim.vehicle.park_command_from_action)
    tasks = ("park",)
    sensors = PARK_SENSORS  # the parking sensors it observes (CruiseSettings.with_sensors turns them on)

    def __init__(self, model: str | Path | None = None) -> None:
        named = model is None or str(model) in NAMED
        self.path = model_path("park" if named else model)
        if named and not self.path.is_file():
            raise DriverError(f"no parking model is shipped at {self.path}: train one with garage-mj train-driver "
                              "GARAGES --task park --out RUN and drive it with --driver learned:RUN/model.zip "
                              "(docs/learned-parking.md)")
        self.model = load_model(self.path, parking=True)
        # a model trained with the park route or the park guide observes them (train-driver's park_route and
        # park_guide): its vector is longer by theirs
        size = int(self.model.observation_space["vector"].shape[0])
        self.route, self.guide = next(((r, g) for r in (False, True) for g in (False, True)
                                       if park_vector_size(r, g) == size), (False, False))
        self._checked: tuple[int, ...] | None = None

    def reset(self, info: dict[str, Any]) -> None:
        """Start a test (nothing is random: the policy's mean action)."""
        if info.get("action_type", "continuous") != "continuous":
            raise DriverError(f"learned parking driver {self.path} sends the continuous park action [pedal, steer, "
                              "gear]; leave out --action-type (or give continuous)")

    def _check(self, shape: tuple[int, ...]) -> None:
        why = _space_difference(self.model.observation_space, park_space(*shape, self.route, self.guide))
        if why:
            raise DriverError(f"learned parking driver model {self.path} does not fit this camera ({shape[0]}x"
                              f"{shape[1]}): {why}; drive with the camera it was trained on")
        self._checked = shape

    def act(self, obs: dict[str, Any]) -> np.ndarray:
        """The policy's park command for ``obs`` (a park or AVP test's observation, depth in metres)."""
        try:
            o = park_observation(obs, self.route, self.guide)
        except ValueError as exc:
            raise DriverError(f"learned parking driver: {exc}") from None
        if self._checked != o["image"].shape[1:]:
            self._check(o["image"].shape[1:])
        return park_command(greedy_action(self.model, o))


class LearnedAVPDriver:
    """An AVP test driven by two learned models: the cruise model to the stall, then the parking model into it.

    ``learned:avp``: a cruise model (:class:`LearnedDriver`, the paper's 4 actions sent as their ``[throttle, steer]``
    commands in drive; by default the shipped :data:`AVP_CRUISE_MODEL`, trained as ``--driver learned``'s but in the
    park geometries) follows the route from the entrance. Where a park test would start, the
    car brakes to rest and the parking model (:class:`LearnedParkDriver`) parks it. For a parking model that reads the
    park guide, that is where the plan starts: the guide begins (its gear reads non-zero) when the car has come within
    :data:`~garage_mj.driving.sim.park_guide.START_RADIUS` of the plan's start; from there the cruise model steers on
    at a crawl (:data:`CRAWL`, held by the pedal) and the car brakes to rest once its own odometry (the speed it
    observes, times the control period) says it has covered that distance, less what it takes to stop from a crawl.
    (Braked to rest where the guide begins, a car that arrived slowly stood up to a metre short of the start, where
    the parking model, trained from the start, often failed.) For a parking model without the guide, the car brakes
    when the slot detector reports the target stall alongside (its centre within :data:`HANDOVER_AHEAD` ahead or
    behind and :data:`HANDOVER_RANGE` away). Both see only their own unprivileged observations; the handover is the
    one rule between them.
    """

    action_type = "continuous"
    tasks = ("avp",)
    sensors = PARK_SENSORS
    HANDOVER_AHEAD = 1.0  # [m] |slot x| (car frame) at most this: the stall is alongside
    HANDOVER_RANGE = 8.0  # [m] and its centre at most this far away
    AT_REST = 0.05  # [m/s] the parking model takes over below this speed
    CRAWL = 0.5  # [m/s] the approach to the plan's start, once the guide has begun

    def __init__(self, model: str | Path | None = None, cruise_model: str | Path | None = None) -> None:
        self.cruise = LearnedDriver(default_model(AVP_CRUISE_MODEL) if cruise_model is None else cruise_model)
        self.park = LearnedParkDriver(None if model is None or str(model) == "avp" else model)
        self.phase = "cruise"
        self.dt = 0.1  # [s] the control period (the reset info's)
        self.decel = 5.0  # [m/s^2] the car's full braking (the reset info's car)
        self.covered = 0.0  # [m] odometry since the guide began

    def reset(self, info: dict[str, Any]) -> None:
        """Start a test: cruise first."""
        self.park.reset(info)
        self.cruise.reset({**info, "action_type": "continuous"})
        self.phase = "cruise"
        self.dt = float(info.get("dt", 0.1))
        self.decel = float(getattr(info.get("car"), "max_decel", 5.0))
        self.covered = 0.0

    def _approached(self) -> bool:
        """Whether the car, approaching at a crawl since the guide began, should brake now to stand on the plan's
        start: it has covered :data:`~garage_mj.driving.sim.park_guide.START_RADIUS` less its stopping distance
        from a crawl (one control period, then full braking)."""
        stopping = self.CRAWL * self.dt + self.CRAWL ** 2 / (2 * self.decel)
        return self.covered + stopping >= START_RADIUS

    def _at_park_start(self, obs: dict[str, Any]) -> bool:
        """Whether the car is where a park test starts: the park guide has begun, or without one the stall is
        alongside."""
        if self.park.guide:
            return "park_guide" in obs and float(np.asarray(obs["park_guide"]).reshape(-1)[0]) != 0.0
        return self._stall_alongside(obs)

    def _stall_alongside(self, obs: dict[str, Any]) -> bool:
        """Whether the slot detector reports the target stall alongside (the handover without the park guide)."""
        slot = np.asarray(obs["slot"], dtype=float).reshape(-1) if "slot" in obs else None
        return slot is not None and abs(slot[0]) <= self.HANDOVER_AHEAD and math.hypot(slot[0], slot[1]) <= \
            self.HANDOVER_RANGE

    def act(self, obs: dict[str, Any]) -> np.ndarray:
        """The cruise model's command until the car is where a park test starts, a stop, then the parking model's."""
        if self.phase == "cruise":
            if self._at_park_start(obs):
                self.phase = "approach" if self.park.guide else "stop"
            else:
                throttle, steer = (float(v) for v in self.cruise.act(obs))
                return np.array([throttle, steer, 1.0], dtype=np.float32)
        if self.phase == "approach":
            speed = abs(float(np.asarray(obs["speed"]).reshape(-1)[0]))
            self.covered += speed * self.dt
            if self._approached():
                self.phase = "stop"
            else:
                steer = float(self.cruise.act(obs)[1])  # its steering; the pedal holds a crawl
                return np.array([1.0 if speed < self.CRAWL else -1.0, steer, 1.0], dtype=np.float32)
        if self.phase == "stop":
            if abs(float(np.asarray(obs["speed"]).reshape(-1)[0])) > self.AT_REST:
                return np.array([-1.0, 0.0, 1.0], dtype=np.float32)
            self.phase = "park"
        return self.park.act(obs)
