"""Every model file goes through one loading door (``garage_mj.core.model_file``) and never runs code.

A training checkpoint, its replay buffer and counters, a generator (``generate --model``, the one that
``generate --map`` keeps beside a library) are data: a crafted file is refused in one line or its
pickled entry is rebuilt from plain fields, and the payload never runs. The learned driver's model
files are tested the same way in ``tests/test_learned_driver.py``.
"""

from __future__ import annotations

import ast
import base64
import io
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from garage_mj.generation.conditioned import default_model_out, load_policy, shipped_generator
from garage_mj.generation.runs import latest_checkpoint
from garage_mj.generation.training import load_dqn_config, train
from tests._cli import one_line_error, snapshot

ROOT = Path(__file__).resolve().parents[1]
DOOR = ROOT / "garage_mj" / "core" / "model_file.py"
#: Calls that read a file by unpickling it (or load an SB3 model, which does): only the door may make them.
UNPICKLING = frozenset({"pickle.load", "pickle.loads", "cloudpickle.load", "cloudpickle.loads", "dill.load",
                        "dill.loads", "marshal.load", "marshal.loads", "torch.load", "joblib.load",
                        "load_from_zip_file", "load_from_pkl", "yaml.load"})
#: Receivers whose ``.load``/``.loads`` read data, never code (NumPy only without ``allow_pickle=True``).
DATA_READERS = frozenset({"json", "tomllib", "np", "numpy", "trimesh"})


class Touch:
    """A pickle that, when loaded, creates the file ``path``: what a crafted model file could run."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return Path.touch, (self.path,)


def loading_calls(source: str) -> list[tuple[int, str]]:
    """(line, call) of every call in ``source`` that may load a model file by unpickling it."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = ast.unparse(func)
        leaf = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
        receiver = ast.unparse(func.value).split(".")[0] if isinstance(func, ast.Attribute) else ""
        pickled_numpy = any(k.arg == "allow_pickle" and not (isinstance(k.value, ast.Constant) and k.value.value is False)
                            for k in node.keywords)
        sb3_buffer = isinstance(func, ast.Attribute) and leaf == "load_replay_buffer"  # the model's, which unpickles
        if name in UNPICKLING or leaf in {"load_from_zip_file", "load_from_pkl"} or sb3_buffer:
            found.append((node.lineno, name))
        elif leaf in {"load", "loads"} and (receiver not in DATA_READERS or pickled_numpy):
            found.append((node.lineno, name))  # SB3's DQN.load, a policy's .load, np.load(allow_pickle=True), ...
    return found


def _sources() -> list[Path]:
    return sorted([*(ROOT / "garage_mj").rglob("*.py"), *(ROOT / "generation").glob("*.py"),
                   *(ROOT / "eval").glob("*.py"), ROOT / "pytest_garage_mj.py"])


def test_only_the_door_loads_model_files():
    outside = [f"{p.relative_to(ROOT)}:{line}: {call}" for p in _sources() if p != DOOR
               for line, call in loading_calls(p.read_text())]
    assert not outside, "load model files through garage_mj.core.model_file only:\n" + "\n".join(outside)
    assert loading_calls(DOOR.read_text())  # the door itself does load


@pytest.mark.parametrize("code", ["DQN.load(path)", "algo.load(p, env=e)", "DQNPolicy.load(str(p))", "torch.load(f)",
                                  "pickle.loads(b)", "model.load_replay_buffer(p)", "np.load(p, allow_pickle=True)",
                                  "load_from_zip_file(p)", "self.policy.load(p)"])
def test_the_door_check_sees_each_way_of_loading(code):
    assert loading_calls(f"x = {code}\n"), code


@pytest.mark.parametrize("code", ["json.loads(t)", "tomllib.loads(t)", "np.load(p, allow_pickle=False)",
                                  "np.load(p)", "trimesh.load(p)"])
def test_the_door_check_lets_data_readers_be(code):
    assert not loading_calls(f"x = {code}\n"), code


# -- training runs ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A short fast-learner run of tiny_7x11 with two checkpoints and their replay buffers."""
    out = tmp_path_factory.mktemp("run") / "run"
    config = load_dqn_config(learner="fast", learning_starts=256, checkpoint_every=1000, save_replay_buffer=True,
                             buffer_size=4_000)
    train("tiny_7x11", 2000, 0, out, config, progress=False)
    return out


def _copy(run_dir: Path, tmp_path: Path) -> tuple[Path, Path]:
    out = tmp_path / "run"
    shutil.copytree(run_dir, out)
    return out, latest_checkpoint(out)[0]


def _resume(out: Path, timesteps: int = 2600) -> list[str]:
    return ["train", "--map", "tiny_7x11", "--timesteps", str(timesteps), "--out", str(out), "--resume",
            "--no-progress"]


def _poison(model: Path, key: str, marker: Path) -> None:
    """Give the model zip's ``data`` entry ``key`` a pickled payload that touches ``marker`` (its plain fields kept)."""
    with zipfile.ZipFile(model) as z:
        entries = {name: z.read(name) for name in z.namelist()}
    data = json.loads(entries["data"])
    data[key] = {**(data.get(key) if isinstance(data.get(key), dict) else {}),
                 ":serialized:": base64.b64encode(pickle.dumps(Touch(marker))).decode()}
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(model, "w") as z:
        for name, blob in entries.items():
            z.writestr(name, blob)


