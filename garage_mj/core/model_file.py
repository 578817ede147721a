"""The one door through which every model file is read: weights and plain fields, nothing in it run.

Every model, policy, checkpoint, replay buffer and generator file garage-mj reads goes through this
module, and no other module calls ``pickle.load``, ``torch.load``, an SB3 ``load`` or
``load_from_zip_file`` (``tests/test_model_files.py`` walks the package to keep it so). A file handed
on by someone else is data: a crafted one is refused in one line, it never runs its own code.

- **SB3 model zips** (a learned driver, a training checkpoint, ``final_model.zip``): ``data`` holds
  JSON settings and ``.pth`` files hold ``torch.save`` weights. SB3 pickles (cloudpickle) each setting
  JSON cannot hold, such as the policy class, the spaces and the schedules, as a ``":serialized:"``
  entry of ``data``, and ``SB3.load`` would unpickle it. :func:`load_sb3` unpickles none of them: the
  caller's table of :class:`Rebuild` makes each such entry again from the plain fields SB3 writes beside
  the pickle, or from what the caller knows (a run's own config, the env it resumes on); a key the table
  does not list refuses the file. SB3 gets them as ``custom_objects``, so it never unpickles that entry.
  The ``.pth`` files are read by ``torch.load(weights_only=True)`` (tensors and plain containers only),
  here first, then by SB3 (which uses ``weights_only=True`` too), from the same bytes read once.
  The stage that owns a kind of model keeps its table (the learned driver's in
  :mod:`garage_mj.driving.learning.saved_model`, a DQN run's in :mod:`garage_mj.generation.runs`);
  :data:`COMMON` holds the entries every table shares.
- **Weights files** (a generator policy): :func:`read_weights` is ``torch.load(weights_only=True)``;
  the caller rebuilds its network from the plain fields beside the tensors.
- **Replay buffers**: :func:`save_replay_buffer` writes the buffer's arrays to an ``.npz`` and
  :func:`load_replay_buffer` reads them back with ``allow_pickle=False``.

Every refusal is a :class:`ModelFileError` (one line, without the file name: the caller names it).
torch and SB3 are imported when a model is loaded.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from garage_mj.core.errors import GarageMJError

SERIALIZED = ":serialized:"  # the key SB3 gives a pickled entry of ``data``
_NUMBER = r"[-+0-9.eEinfa]+"


class ModelFileError(GarageMJError, ValueError):
    """A model file that is not read as data; the message says what is wrong (one line, no file name)."""


def _float(value: Any, what: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ModelFileError(f"its {what} is {str(value)[:60]!r}, not a number") from None
    if not math.isfinite(x):
        raise ModelFileError(f"its {what} is {x}, not a finite number")
    return x


#: ``build(entry, data, algo, env)``: the value of a pickled ``data`` entry, made from ``entry``'s plain
#: fields, the whole ``data``, the SB3 class being loaded and the env it is loaded on (None without one).
Build = Callable[[dict, dict, type, Any], Any]


@dataclass(frozen=True)
class Rebuild:
    """How one pickled entry of a model zip's ``data`` is made from plain fields instead of unpickled."""

    key: str
    build: Build


def rebuilds(*items: Rebuild) -> dict[str, Rebuild]:
    """A table of :class:`Rebuild` by key: :data:`COMMON` and then ``items`` (which replace a common key)."""
    return {**COMMON, **{r.key: r for r in items}}


def policy_class(pick: Callable[[type], type], what: str) -> Build:
    """A :class:`Build` for ``policy_class``: the class ``pick(algo)``, if the entry's plain fields name it
    (its module and its ``__init__``); ``what`` names it in the refusal."""

    def build(entry: dict, data: dict, algo: type, env: Any) -> Any:
        cls = pick(algo)
        if entry.get("__module__") != cls.__module__ or f" {cls.__name__}.__init__ " not in str(entry.get("__init__")):
            raise ModelFileError(f"its policy is not {what}")
        return cls

    return build


def discrete_space(entry: dict, data: dict, algo: type, env: Any) -> Any:
    """The ``Discrete(n, start)`` space whose plain fields the entry holds."""
    from gymnasium import spaces

    try:
        n, start = int(entry["n"]), int(entry.get("start", 0))
    except (KeyError, TypeError, ValueError):
        raise ModelFileError("its action space has no plain n (a Discrete space's)") from None
    if "Discrete" not in str(entry.get(":type:")) or entry.get("dtype") != "int64" or not 1 <= n <= 1_000_000:
        raise ModelFileError(f"its action space is {str(entry.get(':type:'))[:60]}, not Discrete(n)")
    return spaces.Discrete(n, start=start)


