"""DQN training on GarageGenEnv that feeds the scenario library (paper Sec. "RL Experiments").

``train(map, timesteps, seed, out_dir)`` runs stable-baselines3 DQN with an MLP policy. Every
finished episode is logged by SB3's ``Monitor`` (``out_dir/monitor.csv``: return, length) and,
when its garage is usable, committed to the library at once, so a crash loses no garage that
was reported. Checkpoints (model + episode/timestep counters) are written atomically every
``checkpoint_every`` timesteps and on Ctrl-C; ``resume=True`` continues from the newest one
(the lifecycle of :class:`garage_mj.generation.runs.DQNRun`).

A run folder holds ``run.json`` (the manifest: map, seed, config, progress, throughput),
``monitor.csv``, ``checkpoints/`` and, at the end, ``final_model.zip`` (and the manifest's ``returns``: the
mean episode return of the first and last tenth of the run's episodes). The manifest's ``live``
(timesteps, episodes, timesteps/s, time) is refreshed every :data:`HEARTBEAT_S` and at each
checkpoint, so a progress view can tell a running run from a stopped one.

A garage met in several runs of one map is credited to the lowest seed
(:meth:`~garage_mj.generation.library.Library.credit`): parallel runs fill the same library
whichever finishes first. A run trained on another machine (:mod:`garage_mj.generation.remote`)
passes a ``sink`` instead of a library and ``on_files``, which gets the files each checkpoint
writes, to send them to the machine that keeps the run.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import gymnasium as gym
from stable_baselines3.common.callbacks import BaseCallback

from garage_mj.core.config import ConfigError, bounded, load_config, read_toml, refuse_other_settings
from garage_mj.core.errors import GarageMJError
from garage_mj.generation.gen_env import GarageGenEnv
from garage_mj.generation.library import Library, check_writable
from garage_mj.generation.runs import DQNRun
from garage_mj.grid.map_io import load_map

if TYPE_CHECKING:
    from garage_mj.grid.garage import Garage

MANIFEST = "run.json"
MONITOR = "monitor.csv"
FINAL_MODEL = "final_model.zip"
LIBRARY = "library.sqlite"
PROGRESS_EVERY = 256  # [timesteps] between progress-bar refreshes
HEARTBEAT_S = 30.0  # [s] between refreshes of the manifest's ``live`` progress
LEARNING_SHARE = 0.1  # of a run's episodes: the first and last this share are compared in its ``returns``


MAX_BUFFER_SIZE = 10_000_000  # [transitions] ~40 GB at ~4 KB each: beyond that the run cannot fit in memory
DEVICES = ("auto", "cpu", "cuda")
MAX_VIEW_SIZE = 31  # [cells] side of the observed window; larger than any supported garage needs
MAX_ENVS = 1_024  # envs of one run, stepped in one process
MAX_TIMESTEPS = 1_000_000_000  # [timesteps] the longest schedule a setting may name
MAX_WIDTH = 4_096  # units of one hidden layer


class TrainingError(GarageMJError):
    """A training run cannot start or resume (bad folder, mismatched manifest)."""


@dataclass(frozen=True)
class DQNConfig:
    """SB3 DQN hyper-parameters and the env settings of a run (TOML-loadable, unknown keys rejected).

    The defaults are tuned so that a few thousand steps on ``tiny_7x11`` already learn to avoid
    walls and reach the exit sometimes; the paper's 2,000,000-step runs use them unchanged.
    ``generation/dqn_fast.toml`` is about 2.5-3.5 times faster (8 envs, (64, 64), one step of 128
    per 8 timesteps) but not yet shown to learn as well (README, "Throughput and learning quality").
    """

    learning_rate: float = bounded(5e-4, gt=0.0, le=1.0)
    # [transitions] ~4 KB each with the 7x7 view
    buffer_size: int = bounded(50_000, ge=1, le=MAX_BUFFER_SIZE, why="~4 KB each: more cannot fit in memory")
    learning_starts: int = bounded(1_000, ge=0, le=MAX_TIMESTEPS)  # [timesteps] of random actions before the first update
    batch_size: int = bounded(64, ge=1, le=65_536)  # [transitions] per gradient step
    tau: float = bounded(1.0, ge=0.0, le=1.0)  # 1: hard target-network update
    gamma: float = bounded(0.99, gt=0.0, le=1.0)
    train_freq: int = bounded(4, ge=1, le=MAX_TIMESTEPS)  # [vector steps] between updates; a vector step is n_envs timesteps
    gradient_steps: int = bounded(1, ge=1, le=10_000)  # gradient steps per update
    n_steps: int = bounded(1, ge=1, le=1_000)  # n-step returns
    target_update_interval: int = bounded(1_000, ge=1, le=MAX_TIMESTEPS)  # [timesteps]
    exploration_fraction: float = bounded(0.2, ge=0.0, le=1.0)  # share of the run over which epsilon decays
    exploration_initial_eps: float = bounded(1.0, ge=0.0, le=1.0)
    exploration_final_eps: float = bounded(0.05, ge=0.0, le=1.0)
    max_grad_norm: float = bounded(10.0, gt=0.0, le=1e6)
    # hidden layer widths of the Q-network
    net_arch: tuple[int, ...] = bounded((256, 256), ge=1, le=MAX_WIDTH, min_items=1)
    checkpoint_every: int = bounded(25_000, ge=1, le=MAX_TIMESTEPS)  # [timesteps] between checkpoints
    save_replay_buffer: bool = False  # also checkpoint the replay buffer (large: buffer_size x 4 KB)
    torch_threads: int = bounded(1, ge=1, le=256)  # CPU threads for torch; 1 is fastest for this small MLP
    # envs stepped together (DummyVecEnv or GarageGenVecEnv, one process): one batched action choice
    n_envs: int = bounded(1, ge=1, le=MAX_ENVS, why="stepped in one process, each with its own garage and buffers")
    view_size: int = bounded(7, ge=1, le=MAX_VIEW_SIZE)  # env: side of the observed window (odd)
    max_errors: int = bounded(10, ge=0, le=10_000)  # env: errors allowed per episode
    # the n_envs garages in one GarageGenVecEnv, windows stored as block codes (~9x less replay memory to
    # fill and sample) and the Q-network's first layer computed from them (WindowLayer): the same network
    vector_env: bool = False
    # torch device of the gradient updates: auto (CUDA when torch sees one), cpu or cuda
    device: str = bounded("auto", choices=DEVICES)

    def __post_init__(self) -> None:
        if not isinstance(self.net_arch, (list, tuple)):
            raise ConfigError(f"DQNConfig: net_arch must be a list of positive integers such as [256, 256], "
                              f"got {self.net_arch!r}")
        for name in ("learning_rate", "max_grad_norm"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ConfigError(f"DQNConfig: {name} must be a finite number > 0, got {v!r}")
        if self.buffer_size > MAX_BUFFER_SIZE:
            raise ConfigError(f"DQNConfig: buffer_size {self.buffer_size} is above {MAX_BUFFER_SIZE:,} transitions "
                              "(~4 KB each); choose a smaller replay buffer")
        if not (isinstance(self.view_size, int) and 1 <= self.view_size <= MAX_VIEW_SIZE and self.view_size % 2):
            raise ConfigError(f"DQNConfig: view_size must be an odd integer from 1 to {MAX_VIEW_SIZE}, "
                              f"got {self.view_size!r}")
        if self.device not in DEVICES:
            raise ConfigError(f"DQNConfig: device must be one of {', '.join(DEVICES)}, got {self.device!r}")
        if not isinstance(self.max_errors, int) or self.max_errors < 0:
            raise ConfigError(f"DQNConfig: max_errors must be an integer >= 0, got {self.max_errors!r}")
        arch = tuple(self.net_arch)
        if not arch or not all(isinstance(w, int) and not isinstance(w, bool) and w > 0 for w in arch):
            raise ConfigError(f"DQNConfig: net_arch must be a list of positive integers, got {self.net_arch!r}")
        object.__setattr__(self, "net_arch", arch)
        for name in ("buffer_size", "batch_size", "train_freq", "gradient_steps", "n_steps",
                     "target_update_interval", "checkpoint_every", "torch_threads", "n_envs"):
            if getattr(self, name) < 1:
                raise ConfigError(f"DQNConfig: {name} must be >= 1, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ConfigError(f"DQNConfig: learning_starts must be >= 0, got {self.learning_starts}")
        for name in ("exploration_fraction", "exploration_initial_eps", "exploration_final_eps", "tau"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"DQNConfig: {name} must be in [0, 1], got {getattr(self, name)}")
        if not 0.0 < self.gamma <= 1.0:
            raise ConfigError(f"DQNConfig: gamma must be in (0, 1], got {self.gamma}")

    def dqn_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``stable_baselines3.DQN``."""
        keys = ("learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma", "train_freq",
                "gradient_steps", "n_steps", "target_update_interval", "exploration_fraction",
                "exploration_initial_eps", "exploration_final_eps", "max_grad_norm")
        kw = {k: getattr(self, k) for k in keys}
        kw["policy_kwargs"] = {"net_arch": list(self.net_arch), "optimizer_kwargs": _adam_kwargs()}
        if self.vector_env:
            # the first hidden layer computed from the window's block codes (WindowLayer), the rest as usual
            from garage_mj.generation.window_net import WindowLayer

            kw["policy_kwargs"].update(net_arch=list(self.net_arch[1:]), features_extractor_class=WindowLayer,
                                       features_extractor_kwargs={"width": self.net_arch[0]})
        return kw

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["net_arch"] = list(self.net_arch)
        return d