@pytest.mark.parametrize("key", ["policy_class", "policy_kwargs", "observation_space", "exploration_schedule",
                                 "train_freq", "replay_buffer_class", "a_new_entry"])
def test_train_resume_never_runs_a_pickle_in_a_checkpoint(key, run_dir, tmp_path, capsys):
    """A pickled entry SB3 writes is rebuilt from the run's config and plain fields (the payload unread);
    any other pickled entry refuses the checkpoint in one line and changes nothing."""
    from garage_mj.cli import main

    out, model = _copy(run_dir, tmp_path)
    marker = tmp_path / "ran"
    _poison(model, key, marker)
    if key == "a_new_entry":
        before = snapshot(out)
        line = one_line_error(capsys, _resume(out))
        assert f"checkpoint {model} cannot be resumed: its data entry 'a_new_entry' is pickled Python" in line
        assert snapshot(out) == before
    else:
        assert main(_resume(out)) == 0
        assert json.loads((out / "run.json").read_text())["timesteps"] >= 2600
    assert not marker.exists()


def test_a_forged_checkpoint_counter_is_refused(run_dir, tmp_path, capsys):
    out, model = _copy(run_dir, tmp_path)
    counters = model.with_suffix(".json")
    counters.write_text(json.dumps({"timesteps": 999_999_999, "episodes": 3}))
    before = snapshot(out)
    line = one_line_error(capsys, _resume(out, 5000))
    assert f"checkpoint {counters} says 999999999 timesteps" in line and "its model has trained 2" in line
    assert "remove both files" in line
    assert snapshot(out) == before


def test_a_replay_buffer_is_read_as_arrays(run_dir, tmp_path, capsys):
    from garage_mj.core.model_file import load_replay_buffer, save_replay_buffer
    from garage_mj.generation.runs import load_dqn, replay_path

    out, model = _copy(run_dir, tmp_path)
    buffer = replay_path(model)
    config = load_dqn_config(json.loads((out / "run.json").read_text())["config"])
    saved = load_dqn(model, config).replay_buffer
    load_replay_buffer(saved, buffer)
    assert saved.pos > 0 and np.any(saved.observations)
    again = load_dqn(model, config).replay_buffer
    save_replay_buffer(saved, tmp_path / "again.npz")
    load_replay_buffer(again, tmp_path / "again.npz")
    assert again.pos == saved.pos and np.array_equal(again.observations, saved.observations)

    marker = tmp_path / "ran"
    with open(buffer, "wb") as f:  # an object array: what np.load(allow_pickle=True) would run
        np.savez(f, observations=np.array([Touch(marker)], dtype=object))
    before = snapshot(out)
    line = one_line_error(capsys, _resume(out))
    assert f"checkpoint {model} cannot be resumed: it is not a replay buffer of arrays" in line
    assert snapshot(out) == before and not marker.exists()


# -- generators ----------------------------------------------------------------------------------------------
def _payload_file(path: Path, marker: Path) -> Path:
    blob = io.BytesIO()
    torch.save({"format": "garage-mj generator policy 1", "state_dict": {"w": Touch(marker)}}, blob)
    path.write_bytes(blob.getvalue())
    return path


def test_generate_model_never_runs_a_payload(tmp_path, capsys):
    marker = tmp_path / "ran"
    model = _payload_file(tmp_path / "evil.zip", marker)
    library = tmp_path / "lib.sqlite"
    line = one_line_error(capsys, ["generate", "--map", "tiny_7x11", "--difficulty", "0.2", "0.8", "--count", "1",
                                   "--model", str(model), "--library", str(library), "--no-progress"])
    assert f"{model} is not a generator saved by garage-mj: it holds more than weights" in line
    assert not marker.exists() and not library.exists()


def test_a_generator_file_that_pickles_its_settings_is_refused(tmp_path):
    """SB3's own ``policy.save`` pickles the spaces and classes beside the weights: not a file the door reads."""
    from garage_mj.generation.conditioned import GenerationError

    legacy = tmp_path / "generator.zip"
    load_policy(shipped_generator("tiny_7x11")).save(str(legacy))
    with pytest.raises(GenerationError, match=r"is not a generator saved by garage-mj: it holds more than weights"):
        load_policy(legacy)


def test_generate_map_never_runs_a_generator_planted_beside_the_library(tmp_path, capsys):
    from garage_mj.grid.map_io import load_map

    map_file = tmp_path / "mine.txt"
    shutil.copyfile(ROOT / "tests" / "data" / "maps" / "scattered_13x13.txt", map_file)
    library = tmp_path / "lib.sqlite"
    marker = tmp_path / "ran"
    planted = _payload_file(default_model_out(library, load_map(str(map_file)).name), marker)
    line = one_line_error(capsys, ["generate", "--map", str(map_file), "--difficulty", "0.2", "0.8", "--count", "1",
                                   "--library", str(library), "--no-progress"])
    assert f"{planted} is not a generator saved by garage-mj" in line and "remove it" in line
    assert not marker.exists() and not library.exists()


@pytest.mark.parametrize("name", ["tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"])
def test_every_shipped_generator_is_weights_and_plain_fields(name):
    policy = load_policy(shipped_generator(name))
    assert policy.action_space.n == 4 and not policy.training
