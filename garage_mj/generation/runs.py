"""The lifecycle every resumable DQN run shares: run folder, checkpoints, resume, Ctrl-C.

Plain training (:func:`garage_mj.generation.training.train`) and the conditioned generator
(:func:`garage_mj.generation.conditioned.train_conditioned`) run stable-baselines3 DQN the same way,
through :class:`DQNRun`:

- a run folder with a manifest (``run.json``) and ``checkpoints/step_<timesteps>.zip`` + ``.json``
  (the model and its timestep/episode counters, each written atomically; the newest
  :data:`KEEP_CHECKPOINTS` are kept);
- on resume, the newest complete checkpoint: the model is loaded from it and re-seeded with
  ``seed + timesteps`` (a fresh, reproducible stream), the episode log is cut back to its episodes;
  a new run builds the model with ``seed``;
- a checkpoint every ``checkpoint_every`` timesteps, and one on Ctrl-C before the interrupt goes on;
  :attr:`DQNRun.after_checkpoint`, when set, gets the files each checkpoint wrote (a run trained on
  another machine sends them to the machine that keeps the run, :mod:`garage_mj.generation.remote`).

What differs between the two (the manifest's fields, the env, the callbacks, what is saved at the
end) stays with the caller.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import torch
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.vec_env import VecEnv

from garage_mj.core.fsutil import write_json
from garage_mj.core.model_file import (
    ModelFileError,
    Rebuild,
    load_replay_buffer,
    load_sb3,
    policy_class,
    rebuilds,
    save_replay_buffer,
    sb3_settings,
)
from garage_mj.generation.lean_dqn import LeanDQN

if TYPE_CHECKING:
    from garage_mj.generation.training import DQNConfig

CHECKPOINTS = "checkpoints"
KEEP_CHECKPOINTS = 2  # older checkpoints are deleted


class EpisodeCounter(Protocol):
    """The callback that counts a run's finished episodes (checkpoints record its count)."""

    episodes: int

    def flush(self) -> None:
        """Put what it logged so far on disk (called before each checkpoint)."""


def latest_checkpoint(out_dir: Path) -> tuple[Path, dict[str, Any]] | None:
    """The newest complete checkpoint (model zip + counters) of a run folder, if any.

    Safe while the run trains (``--status`` from another shell, a watcher): a checkpoint that the run prunes
    between the listing and the reading is passed over.
    """
    best = None
    for state_path in (out_dir / CHECKPOINTS).glob("step_*.json"):
        model = state_path.with_suffix(".zip")
        if not model.exists():
            continue
        try:
            state = json.loads(state_path.read_text())
        except FileNotFoundError:
            continue  # pruned by the running training since the listing: a newer one exists
        except (ValueError, RecursionError):
            continue  # a torn or foreign checkpoint record: an older one is used
        if not isinstance(state, dict) or not isinstance(state.get("timesteps"), int):
            continue  # a foreign record: check_counters refuses a forged one that names a number
        if best is None or state["timesteps"] > best[1]["timesteps"]:
            best = (model, state)
    return best


def unresumable(model: Path, exc: ModelFileError) -> ModelFileError:
    """The one line for a checkpoint model file that is not read as data: what is wrong and the fix."""
    return ModelFileError(f"checkpoint {model} cannot be resumed: {exc}; remove it to resume from the one before, "
                          "or start a new run in another folder")


def check_counters(model: Path, state: dict[str, Any]) -> None:
    """Refuse a checkpoint whose counters (``step_N.json``) are not the model's own: ``timesteps`` must be the
    model zip's ``num_timesteps`` and ``episodes`` a count no larger (each episode takes a timestep)."""
    steps, episodes = state.get("timesteps"), state.get("episodes")
    try:
        saved = sb3_settings(model).get("num_timesteps")
    except ModelFileError as exc:
        raise unresumable(model, exc) from None
    ints = all(isinstance(v, int) and not isinstance(v, bool) for v in (steps, episodes, saved))
    if not ints or steps != saved or not 0 <= episodes <= steps:
        raise ModelFileError(f"checkpoint {model.with_suffix('.json')} says {steps!r} timesteps and {episodes!r} "
                             f"episodes, but its model has trained {saved!r} timesteps; remove both files to resume "
                             "from the checkpoint before, or start a new run in another folder")