def schedule(entry: dict, data: dict, algo: type, env: Any) -> Any:
    """A constant or linear schedule from its plain fields."""
    from stable_baselines3.common.utils import FloatSchedule, LinearSchedule

    if {"start", "end", "end_fraction"} <= set(entry):
        return LinearSchedule(*(_float(entry[k], f"schedule's {k}") for k in ("start", "end", "end_fraction")))
    constant = re.fullmatch(rf"ConstantSchedule\(val=({_NUMBER})\)", str(entry.get("value_schedule")))
    if constant is None:
        raise ModelFileError(f"its schedule {str(entry.get('value_schedule'))[:60]!r} is neither constant nor linear")
    return FloatSchedule(_float(constant.group(1), "schedule's value"))


def nothing(entry: dict, data: dict, algo: type, env: Any) -> Any:
    """None: a setting SB3 makes again itself (the replay buffer class, from ``n_steps``) or training state
    (the last observation, episode buffers) that a loaded model starts afresh."""
    return None


#: The pickled entries every SB3 model zip may hold and every table rebuilds the same way.
COMMON: dict[str, Rebuild] = {r.key: r for r in (
    Rebuild("action_space", discrete_space),
    Rebuild("lr_schedule", schedule),
    Rebuild("exploration_schedule", schedule),
    Rebuild("clip_range", schedule),
    Rebuild("clip_range_vf", schedule),
    Rebuild("replay_buffer_class", nothing),  # None: SB3 picks ReplayBuffer, NStepReplayBuffer or DictReplayBuffer
    Rebuild("rollout_buffer_class", nothing),
    *(Rebuild(key, nothing) for key in ("_last_obs", "_last_original_obs", "_last_episode_starts",
                                         "ep_info_buffer", "ep_success_buffer")),  # training state
)}


def plain_objects(data: dict, algo: type, table: Mapping[str, Rebuild], env: Any = None) -> dict[str, Any]:
    """``custom_objects`` for ``algo.load``: every pickled entry of ``data`` rebuilt by ``table``."""
    custom = {}
    for key, entry in data.items():
        if isinstance(entry, dict) and SERIALIZED in entry:
            if key not in table:
                raise ModelFileError(f"its data entry {key[:60]!r} is pickled Python, which a model file may not hold")
            custom[key] = table[key].build(entry, data, algo, env)
    return custom


def _weights(raw: bytes, what: str) -> Any:
    """``torch.load(weights_only=True)`` of ``raw``: tensors and plain containers, or :class:`ModelFileError`."""
    import pickle

    import torch

    try:
        return torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:  # torch's text advises weights_only=False: never relayed
        raise ModelFileError(f"{what} holds more than weights (Python objects to rebuild)") from None
    except Exception as exc:  # noqa: BLE001 - a damaged file in any way: one line
        raise ModelFileError(f"{what} is not readable weights ({type(exc).__name__})") from None


def read_sb3_data(raw: bytes) -> dict:
    """The plain ``data`` entry of an SB3 model zip's bytes (nothing unpickled)."""
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as archive:
            text = archive.read("data")
    except KeyError:
        raise ModelFileError("it has no data entry (not a stable-baselines3 model zip)") from None
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
        raise ModelFileError(f"it is not a readable zip ({type(exc).__name__})") from None
    try:
        data = json.loads(text)
    except (ValueError, RecursionError):
        raise ModelFileError("its data entry is not JSON") from None
    if not isinstance(data, dict):
        raise ModelFileError("its data entry is not a JSON object")
    return data


def sb3_settings(path: str | Path) -> dict:
    """The plain settings of the SB3 model zip at ``path`` (``num_timesteps``, ...), nothing unpickled; the
    pickled entries stay as SB3 wrote them (their plain fields beside an unread ``:serialized:``)."""
    return read_sb3_data(Path(path).read_bytes())