def _adam_kwargs() -> dict[str, Any]:
    """Fused Adam where torch has it on CPU (>= 2.4): the same update, one kernel instead of a
    loop over the parameter tensors (66 us instead of 208 us per step for the (64, 64) Q-network)."""
    import torch

    return {"fused": True} if torch.torch_version.TorchVersion(torch.__version__) >= "2.4" else {}


#: The named learners: DQN settings that ``train --learner``, protocol files and the benchmarks choose
#: from; a config file's keys override the chosen learner's. ``paper``: the paper's kind of run, one
#: env, a (256, 256) MLP, one gradient step of 64 transitions per 4 timesteps. ``fast``: 32 garages
#: painted together (GarageGenVecEnv), a (64, 64) MLP on the same input (its first layer read from the
#: window's codes, WindowLayer), 3-step returns, one gradient step of 256 transitions per 32 timesteps at
#: twice the learning rate, the target network renewed every 250 gradient steps as in ``paper`` (8,000
#: timesteps), and epsilon-greedy exploration ending at 0.1 instead of 0.05 (its policy changes less
#: between episodes, so with 0.05 it repeats more of its garages); trained by LeanDQN, about 13x the
#: timesteps/s (docs/results.md compares what they store).
LEARNERS: dict[str, dict[str, Any]] = {
    "paper": {},
    "fast": {"vector_env": True, "n_envs": 32, "net_arch": [64, 64], "batch_size": 256, "train_freq": 1,
             "gradient_steps": 1, "n_steps": 3, "learning_rate": 1e-3, "target_update_interval": 8_000,
             "exploration_final_eps": 0.1},
}
# the fast learner is the default: over 19 seeds of m5 and m7 at 200,000 timesteps it stores more distinct
# usable garages, over the same or a wider difficulty range, at a return within the paper learner's spread
# (docs/results.md, "The fast learner against the paper's"; eval/learner_verdict.py)
DEFAULT_LEARNER = "fast"