def checkpoint_files(out_dir: Path) -> list[Path]:
    """The files of the newest complete checkpoint of a run folder (model, replay buffer if saved, counters)."""
    found = latest_checkpoint(out_dir)
    if found is None:
        return []
    model = found[0]
    replay = replay_path(model)
    return [model, *([replay] if replay.exists() else []), model.with_suffix(".json")]


def replay_path(checkpoint: Path) -> Path:
    """Where the replay buffer of the checkpoint ``step_N.zip`` (or its stem) is kept: ``step_N_replay.npz``."""
    return checkpoint.with_name(checkpoint.with_suffix("").name + "_replay.npz")


def prune_checkpoints(out_dir: Path) -> None:
    """Delete all but the newest :data:`KEEP_CHECKPOINTS` checkpoints of a run folder."""
    states = sorted((out_dir / CHECKPOINTS).glob("step_*.json"))
    for old in states[:-KEEP_CHECKPOINTS]:
        for path in (old, old.with_suffix(".zip"), replay_path(old)):
            path.unlink(missing_ok=True)


def truncate_log(path: Path, header_lines: int, rows: int) -> None:
    """Keep the first ``header_lines`` lines of a log and its first ``rows`` rows (a checkpoint's past)."""
    if not path.exists():
        return
    lines = path.read_text().splitlines(keepends=True)
    keep = lines[: header_lines + rows]
    if len(keep) != len(lines):
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text("".join(keep))
        os.replace(tmp, path)


