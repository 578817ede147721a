"""How a learned driver's model zip is read as data (:mod:`garage_mj.core.model_file`, the one loading door).

:data:`DRIVER_REBUILDS` makes each pickled entry a ``train-driver`` model holds from its plain fields:
the policy class (the algorithm's ``MultiInputPolicy``), the network (``CameraRouteExtractor``), the
observation space (:func:`~garage_mj.driving.learning.observation.learned_space` at the recorded camera
size; :func:`~garage_mj.driving.learning.observation.park_space` for a parking driver), the action space
(``Discrete``) and schedules (:data:`~garage_mj.core.model_file.COMMON`). Any other pickled
entry refuses the file. Imported by the learned driver and by ``train-driver``'s resume. It also names the shipped
models (:func:`model_path`: ``learned``, ``learned:park``) and tells which learned driver runs a model
(:func:`learned_kind`), reading no more than a zip's plain ``data``.
"""

from __future__ import annotations

import inspect
import json
import re
import zipfile
from importlib import resources
from pathlib import Path
from typing import Any

from garage_mj.core.model_file import (
    ModelFileError,
    Rebuild,
    load_sb3,
    policy_class,
    rebuilds,
)


def _policy_kwargs(entry: dict, data: dict, algo: type, env: Any) -> Any:
    from garage_mj.driving.learning.network import saved_policy_kwargs

    kwargs = saved_policy_kwargs(data)
    if kwargs is None:
        raise ModelFileError("its policy_kwargs name a network other than CameraRouteExtractor (train-driver's)")
    return kwargs


def _observation_space(entry: dict, data: dict, algo: type, env: Any) -> Any:
    """:func:`learned_space` (a cruise driver's) or :func:`park_space` (a parking driver's) for the camera size the
    entry records, if the entry's plain fields are that space."""
    from garage_mj.driving.learning.observation import PARK_IMAGE_CHANNELS, learned_space, park_space

    text = str(entry.get("spaces"))
    size = re.search(r"'image': Box\(0, 255, \((\d+), (\d+), (\d+)\), uint8\)", text)
    channels, shape = (int(size.group(1)), (int(size.group(2)), int(size.group(3)))) if size else (0, (0, 0))
    made = ([learned_space(*shape)] if channels == 2 else
            [park_space(*shape, route, guide) for route in (False, True) for guide in (False, True)] if channels == PARK_IMAGE_CHANNELS else [])
    space = next((s for s in made if str(dict(s.spaces)) == text), None)
    if space is None:
        raise ModelFileError(f"its observation space {text[:120]} is not a learned driver's (learned_space or "
                             "park_space)")
    return space


def _train_freq(entry: dict, data: dict, algo: type, env: Any) -> Any:
    return inspect.signature(algo).parameters["train_freq"].default  # the algorithm's own; a driver does not train


#: Every pickled ``data`` entry a learned-driver model may hold, by key; any other refuses the file.
DRIVER_REBUILDS: dict[str, Rebuild] = rebuilds(
    Rebuild("policy_class", policy_class(lambda algo: algo.policy_aliases["MultiInputPolicy"],
                                         "the algorithm's MultiInputPolicy (the learned driver's)")),
    Rebuild("policy_kwargs", _policy_kwargs),
    Rebuild("observation_space", _observation_space),
    Rebuild("train_freq", _train_freq),
)


class ActingOnly:
    """The optimizer of a model loaded to act, not to train: it keeps no state and refuses to step.

    Building torch's own optimizer imports ``torch._dynamo`` (about 4 s per process on 2 cores), which a driver that
    only predicts never uses; :func:`load_driver_model` ``(acting=True)`` puts this in its place. The file's
    optimizer state is read (as weights) and dropped.
    """

    def __init__(self, params: Any, lr: float = 0.0, **kwargs: Any) -> None:
        self.param_groups = [{"params": list(params), "lr": lr}]

    def load_state_dict(self, state: Any, strict: bool = True) -> None:
        """Drops ``state``: an acting model does not train."""

    def zero_grad(self, set_to_none: bool = True) -> None:
        raise RuntimeError("this model was loaded to act (load_driver_model(acting=True)); load it to train it")

    step = zero_grad