def learner_settings(learner: str) -> dict[str, Any]:
    """The :data:`LEARNERS` entry ``learner``; :class:`ConfigError` naming the known ones otherwise."""
    if learner not in LEARNERS:
        raise ConfigError(f"unknown learner {learner!r}; choose one of {', '.join(LEARNERS)}")
    return dict(LEARNERS[learner])


def load_dqn_config(source: str | Path | dict[str, Any] | None = None, *, learner: str = "paper",
                    **overrides: Any) -> DQNConfig:
    """A :class:`DQNConfig`: the ``learner``'s settings (:data:`LEARNERS`; ``paper`` is the plain
    :class:`DQNConfig` defaults), then the keys of a TOML file or dict (a ``[dqn]`` table or top-level
    keys), then ``overrides``."""
    base = learner_settings(learner)
    if isinstance(source, (str, Path)):
        path = Path(source)
        data = read_toml(path)
        if set(data) == {"dqn"}:
            data = data["dqn"]
        return load_config(DQNConfig, {**base, **data}, where=path, **overrides)
    return load_config(DQNConfig, {**base, **(source or {})}, **overrides)


# -- env wrappers ---------------------------------------------------------------------------------
class FinalGarage(gym.Wrapper):
    """Puts the episode's final :class:`Garage` into ``info["final_garage"]`` when it ends.

    The vectorised env resets right after the last step, so the callback could not read the
    final matrix from the env any more; the info dict carries it across.
    """

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            info["final_garage"] = self.env.unwrapped.garage()
        return obs, reward, terminated, truncated, info


