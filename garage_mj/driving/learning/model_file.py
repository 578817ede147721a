"""A stable-baselines3 model zip read as data: its weights and plain settings, nothing in it run.

An SB3 zip holds ``data`` (JSON settings) and ``.pth`` files (``torch.save`` weights). SB3 pickles
(cloudpickle) each setting JSON cannot hold, such as the policy class, the spaces and the schedules,
as a ``":serialized:"`` entry of ``data``, and ``SB3.load`` unpickles them: a crafted file would run
its own code. :func:`load_sb3` unpickles none of them: :data:`REBUILDS` makes each such entry again
from the plain fields SB3 writes beside the pickle (a key it does not list refuses the file), and
SB3 gets them as ``custom_objects``, so it never unpickles that entry. The ``.pth`` files are read by
``torch.load(weights_only=True)`` (tensors and plain containers only), here first, then by SB3 (which
uses ``weights_only=True`` too), from the same bytes read once.

Imported by the learned driver and by ``train-driver``'s resume; torch and SB3 are imported when a
model is loaded.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

SERIALIZED = ":serialized:"  # the key SB3 gives a pickled entry of ``data``
_NUMBER = r"[-+0-9.eEinfa]+"


class ModelFileError(ValueError):
    """A model zip that is not one :func:`load_sb3` reads as data; the message says what is wrong (one line)."""


def _float(value: Any, what: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ModelFileError(f"its {what} is {str(value)[:60]!r}, not a number") from None


def _policy(entry: dict, data: dict, algo: type) -> Any:
    """The algorithm's ``MultiInputPolicy`` (the learned driver's), if that is the class the entry names."""
    cls = algo.policy_aliases["MultiInputPolicy"]
    if entry.get("__module__") != cls.__module__ or f" {cls.__name__}.__init__ " not in str(entry.get("__init__")):
        raise ModelFileError(f"its policy is not {algo.__name__}'s MultiInputPolicy (the learned driver's)")
    return cls


def _policy_kwargs(entry: dict, data: dict, algo: type) -> Any:
    from garage_mj.driving.learning.network import saved_policy_kwargs

    kwargs = saved_policy_kwargs(data)
    if kwargs is None:
        raise ModelFileError("its policy_kwargs name a network other than CameraRouteExtractor (train-driver's)")
    return kwargs


def _observation_space(entry: dict, data: dict, algo: type) -> Any:
    """:func:`learned_space` for the camera size the entry records, if the entry's plain fields are that space."""
    from garage_mj.driving.learning.observation import learned_space

    text = str(entry.get("spaces"))
    size = re.search(r"'image': Box\(0, 255, \(2, (\d+), (\d+)\), uint8\)", text)
    space = learned_space(int(size.group(1)), int(size.group(2))) if size else None
    if space is None or str(dict(space.spaces)) != text:
        raise ModelFileError(f"its observation space {text[:120]} is not a learned driver's (learned_space)")
    return space


def _action_space(entry: dict, data: dict, algo: type) -> Any:
    from gymnasium import spaces

    try:
        n, start = int(entry["n"]), int(entry.get("start", 0))
    except (KeyError, TypeError, ValueError):
        raise ModelFileError("its action space has no plain n (a Discrete space's)") from None
    if "Discrete" not in str(entry.get(":type:")) or entry.get("dtype") != "int64" or n < 1:
        raise ModelFileError(f"its action space is {str(entry.get(':type:'))[:60]}, not Discrete(n)")
    return spaces.Discrete(n, start=start)


def _schedule(entry: dict, data: dict, algo: type) -> Any:
    """A constant or linear schedule from its plain fields (SB3 rebuilds the ones it trains with itself)."""
    from stable_baselines3.common.utils import FloatSchedule, LinearSchedule

    if {"start", "end", "end_fraction"} <= set(entry):
        return LinearSchedule(*(_float(entry[k], f"schedule's {k}") for k in ("start", "end", "end_fraction")))
    constant = re.fullmatch(rf"ConstantSchedule\(val=({_NUMBER})\)", str(entry.get("value_schedule")))
    if constant is None:
        raise ModelFileError(f"its schedule {str(entry.get('value_schedule'))[:60]!r} is neither constant nor linear")
    return FloatSchedule(_float(constant.group(1), "schedule's value"))


