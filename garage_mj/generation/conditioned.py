"""The difficulty-conditioned generator: train it, find it, load it.

:func:`train_conditioned` runs SB3 DQN on ``GarageGenCondEnv`` (the painter with a target band in
its observation), with the hyper-parameters of :class:`garage_mj.generation.training.DQNConfig` and the
band settings of :class:`~garage_mj.generation.cond_env.ConditionConfig`, through the resumable run of
:class:`garage_mj.generation.runs.DQNRun`; a config with ``vector_env`` (the ``fast`` learner: ``learner = "fast"``
in the TOML's ``[dqn]``) steps the envs in one :class:`~garage_mj.generation.vec_env.GarageGenVecEnv`, windows as
block codes, and trains with LeanDQN, as plain training does. The drawn bands cover the
map's admissible difficulty range as :func:`garage_mj.generation.search.search` estimates it. A run folder
holds ``run.json``, ``episodes.csv`` (target band and outcome of every episode), checkpoints
(``resume=True`` continues from the newest), ``generator.zip`` (the Q-network alone, a few hundred
KB: what ships in ``models/generators/``), saved whenever the share of the last
:data:`BEST_WINDOW` training episodes that landed in their band (plus a quarter of the share that
reached the exit) is the best of the run (DQN on
this task can fall back late in a run), and at the end ``generator.json`` (its settings and
training figures).

:func:`shipped_generator` finds the generator shipped for a map, :func:`train_for_map` trains one
for a map that has none (``garage-mj generate --map FILE``) and :func:`load_policy` reads one for
:func:`garage_mj.generation.generator.generate`.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import shutil
import time
from collections import deque
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor
from stable_baselines3.dqn.policies import DQNPolicy

from garage_mj.core.config import ConfigError, load_config, read_toml
from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import write_json
from garage_mj.core.model_file import ModelFileError, read_weights, write_weights
from garage_mj.generation.cond_env import N_COND, ConditionConfig, GarageGenCondEnv
from garage_mj.generation.runs import DQNRun
from garage_mj.generation.search import search
from garage_mj.generation.training import DEFAULT_LEARNER, DQNConfig, load_dqn_config
from garage_mj.generation.vec_env import GarageGenVecEnv
from garage_mj.generation.window_net import STATE_VALUES, OneHotWindow, WindowLayer
from garage_mj.grid.map_io import load_map

if TYPE_CHECKING:
    from garage_mj.generation.generator import GenerateResult

GENERATORS = "generators"  # folder of the shipped generators inside the package data garage_mj.models
RUN_MANIFEST = "run.json"
EPISODES = "episodes.csv"
GENERATOR = "generator.zip"  # the Q-network (policy) alone
GENERATOR_META = "generator.json"
SEARCH_EVALUATIONS = 10_000  # mutations of the search that estimates the admissible range
TRAIN_TIMESTEPS = 200_000  # default training budget of generate --map FILE (about 30 s on one core)
# the settings the shipped generators were trained with (generation/conditioned.toml's [dqn]: the fast
# learner), checkpointed more often
USER_MAP_LEARNER = "fast"
USER_MAP_DQN = {"checkpoint_every": 10000}
CURVE_POINTS = 20  # points of the training curve kept in generator.json
BEST_WINDOW = 200  # [episodes] the shipped policy is the one with the best score over this many
USABLE_WEIGHT = 0.25  # score = in-band share + USABLE_WEIGHT * usable share (reaching the exit counts too)
EPISODE_FIELDS = ("episode", "timestep", "d_lo", "d_hi", "c_lo", "c_hi", "usable", "difficulty", "coverage",
                  "in_band", "return", "length")


class GenerationError(GarageMJError):
    """``generate`` cannot run (no generator for the map, bad band) or did not fill the band.

    When the band was not filled, ``result`` holds the :class:`GenerateResult` of what was found.
    """

    result: GenerateResult | None = None


# -- config ---------------------------------------------------------------------------------------
def load_generator_config(path: str | Path | None, learner: str | None = None
                          ) -> tuple[DQNConfig, ConditionConfig, dict[str, int]]:
    """``[dqn]`` (DQNConfig), ``[condition]`` (ConditionConfig) and ``[timesteps]`` (per map) of a TOML file.

    ``[dqn]``'s ``learner`` key names the learner whose settings its other keys override
    (:data:`garage_mj.generation.training.LEARNERS`; the default learner, ``fast``, when absent, as for
    ``garage-mj train``); ``learner`` here replaces the file's.
    """
    if path is None:
        return load_dqn_config(learner=learner or DEFAULT_LEARNER), ConditionConfig(), {}
    data = read_toml(path)
    unknown = sorted(set(data) - {"dqn", "condition", "timesteps"})
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {unknown}; known: dqn, condition, timesteps")
    table = dict(data.get("dqn", {}))
    chosen = table.pop("learner", DEFAULT_LEARNER)
    if not isinstance(chosen, str):
        raise ConfigError(f"{path}: [dqn] learner must be a learner's name such as \"fast\", got {chosen!r}")
    try:
        dqn = load_dqn_config(table, learner=learner or chosen)
        cond = load_config(ConditionConfig, data.get("condition", {}))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    steps = data.get("timesteps", {})
    if not all(isinstance(v, int) and v > 0 for v in steps.values()):
        raise ConfigError(f"{path}: [timesteps] maps map names to positive integers")
    return dqn, cond, dict(steps)


# -- training -------------------------------------------------------------------------------------
class EpisodeLog(BaseCallback):
    """Appends the target band and outcome of every finished episode to ``episodes.csv``.

    Counts the run's episodes (from ``episodes`` on: a resumed run's past) and calls
    ``on_episodes(self)`` after each step in which episodes ended; :attr:`recent` holds
    (in band, usable) of the last :data:`BEST_WINDOW` episodes.
    """

    def __init__(self, path: Path, episodes: int, on_episodes: Callable[[EpisodeLog], None]) -> None:
        super().__init__()
        self.on_episodes = on_episodes
        self.episodes = episodes
        self.in_band = 0
        self.recent: deque[tuple[int, int]] = deque(maxlen=BEST_WINDOW)  # (in band, usable) of the latest
        new = not path.exists()
        self.file = open(path, "a", newline="")
        self.writer = csv.writer(self.file)
        if new:
            self.writer.writerow(EPISODE_FIELDS)

    def _on_step(self) -> bool:
        ended = False
        for done, info in zip(self.locals["dones"], self.locals["infos"]):
            if not done:
                continue
            ended = True
            self.recent.append((int(info["in_band"]), int(info["usable"])))
            ep = info.get("episode", {})
            (d_lo, d_hi), (c_lo, c_hi) = info["target_difficulty"], info["target_coverage"]
            self.in_band += info["in_band"]
            self.writer.writerow([self.episodes, self.num_timesteps, f"{d_lo:.4f}", f"{d_hi:.4f}",
                                  f"{c_lo:.4f}", f"{c_hi:.4f}", int(info["usable"]),
                                  f"{info['difficulty']:.4f}", f"{info['coverage']:.4f}", int(info["in_band"]),
                                  f"{ep.get('r', float('nan')):.2f}", ep.get("l", 0)])
            self.episodes += 1
        if ended:
            self.on_episodes(self)
        return True

    def flush(self) -> None:
        if not self.file.closed:
            self.file.flush()

    def _on_training_end(self) -> None:
        self.file.close()


class ConditionedProgress(BaseCallback):
    """A tqdm bar over the run's timesteps with episodes and in-band episodes."""

    def __init__(self, total: int, initial: int, name: str, log: EpisodeLog) -> None:
        super().__init__()
        self.total, self.initial, self.name, self.log = total, initial, name, log

    def _on_training_start(self) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=self.total, initial=self.initial, desc=f"{self.name} conditioned", unit="step",
                        dynamic_ncols=True)

    def _on_step(self) -> bool:
        if self.n_calls % 64 == 0:
            self.bar.update(self.num_timesteps - self.bar.n)
            self.bar.set_postfix(episodes=self.log.episodes, in_band=self.log.in_band, refresh=False)
        return True

    def _on_training_end(self) -> None:
        self.bar.update(self.num_timesteps - self.bar.n)
        self.bar.close()