class StepTimer(gym.Wrapper):
    """Adds up the wall time spent inside ``step``/``reset`` of the wrapped env (the env's share)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.seconds = 0.0

    def step(self, action):
        t0 = time.perf_counter()
        out = self.env.step(action)
        self.seconds += time.perf_counter() - t0
        return out

    def reset(self, **kwargs):
        t0 = time.perf_counter()
        out = self.env.reset(**kwargs)
        self.seconds += time.perf_counter() - t0
        return out


def make_env(map: str, config: DQNConfig) -> StepTimer:
    """GarageGenEnv -> FinalGarage -> StepTimer."""
    env: gym.Env = GarageGenEnv(map=map, view_size=config.view_size, max_errors=config.max_errors)
    return StepTimer(FinalGarage(env))


def make_vec_env(map: str, config: DQNConfig, monitor_path: Path | None):
    """``config.n_envs`` envs in one DummyVecEnv under one VecMonitor; returns (vec env, the envs).

    The VecMonitor writes every finished episode (return, length) of all envs to ``monitor_path``
    in the order they end, the order :class:`LibraryCallback` counts them in; an existing file is
    appended to (resume), a missing one is created.
    """
    from stable_baselines3.common.monitor import ResultsWriter
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    envs: list[Any]
    if config.vector_env:
        from garage_mj.generation.vec_env import GarageGenVecEnv

        inner = GarageGenVecEnv(map, config.n_envs, window="codes", view_size=config.view_size,
                                max_errors=config.max_errors)
        envs = [inner]
    else:
        envs = [make_env(map, config) for _ in range(config.n_envs)]
        inner = DummyVecEnv([lambda e=e: e for e in envs])
    venv = VecMonitor(inner)
    if monitor_path is not None:
        venv.results_writer = ResultsWriter(
            str(monitor_path), header={"t_start": venv.t_start, "env_id": "garage_mj/GarageGen-v0"},
            override_existing=not monitor_path.exists(),
        )
    return venv, envs


# -- callbacks ------------------------------------------------------------------------------------
class GarageSink(Protocol):
    """Where a run's usable garages go: a :class:`Library`, or a stream to the machine that keeps it."""

    def credit(self, garage: Garage, *, map: str, run: str, seed: int, episode: int, timestep: int) -> int | None:
        """Store ``garage`` with its provenance (:meth:`Library.credit`); the id when new here, else None."""


class LibraryCallback(BaseCallback):
    """Counts episodes and commits the final garage of every usable one to the library (or ``sink``)."""

    def __init__(self, library: GarageSink, *, map: str, run: str, seed: int, episodes: int = 0) -> None:
        super().__init__()
        self.library, self.map, self.run, self.seed = library, map, run, seed
        self.episodes = episodes  # episodes finished so far in this run (continues on resume)
        self.stored = 0  # garages stored by this process
        self.usable = 0  # usable episodes met by this process (stored or duplicate)
        # garages this process has credited already: crediting one again changes nothing (a lower seed
        # that takes it over keeps it), so a repeat skips the library and its metrics
        self._credited: set[str] = set()

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"]):
            if not done:
                continue
            garage = info.get("final_garage")
            if info.get("usable") and garage is not None:
                self.usable += 1
                key = garage.canonical_hash()
                if key not in self._credited:
                    self._credited.add(key)
                    new = self.library.credit(
                        garage, map=self.map, run=self.run, seed=self.seed, episode=self.episodes,
                        timestep=self.num_timesteps,
                    )
                    self.stored += new is not None
            self.episodes += 1
        return True

    def flush(self) -> None:
        """Nothing to flush: every garage is committed as it is found."""