def _nothing(entry: dict, data: dict, algo: type) -> Any:
    """None: a setting SB3 makes again itself (buffer class, train frequency) or training state a driver needs not."""
    return None


def _train_freq(entry: dict, data: dict, algo: type) -> Any:
    import inspect

    return inspect.signature(algo).parameters["train_freq"].default  # the algorithm's own; a driver does not train


@dataclass(frozen=True)
class Rebuild:
    """How one pickled entry of a model zip's ``data`` is made from plain fields instead of unpickled."""

    key: str
    build: Callable[[dict, dict, type], Any]  # (the entry's plain fields, the whole data, the SB3 class) -> value


#: Every pickled ``data`` entry a learned-driver model may hold, by key; any other refuses the file.
REBUILDS: dict[str, Rebuild] = {r.key: r for r in (
    Rebuild("policy_class", _policy),
    Rebuild("policy_kwargs", _policy_kwargs),
    Rebuild("observation_space", _observation_space),
    Rebuild("action_space", _action_space),
    Rebuild("lr_schedule", _schedule),
    Rebuild("exploration_schedule", _schedule),
    Rebuild("clip_range", _schedule),
    Rebuild("clip_range_vf", _schedule),
    Rebuild("train_freq", _train_freq),
    Rebuild("replay_buffer_class", _nothing),  # None: SB3 picks the buffer of a Dict space
    Rebuild("rollout_buffer_class", _nothing),
    *(Rebuild(key, _nothing) for key in ("_last_obs", "_last_original_obs", "_last_episode_starts",
                                         "ep_info_buffer", "ep_success_buffer")),  # training state
)}


def plain_objects(data: dict, algo: type) -> dict[str, Any]:
    """``custom_objects`` for ``algo.load``: every pickled entry of ``data`` rebuilt (:data:`REBUILDS`)."""
    custom = {}
    for key, entry in data.items():
        if isinstance(entry, dict) and SERIALIZED in entry:
            if key not in REBUILDS:
                raise ModelFileError(f"its data entry {key[:60]!r} is pickled Python, which a model file may not hold")
            custom[key] = REBUILDS[key].build(entry, data, algo)
    return custom


def _check_weights(archive: zipfile.ZipFile) -> None:
    """Each ``.pth`` of the zip loads as tensors and plain containers (``weights_only=True``), or refuse it."""
    import pickle

    import torch

    for name in archive.namelist():
        if not name.endswith(".pth"):
            continue
        try:
            torch.load(io.BytesIO(archive.read(name)), map_location="cpu", weights_only=True)
        except pickle.UnpicklingError:  # torch's text advises weights_only=False: never relayed
            raise ModelFileError(f"its {name[:60]} holds more than weights (Python objects to rebuild)") from None
        except Exception as exc:  # noqa: BLE001 - a damaged file in any way: one line
            raise ModelFileError(f"its {name[:60]} is not readable weights ({type(exc).__name__})") from None


def load_sb3(path: str | Path, algo: type, **kwargs: Any) -> Any:
    """``algo.load`` of the model zip at ``path`` (``device="cpu"``, ``kwargs`` passed on), nothing in it unpickled.

    Raises :class:`ModelFileError` (one line, without the file name) when the zip holds a pickled entry
    :data:`REBUILDS` does not list or that does not match its plain fields, or weights that are not plain
    tensors; other errors of a damaged file (``OSError``, ``zipfile.BadZipFile``, ...) pass through.
    """
    raw = Path(path).read_bytes()  # read once: what is checked is what SB3 loads
    with zipfile.ZipFile(io.BytesIO(raw)) as archive:
        try:
            data = json.loads(archive.read("data"))
        except KeyError:
            raise ModelFileError("it has no data entry (not a stable-baselines3 model zip)") from None
        except ValueError:
            raise ModelFileError("its data entry is not JSON") from None
        if not isinstance(data, dict):
            raise ModelFileError("its data entry is not a JSON object")
        custom = plain_objects(data, algo)
        _check_weights(archive)
    return algo.load(io.BytesIO(raw), device="cpu", custom_objects=custom, **kwargs)