def load_sb3(path: str | Path, algo: type, table: Mapping[str, Rebuild], env: Any = None,
             policy_kwargs: Mapping[str, Any] | None = None, **kwargs: Any) -> Any:
    """``algo.load`` of the model zip at ``path`` (``device="cpu"`` unless given; ``env`` and ``kwargs`` passed
    on), every pickled entry rebuilt by ``table`` and nothing in the file unpickled; ``policy_kwargs`` are set over
    the file's own (an optimizer class, say).

    Raises :class:`ModelFileError` (one line, without the file name) when the file is not a zip, holds a
    pickled entry ``table`` does not list or whose plain fields do not match, weights that are not plain
    tensors, or weights that do not fit the network the settings describe; ``OSError`` of a missing or
    unreadable file passes through.
    """
    raw = Path(path).read_bytes()  # read once: what is checked is what SB3 loads
    data = read_sb3_data(raw)
    custom = plain_objects(data, algo, table, env)
    if policy_kwargs:
        own = custom.get("policy_kwargs", data.get("policy_kwargs"))
        custom["policy_kwargs"] = {**(own if isinstance(own, dict) else {}), **policy_kwargs}
    with zipfile.ZipFile(io.BytesIO(raw)) as archive:
        for name in archive.namelist():
            if name.endswith(".pth"):
                _weights(archive.read(name), f"its {name[:60]}")
    kwargs.setdefault("device", "cpu")
    try:
        return algo.load(io.BytesIO(raw), env=env, custom_objects=custom, **kwargs)
    except ModelFileError:
        raise
    except (RuntimeError, ValueError, KeyError, TypeError, AssertionError) as exc:  # weights of another network
        text = " ".join(str(exc).split())
        raise ModelFileError(f"its weights do not fit the network its settings describe ({text[:160]})") from None


def read_weights(path: str | Path) -> Any:
    """The tensors and plain containers ``torch.save`` wrote to ``path`` (``weights_only=True``)."""
    return _weights(Path(path).read_bytes(), "it")


def write_weights(payload: Any, path: str | Path) -> None:
    """``torch.save(payload)`` to ``path`` atomically (a temporary file beside it, then renamed); ``payload``
    holds tensors and plain containers only, so that :func:`read_weights` reads it back."""
    import torch

    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)


#: The arrays of an SB3 replay buffer that a checkpoint keeps, and its two counters.
_BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def save_replay_buffer(buffer: Any, path: str | Path) -> None:
    """The replay buffer's arrays and position to ``path`` (``.npz``, atomically): data, no pickled object."""
    import numpy as np

    path = Path(path)
    arrays = {name: getattr(buffer, name) for name in _BUFFER_ARRAYS if getattr(buffer, name, None) is not None}
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        np.savez(f, pos=np.int64(buffer.pos), full=np.bool_(buffer.full), **arrays)
    os.replace(tmp, path)


def load_replay_buffer(buffer: Any, path: str | Path) -> None:
    """Fill ``buffer`` (made by the model for its own spaces and size) from a :func:`save_replay_buffer` file;
    an array of another shape or kind, or a position outside the buffer, refuses the file."""
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as z:
            found = {name: z[name] for name in z.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise ModelFileError(f"it is not a replay buffer of arrays ({' '.join(str(exc).split())[:100]})") from None
    for name in _BUFFER_ARRAYS:
        mine = getattr(buffer, name, None)
        if mine is None:
            continue
        theirs = found.get(name)
        if theirs is None or theirs.shape != mine.shape or theirs.dtype != mine.dtype:
            got = "missing" if theirs is None else f"{theirs.dtype}{list(theirs.shape)}"
            raise ModelFileError(f"its {name} are {got}, this run's buffer holds {mine.dtype}{list(mine.shape)}")
    try:
        pos, full = int(found["pos"]), bool(found["full"])
    except (KeyError, TypeError, ValueError):
        raise ModelFileError("it has no position (pos, full)") from None
    if not 0 <= pos < buffer.buffer_size:
        raise ModelFileError(f"its position {pos} is outside the buffer of {buffer.buffer_size}")
    for name in _BUFFER_ARRAYS:
        if getattr(buffer, name, None) is not None:
            getattr(buffer, name)[...] = found[name]
    buffer.pos, buffer.full = pos, full


__all__ = ["COMMON", "ModelFileError", "Rebuild", "discrete_space", "load_replay_buffer", "load_sb3", "nothing",
           "plain_objects", "policy_class", "read_sb3_data", "read_weights", "rebuilds", "save_replay_buffer", "sb3_settings",
           "schedule", "write_weights"]