def load_driver_model(path: str | Path, algo: type, env: Any = None, *, acting: bool = False, **kwargs: Any) -> Any:
    """The learned-driver model zip at ``path`` as an ``algo`` (DQN or PPO), read as data (module docstring).

    ``acting``: loaded to predict only (a driver), its optimizer :class:`ActingOnly`; else ready to train on.
    """
    return load_sb3(path, algo, DRIVER_REBUILDS, env=env, policy_kwargs={"optimizer_class": ActingOnly} if acting else None,
                    **kwargs)


# -- the shipped models, by the names ``learned`` and ``learned:NAME`` run ----------------------------------------
DRIVER_MODELS = "drivers"  # the folder of models/ that holds the shipped driver models
DEFAULT_MODEL = "cruise_m5"  # models/drivers/<DEFAULT_MODEL>.zip: what ``--driver learned`` runs
#: Where ``learned:park`` (and ``learned:avp``) look for the shipped parking model: models/drivers/<PARK_MODEL>.zip
#: (docs/learned-parking.md).
PARK_MODEL = "park_m5"
#: The cruise model ``learned:avp`` drives to the stall with: models/drivers/<AVP_CRUISE_MODEL>.zip, the cruise model's
#: run in the park geometries (docs/learned-parking.md).
AVP_CRUISE_MODEL = "avp_cruise_m5"
#: The learned drivers a ``learned:NAME`` spec names: the parking model, and the AVP driver (the shipped cruise and
#: parking models together, :class:`~garage_mj.driving.drivers.learned.LearnedAVPDriver`).
NAMED = ("park", "avp")


def default_model(name: str = DEFAULT_MODEL) -> Path:
    """A shipped model: ``models/drivers/<name>.zip`` in the package (by default what ``--driver learned`` runs)."""
    return Path(str(resources.files("garage_mj.models").joinpath(DRIVER_MODELS, f"{name}.zip")))


def model_path(model: str | Path | None) -> Path:
    """The file of a learned driver's model: None or ``""`` the shipped cruise model, ``park`` the shipped parking
    model (:data:`PARK_MODEL`), anything else a path."""
    if model is None or str(model) == "":
        return default_model()
    if str(model) == "park":
        return default_model(PARK_MODEL)
    return Path(model).expanduser()


def learned_kind(model: str | Path | None) -> str:
    """Which learned driver runs ``model`` (a ``learned:`` spec's model part): ``"avp"`` for ``avp``
    (:class:`~garage_mj.driving.drivers.learned.LearnedAVPDriver`), ``"park"`` for ``park`` or a zip whose observation
    is the parking driver's (:func:`~garage_mj.driving.learning.observation.park_space`: 4 image planes;
    :class:`~garage_mj.driving.drivers.learned.LearnedParkDriver`; read from its plain ``data``, nothing loaded),
    else ``"cruise"``
    (:class:`~garage_mj.driving.drivers.learned.LearnedDriver`; a file that cannot be read too: its loader then names what is wrong with it)."""
    if model is not None and str(model) in NAMED:
        return str(model)
    if model is None or str(model) == "":
        return "cruise"
    try:
        with zipfile.ZipFile(model_path(model)) as z:
            data = json.loads(z.read("data"))
        from garage_mj.driving.learning.observation import PARK_IMAGE_CHANNELS

        spaces = str(data["observation_space"]["spaces"])
        return "park" if f"'image': Box(0, 255, ({PARK_IMAGE_CHANNELS}, " in spaces else "cruise"
    except (OSError, zipfile.BadZipFile, KeyError, TypeError, ValueError):
        return "cruise"


__all__ = ["AVP_CRUISE_MODEL", "DEFAULT_MODEL", "DRIVER_MODELS", "DRIVER_REBUILDS", "NAMED", "PARK_MODEL", "default_model", "learned_kind",
           "load_driver_model", "model_path"]