class ProgressCallback(BaseCallback):
    """A tqdm bar over the run's timesteps with its episodes and garages (the words of ``garage-mj train``'s
    summary line); ``garages0``: the run's garages in the library when this process started (on resume)."""

    def __init__(self, total: int, initial: int, library_cb: LibraryCallback, desc: str, enabled: bool,
                 garages0: int = 0) -> None:
        super().__init__()
        self.total, self.initial, self.library_cb, self.desc, self.enabled = total, initial, library_cb, desc, enabled
        self.garages0 = garages0
        self.bar = None

    def _on_training_start(self) -> None:
        if self.enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, initial=self.initial, desc=self.desc, unit="step",
                            dynamic_ncols=True, smoothing=0.05)

    def _on_step(self) -> bool:
        if self.bar is not None and self.n_calls % PROGRESS_EVERY == 0:
            self.bar.update(self.num_timesteps - self.bar.n)
            self.bar.set_postfix(episodes=self.library_cb.episodes, garages=self.garages0 + self.library_cb.stored,
                                 refresh=False)
        return True

    def close(self, episodes: int | None = None, garages: int | None = None) -> None:
        """Bring the bar to the last timestep and close it, its postfix the run's final ``episodes`` and
        ``garages`` when given (the manifest's, so the bar ends on the counts the summary line prints)."""
        if self.bar is not None:
            self.bar.total = max(self.bar.total, self.num_timesteps)  # the last batch of envs may overshoot it
            self.bar.update(self.num_timesteps - self.bar.n)
            self.bar.set_postfix(episodes=self.library_cb.episodes if episodes is None else episodes,
                                 garages=self.garages0 + self.library_cb.stored if garages is None else garages,
                                 refresh=False)
            self.bar.close()
            self.bar = None


class LiveCallback(BaseCallback):
    """Every :data:`HEARTBEAT_S` of wall time, ``beat()`` (which refreshes the manifest's ``live``)."""

    def __init__(self, beat: Callable[[], None]) -> None:
        super().__init__()
        self.beat, self.last = beat, time.monotonic()

    def _on_step(self) -> bool:
        if self.n_calls % 64 == 0 and time.monotonic() - self.last >= HEARTBEAT_S:
            self.last = time.monotonic()
            self.beat()
        return True


# -- run folder -----------------------------------------------------------------------------------
def read_manifest(out_dir: str | Path) -> dict[str, Any]:
    """The ``run.json`` of a run folder; :class:`TrainingError` if there is none."""
    path = Path(out_dir) / MANIFEST
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise TrainingError(f"{out_dir} holds no training run (no {MANIFEST})") from None
    except (ValueError, RecursionError) as exc:
        raise TrainingError(f"{path} is not valid JSON ({str(exc)[:120]}); delete the run folder and train again") from None


def new_run_id(map_name: str, seed: int, out: Path) -> str:
    """``<map>_s<seed>_<UTC time>_<folder digest>``: unique per run folder and start."""
    import hashlib

    digest = hashlib.sha1(str(out.resolve()).encode()).hexdigest()[:6]
    return f"{map_name}_s{seed}_{datetime.now(timezone.utc).strftime('%Y%m%dT%H%M%S')}_{digest}"


def _count_run(library_path: Path, run: str) -> int:
    with Library(library_path) as lib:
        return lib.count(run=run)