def admissible_range(map: str, evaluations: int = SEARCH_EVALUATIONS, seed: int = 0) -> tuple[float, float]:
    """The difficulty range :func:`garage_mj.generation.search.search` reaches on ``map`` (a lower bound of the truth)."""
    return search(map, evaluations, seed=seed).range


def train_conditioned(map: str, timesteps: int, seed: int, out_dir: str | Path, dqn: DQNConfig | None = None,
                      condition: ConditionConfig | None = None, resume: bool = False, progress: bool = True,
                      search_evaluations: int = SEARCH_EVALUATIONS) -> dict[str, Any]:
    """Train a conditioned generator for ``map``; returns its ``generator.json`` record.

    Without a fixed range in ``condition`` (the default [0, 1]) the drawn difficulty bands
    cover the range search reaches on the map, widened by half a band at each end.
    """
    out = Path(out_dir)
    garage = load_map(map)
    if resume:
        try:
            manifest = json.loads((out / RUN_MANIFEST).read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            raise GenerationError(f"{out} holds no conditioned-generator run to resume") from None
        if manifest["map"] != garage.name or manifest["seed"] != seed:
            raise GenerationError(f"{out} is a run of map {manifest['map']} seed {manifest['seed']}; pass the same")
        dqn = load_dqn_config(manifest["dqn"])
        condition = load_config(ConditionConfig, manifest["condition"])
    else:
        if (out / RUN_MANIFEST).exists():
            raise GenerationError(f"{out} already holds a run; pass resume or choose a new folder")
        dqn, condition = dqn or DQNConfig(), condition or ConditionConfig()
        searched = None
        if (condition.difficulty_lo, condition.difficulty_hi) == (0.0, 1.0) and search_evaluations > 0:
            searched = admissible_range(map, search_evaluations)
            half = condition.band_width / 2
            condition = dataclasses.replace(condition, difficulty_lo=max(0.0, round(searched[0] - half, 3)),
                                            difficulty_hi=min(1.0, round(searched[1] + half, 3)))
        manifest = {"map": garage.name, "map_source": str(map), "seed": seed, "dqn": dqn.to_dict(),
                    "condition": dataclasses.asdict(condition), "searched_range": searched,
                    "search_evaluations": search_evaluations, "timesteps": 0, "episodes": 0, "wall_s": 0.0}
    run = DQNRun(out, manifest, RUN_MANIFEST, resume)
    run.restart_log(out / EPISODES, header_lines=1)
    manifest.update(target_timesteps=timesteps, status="running")

    env_kw = {"map": map, "view_size": dqn.view_size, "max_errors": dqn.max_errors, "condition": condition}
    if dqn.vector_env:  # windows as block codes, read by WindowLayer: 7 state values and the 5 band values after them
        venv = VecMonitor(GarageGenVecEnv(n_envs=dqn.n_envs, window="codes", env_cls=GarageGenCondEnv, **env_kw))
        model = run.start_model(venv, dqn, seed, extractor_kwargs={"state_values": STATE_VALUES + N_COND})
    else:
        venv = VecMonitor(DummyVecEnv([lambda: GarageGenCondEnv(**env_kw) for _ in range(dqn.n_envs)]))
        model = run.start_model(venv, dqn, seed)
    manifest.setdefault("best", {"score": -1.0, "timestep": 0, "episode": 0})

    def keep_best(log: EpisodeLog) -> None:
        """Save the policy as the generator when its score over the last BEST_WINDOW episodes is the best yet."""
        if len(log.recent) < BEST_WINDOW:
            return
        in_band = sum(b for b, _ in log.recent) / len(log.recent)
        usable = sum(u for _, u in log.recent) / len(log.recent)
        score = in_band + USABLE_WEIGHT * usable
        if score > manifest["best"].get("score", -1.0):
            save_policy(model.policy, out / GENERATOR)
            manifest["best"] = {"score": round(score, 4), "in_band": round(in_band, 4), "usable": round(usable, 4),
                                "timestep": model.num_timesteps, "episode": log.episodes}

    log = EpisodeLog(out / EPISODES, run.done_episodes, keep_best)
    wall0 = manifest.get("wall_s", 0.0)
    t0 = time.perf_counter()
    bar = [ConditionedProgress(timesteps, run.done_steps, garage.name, log)] if progress else []
    run.learn(timesteps, log, bar, checkpoint_every=dqn.checkpoint_every, close=(venv.close,),
              checkpoint_fields=lambda: {"wall_s": round(wall0 + time.perf_counter() - t0, 1)})
    run.save_checkpoint()
    if not (out / GENERATOR).exists():  # too few episodes to choose: the last policy
        save_policy(model.policy, out / GENERATOR)
        manifest["best"] = {"in_band": None, "timestep": model.num_timesteps, "episode": log.episodes}
    manifest["status"] = "finished"
    run.write_manifest()
    meta = {"map": garage.name, "seed": seed, "timesteps": model.num_timesteps, "episodes": log.episodes,
            "train_wall_s": manifest["wall_s"], "view_size": dqn.view_size, "max_errors": dqn.max_errors,
            "net_arch": list(dqn.net_arch), "dqn": dqn.to_dict(), "condition": manifest["condition"],
            "searched_range": manifest["searched_range"], "chosen": manifest["best"],
            "curve": training_curve(out / EPISODES)}
    write_json(out / GENERATOR_META, meta)
    return meta


def training_curve(episodes_csv: Path, points: int = CURVE_POINTS) -> list[dict[str, float]]:
    """Per consecutive chunk of episodes: timesteps, usable share, in-band share (of all and of usable)."""
    with open(episodes_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return []
    out = []
    for chunk in np.array_split(np.arange(len(rows)), min(points, len(rows))):
        rs = [rows[i] for i in chunk]
        usable = sum(int(r["usable"]) for r in rs)
        in_band = sum(int(r["in_band"]) for r in rs)
        out.append({"timestep": int(rs[-1]["timestep"]), "episodes": len(rs),
                    "usable": round(usable / len(rs), 3), "in_band": round(in_band / len(rs), 3),
                    "in_band_of_usable": round(in_band / usable, 3) if usable else 0.0,
                    "mean_return": round(float(np.mean([float(r["return"]) for r in rs])), 2)})
    return out



# -- the trained generators ---------------------------------------------------------------------
def shipped_generator(map_name: str) -> Path | None:
    """The shipped generator of a shipped map, if there is one."""
    path = Path(str(resources.files("garage_mj.models").joinpath(GENERATORS, f"{map_name}.zip")))
    return path if path.is_file() else None


def default_model_out(library: str | Path, map_name: str) -> Path:
    """Where ``generate --map FILE`` keeps the generator it trains: next to the library."""
    lib = Path(library)
    return lib.with_name(f"{lib.stem}.{map_name}.generator.zip")


def train_for_map(map: str, model_out: str | Path, timesteps: int = TRAIN_TIMESTEPS, seed: int = 0,
                  progress: bool = True, search_evaluations: int = SEARCH_EVALUATIONS,
                  dqn: DQNConfig | None = None) -> tuple[Path, float | None]:
    """A generator for ``map`` at ``model_out``: reused when the file exists, else trained.

    Trains with :func:`train_conditioned` (the shipped generators' DQN settings unless ``dqn``)
    in a run folder next to ``model_out`` (``<model_out>.run``, resumed if a run was cut off,
    removed once the generator is saved), then writes ``model_out`` and its ``.json``. Returns
    the path and the training wall time in seconds (None when reused).
    """
    out = Path(model_out)
    if out.is_file():
        return out, None
    if out.suffix != ".zip":
        raise GenerationError(f"--model-out {out}: a generator file name ends in .zip")
    run_dir = out.with_name(out.name + ".run")
    resume = (run_dir / RUN_MANIFEST).exists()
    t0 = time.perf_counter()
    try:
        train_conditioned(map, timesteps, seed, run_dir, dqn=dqn or load_dqn_config(USER_MAP_DQN, learner=USER_MAP_LEARNER), resume=resume,
                          progress=progress, search_evaluations=search_evaluations)
    except GenerationError as exc:
        raise GenerationError(f"{exc} (remove {run_dir} to start over)") from None
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(run_dir / GENERATOR_META, out.with_suffix(".json"))
    shutil.copyfile(run_dir / GENERATOR, out.with_name(out.name + ".tmp"))
    os.replace(out.with_name(out.name + ".tmp"), out)
    shutil.rmtree(run_dir, ignore_errors=True)
    return out, time.perf_counter() - t0


def train_command(map: str) -> str:
    stem = Path(map).stem
    return (f"garage-mj generate --map {map} ... (trains one first, {TRAIN_TIMESTEPS:,} timesteps), or train_for_map; "
            f"or .venv/bin/python generation/train_conditioned.py --map {map} --timesteps {TRAIN_TIMESTEPS} --out "
            f"runs/generator_{stem} (about 10 s per 100,000 timesteps on one core with the fast learner, plus "
            f"~10 s to search the map's difficulty range), then pass --model runs/generator_{stem}/{GENERATOR}; "
            f"or try a shipped "
            f"generator on it (a generator sees only a window around the car, so it runs on any map), e.g. "
            f"--model m4_13x13_offset")


#: The first layers a generator's Q-network may start with, by the name its file records.
_EXTRACTORS = {cls.__name__: cls for cls in (FlattenExtractor, WindowLayer, OneHotWindow)}
POLICY_FORMAT = "garage-mj generator policy 1"  # the ``format`` field of a generator file


def save_policy(policy: DQNPolicy, path: Path) -> None:
    """The generator ``policy`` to ``path`` (atomically) as weights and plain fields only (:func:`load_policy`)."""
    import torch

    params = policy._get_constructor_parameters()
    space = policy.observation_space
    extractor_kwargs = dict(params.get("features_extractor_kwargs") or {})
    write_weights({"format": POLICY_FORMAT, "state_dict": policy.state_dict(),
                   "observation_low": torch.as_tensor(space.low), "observation_high": torch.as_tensor(space.high),
                   "n_actions": int(policy.action_space.n), "net_arch": [int(w) for w in params["net_arch"]],
                   "features_extractor": params["features_extractor_class"].__name__,
                   "features_extractor_kwargs": {k: int(v) for k, v in extractor_kwargs.items()}}, path)


def _policy_from(payload: Any) -> DQNPolicy:
    """The Q-network policy a :func:`save_policy` payload describes, its weights in place; ``ValueError`` (one
    line) for any other payload."""
    import torch
    from gymnasium import spaces

    if not isinstance(payload, dict) or payload.get("format") != POLICY_FORMAT:
        raise ValueError(f"it is not a {POLICY_FORMAT!r} file")
    low, high, n = payload.get("observation_low"), payload.get("observation_high"), payload.get("n_actions")
    arch, name = payload.get("net_arch"), payload.get("features_extractor")
    kwargs, state = payload.get("features_extractor_kwargs"), payload.get("state_dict")
    if not (isinstance(low, torch.Tensor) and isinstance(high, torch.Tensor) and low.shape == high.shape
            and low.dim() == 1 and 0 < low.numel() <= 100_000):
        raise ValueError("its observation bounds are not two vectors of one size")
    if not (type(n) is int and 1 <= n <= 64) or not (isinstance(arch, list) and len(arch) <= 16 and all(
            type(w) is int and 1 <= w <= 4_096 for w in arch)):
        raise ValueError("its actions or hidden layers are not small positive integers")
    if name not in _EXTRACTORS or not isinstance(kwargs, dict) or not set(kwargs) <= {"width", "state_values"} or \
            not all(type(v) is int and 1 <= v <= 4_096 for v in kwargs.values()):
        raise ValueError(f"its first layer {str(name)[:40]!r} is not one of {', '.join(_EXTRACTORS)}")
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise ValueError("its state_dict is not a table of tensors")
    if not all(bool(torch.isfinite(v).all()) for v in state.values() if v.is_floating_point()):
        raise ValueError("a weight is NaN or infinite")
    space = spaces.Box(low.numpy(), high.numpy(), dtype=np.float32)
    policy = DQNPolicy(space, spaces.Discrete(n), lambda _: 0.0, net_arch=arch,
                       features_extractor_class=_EXTRACTORS[name], features_extractor_kwargs=kwargs)
    try:
        policy.load_state_dict(state)
    except RuntimeError as exc:
        raise ValueError(f"its weights do not fit its network ({' '.join(str(exc).split())[:120]})") from None
    return policy


def load_policy(path: Path) -> DQNPolicy:
    """The Q-network policy saved at ``path`` by :func:`save_policy` (a ``generator.zip``), read as data
    (:func:`~garage_mj.core.model_file.read_weights`: tensors and plain fields, nothing in it run);
    :class:`GenerationError` in one line if it is not one."""
    try:
        policy = _policy_from(read_weights(path))
    except (ModelFileError, ValueError) as exc:
        raise GenerationError(f"{path} is not a generator saved by garage-mj: {exc}; pass a generator.zip from "
                              "generation/train_conditioned.py (or remove it, and garage-mj generate --map trains a "
                              "new one)") from None
    except OSError as exc:
        raise GenerationError(f"{path} cannot be read ({exc.strerror or type(exc).__name__})") from None
    policy.set_training_mode(False)
    return policy


__all__ = ["GenerationError", "admissible_range", "default_model_out", "load_generator_config", "load_policy", "save_policy",
           "shipped_generator", "train_command", "train_conditioned", "train_for_map", "training_curve"]