def _policy_kwargs(config: DQNConfig, extractor_kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """The policy kwargs a run of ``config`` builds its Q-network with (:meth:`DQNRun.start_model`)."""
    kwargs = config.dqn_kwargs()["policy_kwargs"]
    if extractor_kwargs and config.vector_env:
        kwargs["features_extractor_kwargs"].update(extractor_kwargs)
    return kwargs


def run_rebuilds(config: DQNConfig, extractor_kwargs: dict[str, Any] | None = None) -> dict[str, Rebuild]:
    """How each pickled entry of a run's model zip is made again: from the run's own ``config`` (the policy,
    its network, the train frequency) and the env it is loaded on (the observation space), never unpickled
    (:mod:`garage_mj.core.model_file`). A zip whose plain fields describe another network is refused."""
    from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

    policy_kwargs = _policy_kwargs(config, extractor_kwargs)

    def network(entry: dict, data: dict, algo: type, env: Any) -> Any:
        extractor = policy_kwargs.get("features_extractor_class")
        named = str(entry.get("features_extractor_class", ""))
        if str(entry.get("net_arch")) != str(policy_kwargs["net_arch"]) or (
                extractor is not None and f".{extractor.__name__}'" not in named):
            raise ModelFileError(f"its network (net_arch {str(entry.get('net_arch'))[:40]}, {named[:80]}) is not "
                                 f"the one its run's config builds (net_arch {policy_kwargs['net_arch']})")
        return policy_kwargs

    def observations(entry: dict, data: dict, algo: type, env: Any) -> Any:
        space = env.observation_space if env is not None else box_from_fields(entry)
        if entry.get("_shape") != list(space.shape) or entry.get("dtype") != str(space.dtype):
            raise ModelFileError(f"its observations are {entry.get('dtype')}{entry.get('_shape')}, the env's "
                                 f"{space.dtype}{list(space.shape)}")
        return space

    def train_freq(entry: dict, data: dict, algo: type, env: Any) -> Any:
        return TrainFreq(config.train_freq, TrainFrequencyUnit.STEP)

    return rebuilds(Rebuild("policy_class", policy_class(lambda algo: algo.policy_aliases["MlpPolicy"],
                                                         "DQN's MlpPolicy (a garage-mj training run's)")),
                    Rebuild("policy_kwargs", network), Rebuild("observation_space", observations),
                    Rebuild("train_freq", train_freq))


def box_from_fields(entry: dict) -> Any:
    """The ``Box`` whose plain fields (``low``, ``high``, ``_shape``, ``dtype`` as SB3 writes them) ``entry`` holds."""
    import numpy as np
    from gymnasium import spaces

    try:
        shape = tuple(int(n) for n in entry["_shape"])
        dtype = np.dtype(str(entry["dtype"]))
        low, high = (np.array(str(entry[k]).strip("[]").split(), dtype=dtype) for k in ("low", "high"))
        return spaces.Box(low.reshape(shape), high.reshape(shape), dtype=dtype)
    except (KeyError, TypeError, ValueError):
        raise ModelFileError("its observation space has no plain low, high and shape (pass the env)") from None


def load_dqn(path: str | Path, config: DQNConfig, env: Any = None, extractor_kwargs: dict[str, Any] | None = None,
             **kwargs: Any) -> DQN:
    """The model zip of a run trained with ``config`` (a checkpoint or ``final_model.zip``), as
    :class:`~garage_mj.generation.lean_dqn.LeanDQN` when the config trains on the vector env, else SB3's DQN,
    on ``env`` (None: observation space from the file's plain fields); read as data (:func:`run_rebuilds`).
    ``extractor_kwargs``: those the run gave its first layer (:meth:`DQNRun.start_model`)."""
    algo = LeanDQN if config.vector_env else DQN
    return load_sb3(path, algo, run_rebuilds(config, extractor_kwargs), env=env, **kwargs)


class CheckpointEvery(BaseCallback):
    """Saves a checkpoint every ``every`` timesteps through ``save`` (:meth:`DQNRun.save_checkpoint`)."""

    def __init__(self, every: int, save: Callable[[], None]) -> None:
        super().__init__()
        self.every, self.save = every, save
        self.last = 0

    def _on_training_start(self) -> None:
        self.last = self.num_timesteps // self.every

    def _on_step(self) -> bool:
        # with n_envs > 1 the count moves n_envs at a time: save on crossing each multiple
        if self.num_timesteps // self.every > self.last:
            self.last = self.num_timesteps // self.every
            self.save()
        return True


class DQNRun:
    """One resumable DQN run in the folder ``out`` (module docstring).

    Creating it makes the folder and finds the checkpoint to resume from (when ``resume``):
    :attr:`checkpoint`, :attr:`done_steps`, :attr:`done_episodes`. Then: :meth:`restart_log`,
    :meth:`start_model`, :meth:`learn`.

    Args:
        out: the run folder (created, with ``checkpoints/``).
        manifest: the run's manifest; every checkpoint sets its ``timesteps`` and ``episodes`` and
            writes it to ``out / manifest_name``.
        manifest_name: the manifest's file name.
        resume: continue from the newest checkpoint of ``out``, if it has one.
    """

    def __init__(self, out: Path, manifest: dict[str, Any], manifest_name: str, resume: bool) -> None:
        self.out, self.manifest, self.manifest_path = out, manifest, out / manifest_name
        out.mkdir(parents=True, exist_ok=True)
        (out / CHECKPOINTS).mkdir(exist_ok=True)
        self.checkpoint = latest_checkpoint(out) if resume else None
        if self.checkpoint:
            check_counters(*self.checkpoint)
        state = self.checkpoint[1] if self.checkpoint else {"timesteps": 0, "episodes": 0}
        self.done_steps: int = state["timesteps"]
        self.done_episodes: int = state["episodes"]
        self.model: DQN | None = None
        self.counter: EpisodeCounter | None = None
        self.checkpoint_fields: Callable[[], dict[str, Any]] | None = None
        self.save_replay_buffer = False
        #: called with the files each checkpoint wrote (model, replay buffer, counters, manifest), in that order
        self.after_checkpoint: Callable[[list[Path]], None] | None = None
        self.wall_s = self.cpu_s = 0.0  # of the last learn()

    def write_manifest(self) -> None:
        write_json(self.manifest_path, self.manifest)

    def restart_log(self, path: Path, header_lines: int) -> None:
        """Cut the episode log ``path`` back to the checkpoint's episodes; a run without one starts it anew."""
        if self.checkpoint:
            truncate_log(path, header_lines, self.done_episodes)
        else:
            path.unlink(missing_ok=True)

    def start_model(self, venv: VecEnv, config: DQNConfig, seed: int, save_replay_buffer: bool = False,
                    extractor_kwargs: dict[str, Any] | None = None) -> DQN:
        """The run's model on ``venv``: the checkpoint's (with its replay buffer, when one was saved), re-seeded
        with ``seed + timesteps``, or a new ``MlpPolicy`` DQN seeded with ``seed``. A config on the vector env
        trains with :class:`~garage_mj.generation.lean_dqn.LeanDQN` (the same results, less overhead per step).

        ``save_replay_buffer``: checkpoints also save the replay buffer. ``extractor_kwargs``: more keyword
        arguments of a vector-env config's first layer (:class:`~garage_mj.generation.window_net.WindowLayer`),
        e.g. ``state_values`` for an env with more values after the window; a checkpoint keeps its own.
        """
        torch.set_num_threads(config.torch_threads)
        algo = LeanDQN if config.vector_env else DQN
        self.save_replay_buffer = save_replay_buffer
        if self.checkpoint:
            path = self.checkpoint[0]
            try:
                model = load_dqn(path, config, env=venv, extractor_kwargs=extractor_kwargs, device=config.device)
                buffer = replay_path(path)
                if buffer.exists():
                    load_replay_buffer(model.replay_buffer, buffer)
            except ModelFileError as exc:
                raise unresumable(path, exc) from None
            model.set_random_seed(seed + self.done_steps)  # a fresh, reproducible stream after the checkpoint
        else:
            kwargs = config.dqn_kwargs()
            kwargs["policy_kwargs"] = _policy_kwargs(config, extractor_kwargs)
            model = algo("MlpPolicy", venv, seed=seed, device=config.device, verbose=0, **kwargs)
        self.model = model
        return model

    def save_checkpoint(self) -> None:
        """The model (and replay buffer) and the counters at ``checkpoints/step_<timesteps>``; then the manifest."""
        assert self.model is not None and self.counter is not None, "save_checkpoint() before learn()"
        self.counter.flush()
        model = self.model
        step = model.num_timesteps
        stem = self.out / CHECKPOINTS / f"step_{step:09d}"
        tmp = stem.with_name(stem.name + ".tmp.zip")
        model.save(tmp)
        os.replace(tmp, stem.with_suffix(".zip"))
        files = [stem.with_suffix(".zip")]
        if self.save_replay_buffer:
            save_replay_buffer(model.replay_buffer, replay_path(stem))
            files.append(replay_path(stem))
        write_json(stem.with_suffix(".json"), {"timesteps": step, "episodes": self.counter.episodes})
        prune_checkpoints(self.out)
        self.manifest.update(timesteps=step, episodes=self.counter.episodes)
        if self.checkpoint_fields is not None:
            self.manifest.update(self.checkpoint_fields())
        self.write_manifest()
        if self.after_checkpoint is not None:
            self.after_checkpoint([*files, stem.with_suffix(".json"), self.manifest_path])

    def learn(self, timesteps: int, counter: EpisodeCounter, callbacks: Sequence[BaseCallback], *,
              checkpoint_every: int, close: Sequence[Callable[[], None]] = (),
              on_interrupt: Callable[[], None] | None = None, interrupted_status: str | None = None,
              checkpoint_fields: Callable[[], dict[str, Any]] | None = None) -> None:
        """Write the manifest, then learn until the run has ``timesteps`` in all.

        The callbacks run in this order: ``counter`` (which counts the episodes), a checkpoint every
        ``checkpoint_every`` timesteps, ``callbacks``. Each checkpoint, from here on, also sets the
        manifest fields ``checkpoint_fields()`` returns (e.g. the wall time so far). On Ctrl-C:
        ``on_interrupt``, a checkpoint, the manifest's status set to ``interrupted_status`` (unless
        None), and the interrupt goes on. Whatever happens, :attr:`wall_s` and :attr:`cpu_s` get the
        time spent and the ``close`` functions are called.
        """
        assert self.model is not None, "learn() before start_model()"
        self.counter, self.checkpoint_fields = counter, checkpoint_fields
        cbs = [counter, CheckpointEvery(checkpoint_every, self.save_checkpoint), *callbacks]
        self.write_manifest()
        t0, cpu0 = time.perf_counter(), time.process_time()
        try:
            if timesteps > self.done_steps:
                self.model.learn(total_timesteps=timesteps - self.done_steps, callback=CallbackList(cbs),
                                 reset_num_timesteps=not self.checkpoint)
        except KeyboardInterrupt:
            if on_interrupt is not None:
                on_interrupt()
            self.save_checkpoint()
            if interrupted_status is not None:
                self.manifest["status"] = interrupted_status
                self.write_manifest()
            raise
        finally:
            self.wall_s, self.cpu_s = time.perf_counter() - t0, time.process_time() - cpu0
            for fn in close:
                fn()