def train(
    map: str,
    timesteps: int,
    seed: int,
    out_dir: str | Path,
    config: DQNConfig | None = None,
    resume: bool = False,
    library_path: str | Path | None = None,
    progress: bool = True,
    callbacks: list[BaseCallback] | None = None,
    *,
    sink: GarageSink | None = None,
    run_id: str | None = None,
    on_files: Callable[[list[Path]], None] | None = None,
) -> dict[str, Any]:
    """Train DQN for ``timesteps`` in total on ``map``; returns the final manifest.

    Args:
        map: shipped map name or map file.
        timesteps: total timesteps of the run (on resume, the run stops when it has this many).
        seed: seeds torch, numpy, the action space and the env.
        out_dir: the run folder (created; must not hold another run unless ``resume``).
        config: hyper-parameters (default: the :data:`DEFAULT_LEARNER`'s); on resume the run's own config is used.
        resume: continue the run in ``out_dir`` from its newest checkpoint.
        library_path: where usable garages go (default ``out_dir/library.sqlite``).
        progress: show a tqdm progress bar.
        callbacks: extra SB3 callbacks (tests, instrumentation).
        sink: where usable garages go instead of a library (``library_path`` is then not opened; the
            manifest's ``library`` and ``garages_stored`` stay None for the keeper of the library to fill).
        run_id: a new run's id (default :func:`new_run_id`).
        on_files: called with the files of ``out_dir`` just written, in order: after each checkpoint
            (``monitor.csv``, the checkpoint's model, replay buffer, counters, then ``run.json``), at each
            ``live`` refresh (``run.json``) and at the end (``final_model.zip``, ``run.json``).
    """
    if timesteps < 1:
        raise TrainingError(f"--timesteps must be >= 1, got {timesteps}")
    out = Path(out_dir)
    map_name = load_map(map).name  # validates the map before anything is written
    if resume:
        manifest, config = _resumed_manifest(out, map_name, seed, config)
    else:
        manifest, config = _new_manifest(out, map, map_name, seed, config, run_id)
    library_path = None if sink is not None else Path(library_path) if library_path is not None else out / LIBRARY
    if library_path is not None:
        check_writable(library_path)  # before the run folder is written: the first usable garage goes there
    run = DQNRun(out, manifest, MANIFEST, resume)
    manifest.update(target_timesteps=timesteps, library=None if library_path is None else str(library_path))
    if resume and run.done_steps >= timesteps and manifest.get("status") == "finished":
        return manifest
    run.restart_log(out / MONITOR, header_lines=2)

    venv, envs = make_vec_env(map, config, out / MONITOR)
    model = run.start_model(venv, config, seed, save_replay_buffer=config.save_replay_buffer)
    library = Library(library_path) if library_path is not None else None
    lib_cb = LibraryCallback(library or sink, map=map_name, run=manifest["run"], seed=seed,  # type: ignore[arg-type]
                             episodes=run.done_episodes)
    garages0 = _count_run(library_path, manifest["run"]) if resume and library_path is not None else 0
    bar = ProgressCallback(timesteps, run.done_steps, lib_cb, f"{map_name} seed {seed}", progress, garages0)
    manifest["status"] = "running"
    live = _Live(model, lib_cb)

    def beat() -> None:
        manifest.update(live())
        run.write_manifest()
        if on_files is not None:
            on_files([run.manifest_path])

    if on_files is not None:
        run.after_checkpoint = lambda files: on_files([out / MONITOR, *files])
    manifest.update(live())
    if on_files is not None:  # where the run stands, before the first checkpoint
        run.write_manifest()
        on_files([run.manifest_path])
    close = (venv.close,) + ((library.close,) if library is not None else ())
    try:
        run.learn(timesteps, lib_cb, [bar, LiveCallback(beat), *(callbacks or [])],
                  checkpoint_every=config.checkpoint_every, close=close, on_interrupt=bar.close,
                  interrupted_status="interrupted", checkpoint_fields=live)
        _finish(run, live, library_path, envs)
    finally:  # the bar ends on the manifest's counts (those the CLI prints), or where the run stopped
        if manifest["status"] == "finished":
            bar.close(manifest["episodes"], manifest["garages_stored"])
        else:
            bar.close()
    if on_files is not None:
        on_files([out / FINAL_MODEL, run.manifest_path])
    return manifest


def _resumed_manifest(out: Path, map_name: str, seed: int, config: DQNConfig | None
                      ) -> tuple[dict[str, Any], DQNConfig]:
    """The manifest and config of the run in ``out``, which must be of ``map_name`` and ``seed``; a
    ``config`` given must be the run's own."""
    manifest = read_manifest(out)
    wanted = {"map": map_name, "seed": seed}
    refuse_other_settings(manifest, wanted, lambda diff: TrainingError(
        f"{out} is a run with {diff[0]} {manifest[diff[0]]!r}, not {wanted[diff[0]]!r}; pass the same --{diff[0]}"),
        keys=wanted)
    run_config = load_dqn_config(manifest["config"])
    if config is not None:
        refuse_other_settings(run_config.to_dict(), config.to_dict(), lambda diff: TrainingError(
            f"{out} was trained with another config; resume it without --config"))
    return manifest, run_config


def _new_manifest(out: Path, map: str, map_name: str, seed: int, config: DQNConfig | None, run_id: str | None
                  ) -> tuple[dict[str, Any], DQNConfig]:
    """A new run's manifest and config (default :class:`DQNConfig`); ``out`` must not hold a run yet."""
    if (out / MANIFEST).exists():
        raise TrainingError(f"{out} already holds a run; pass --resume to continue it or choose a new --out")
    config = config or load_dqn_config(learner=DEFAULT_LEARNER)
    manifest = {
        "run": run_id or new_run_id(map_name, seed, out),
        "map": map_name, "map_source": str(map), "seed": seed, "algo": "dqn", "config": config.to_dict(),
        "status": "running", "timesteps": 0, "episodes": 0,
    }
    return manifest, config


class _Live:
    """The manifest's ``live`` fields of the running run: timesteps, episodes, and timesteps/s since it (re)started."""

    def __init__(self, model: Any, counter: LibraryCallback) -> None:
        self.model, self.counter = model, counter
        self.steps0 = model.num_timesteps
        self.t0 = time.perf_counter()

    def __call__(self) -> dict[str, Any]:
        wall, steps = time.perf_counter() - self.t0, self.model.num_timesteps - self.steps0
        return {"live": {"timesteps": self.model.num_timesteps, "episodes": self.counter.episodes,
                         "timesteps_per_s": round(steps / wall, 1) if steps > 0 and wall > 0 else None,
                         "updated_at": datetime.now(timezone.utc).isoformat(timespec="seconds")}}


def _finish(run: DQNRun, live: _Live, library_path: Path | None, envs: list[StepTimer]) -> None:
    """Save ``final_model.zip`` and write the finished manifest, with this process's throughput in ``last_session``."""
    model, lib_cb, manifest = live.model, live.counter, run.manifest
    wall, cpu = run.wall_s, run.cpu_s
    model.save(run.out / FINAL_MODEL)
    steps = model.num_timesteps - live.steps0
    manifest.update(live())
    manifest.update(
        status="finished", timesteps=model.num_timesteps, episodes=lib_cb.episodes,
        garages_stored=None if library_path is None else _count_run(library_path, manifest["run"]),
        last_session={
            "timesteps": steps, "wall_s": round(wall, 3),
            "timesteps_per_s": round(steps / wall, 1) if wall > 0 else None,
            # CPU time of this process: the throughput figure that other jobs on the machine disturb least
            "cpu_s": round(cpu, 3), "timesteps_per_cpu_s": round(steps / cpu, 1) if cpu > 0 else None,
            "env_share": round(sum(e.seconds for e in envs) / wall, 4) if wall > 0 else None,
            "usable_episodes": lib_cb.usable, "garages_stored": lib_cb.stored,
        },
        returns=episode_returns(run.out / MONITOR),
    )
    run.write_manifest()


def episode_returns(monitor: Path, share: float = LEARNING_SHARE) -> dict[str, Any] | None:
    """What the run learned, from its episode log: the mean return of its first and last ``share`` of
    episodes (at least one each) and how many episodes that is; None without a finished episode."""
    try:
        lines = [ln for ln in monitor.read_text().splitlines() if ln and not ln.startswith("#")]
        returns = [float(ln.split(",")[0]) for ln in lines[1:]]
    except (OSError, ValueError):
        return None
    if not returns:
        return None
    n = max(1, round(share * len(returns)))
    return {"episodes": len(returns), "share": share, "window": n,
            "first_mean": round(sum(returns[:n]) / n, 3), "last_mean": round(sum(returns[-n:]) / n, 3)}
