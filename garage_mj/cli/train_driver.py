"""``garage-mj train-driver``: train a learned cruise driver (SB3 DQN, DAgger warm start) or a parking driver (the same
DQN over the parking sensors and 90 park commands) over garages."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import (
    MAX_WORKERS,
    checked_range,
    int_in,
    non_negative_int,
    positive_int,
    seed,
    seed_list,
    unit_range,
    user_errors,
)
from garage_mj.cli.cruise import add_actor_arguments, scenario
from garage_mj.core.config import load_config
from garage_mj.core.fsutil import FolderLock
from garage_mj.driving.garage_set import load_garage_set
from garage_mj.driving.learning.saved_model import model_path
from garage_mj.driving.learning.train import CURRICULA, TRAIN_TASKS, DriverTrainConfig, train_driver
from garage_mj.driving.park_geometries import PARK_GEOMETRIES
from garage_mj.driving.sim.park_task import MANEUVER_CHOICES


def geometry_list(text: str) -> tuple[str, ...]:
    """argparse type of --geometries: comma-separated park geometry names."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    bad = [n for n in names if n not in PARK_GEOMETRIES]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"{', '.join(bad) or repr(text)}: give park geometry names, comma-separated, "
                                         f"from {', '.join(PARK_GEOMETRIES)}")
    return names


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train-driver",
        help="train a learned cruise or parking driver (imitation of the oracle, DAgger) over many garages",
        description=(
            "Train a stable-baselines3 DQN (MultiInputPolicy: a CNN over the front camera's depth and "
            "segmentation, an MLP over the next route waypoint, speed, route left and steering angle; the "
            "paper's 4 actions) over a set of garages, one drawn per episode. Training starts by imitation "
            "of the privileged oracle (DAgger: the model drives, the oracle labels every state it visits), "
            "then optionally fine-tunes with DQN on the env's reward (--rl-timesteps). The model never "
            "sees the route plan, its pose or the goal in the world frame. The run folder gets run.json, "
            "curve.csv (validation success per iteration), garages.json, checkpoints/ and model.zip; an "
            "interrupted run continues with --resume. Drive with it: --driver learned:OUT/model.zip.\n\n"
            "--task park trains a parking driver instead: the same DQN over both cameras (front and rear depth + "
            "segmentation), the 12 ultrasonic ranges, the slot detector, the heading to end in, speed, steering and "
            "gear, picking one of 90 park commands [pedal, steer, gear]; trained by DAgger on the command nearest the "
            "oracle's, on park tests of the garages built in --geometries, with "
            "the actors of --scenarios. Drive it with --task park --driver learned:OUT/model.zip; an AVP test is "
            "driven by a cruise model and a parking model together (--driver learned:avp)."
        ),
        epilog=("GARAGES is a library file (.sqlite, with --map/--difficulty/--run-seeds/-n), a garages JSON "
                "(library export-json, or a run's garages.json), a folder of asset packs, or a shipped map name "
                "(painted by the scripted painter, -n garages).\n"
                "example: garage-mj train-driver runs/lib.sqlite --map m5_13x13_aligned --run-seeds 0,1,2 -n 200 "
                "--validation runs/lib.sqlite --validation-run-seeds 3 --out runs/driver_m5"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("garages", metavar="GARAGES", help="where the training garages come from (see below)")
    p.add_argument("--map", help="keep only this map's garages (library)")
    p.add_argument("--difficulty", nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="keep only garages with difficulty in [LO, HI] (0-1), as the library filters")
    p.add_argument("--run-seeds", type=seed_list, metavar="K,K", help="keep only garages of these generation runs' seeds")
    p.add_argument("-n", type=positive_int, metavar="N", help="a seeded sample of N garages (default: all; a map: 32)")
    p.add_argument("--validation", metavar="GARAGES", help="garages of the validation curve (default: the training ones)")
    p.add_argument("--validation-run-seeds", type=seed_list, metavar="K,K", help="run seeds of the validation garages")
    p.add_argument("--validation-n", type=positive_int, metavar="N",
                   help="validation garages drawn from a library or painted (default 20)")
    p.add_argument("--out", required=True, type=Path, help="run folder (must be new unless --resume)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out after its last finished iteration")
    p.add_argument("--init", metavar="MODEL",
                   help="start from this model instead of a new network, fine-tuning it on GARAGES: a model zip, "
                        "learned / learned:park for a shipped one, or a run's RUN/checkpoints/iter_NNN.zip, which "
                        "brings that run's states up to the iteration too; give the config it was trained with "
                        "(e.g. models/drivers/park_m5.toml)")
    p.add_argument("--config", type=Path, help="TOML of DriverTrainConfig keys (unknown keys are an error)")
    p.add_argument("--iterations", type=positive_int, help="DAgger iterations (default 6)")
    p.add_argument("--steps", type=positive_int, help="env steps driven per iteration (default 6000)")
    p.add_argument("--curriculum", choices=CURRICULA, help="how garages are drawn: uniform (default), difficulty (easy to hard), adversarial (failure-prioritised replay), hunt (garages hunt finds the model failing on)")
    p.add_argument("--rl-timesteps", type=non_negative_int, help="DQN fine-tuning timesteps after imitation (default 0)")
    p.add_argument("--workers", type=int_in(1, MAX_WORKERS), help=f"worker processes driving, 1 to {MAX_WORKERS:,} (default 2)")
    park = p.add_argument_group("a parking driver")
    park.add_argument("--task", choices=TRAIN_TASKS, help="what it learns: cruise tests (default) or park tests")
    park.add_argument("--maneuver", choices=MANEUVER_CHOICES,
                      help="park tests: reverse, forward or any (drawn per test; the default)")
    park.add_argument("--geometries", type=geometry_list, metavar="NAME,NAME",
                      help=f"park geometries the garages are built in (cruise or park), garage k in the (k mod "
                           f"n)th: {', '.join(PARK_GEOMETRIES)} (default: default)")
    park.add_argument("--scenarios", type=lambda t: tuple(n.strip() for n in t.split(",") if n.strip()),
                      metavar="NAME,NAME", help="park actor scenarios drawn with each geometry (every pair of "
                      "geometry and scenario gets its share of the garages): none or park_* names of --scenario")
    act = p.add_argument_group("adverse events while training (the oracle yields to them, the model sees them "
                               "only in its camera)")
    add_actor_arguments(act, per="episode")
    p.add_argument("--seed", type=seed, default=0, help="random seed of the run (default 0)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


@user_errors
def run(args: argparse.Namespace) -> int:
    flags = {key: value for key, value in (("iterations", args.iterations), ("steps_per_iteration", args.steps),
                                           ("curriculum", args.curriculum), ("rl_timesteps", args.rl_timesteps),
                                           ("n_envs", args.workers), ("task", args.task),
                                           ("maneuver", args.maneuver), ("geometries", args.geometries), ("scenarios", args.scenarios))
             if value is not None}
    try:
        config = load_config(DriverTrainConfig, args.config, **flags)  # a bad value: the file (or flag), key, range
    except ValueError as exc:
        raise UserError(f"driver training config: {exc}") from None
    if args.resume and not (args.out / "run.json").is_file():
        raise UserError(f"--resume: {args.out} holds no driver run to continue; drop --resume to start one there")
    scen = scenario(args)  # bad actor settings are refused before any garage is drawn
    init = _init_path(args.init)
    garages = load_garage_set(args.garages, map=args.map, difficulty=checked_range(args.difficulty, "difficulty"),
                              run_seeds=args.run_seeds, n=args.n, seed=args.seed)
    validation = None
    if args.validation is not None:
        spec = args.validation
        from_library = spec.endswith(".sqlite")
        drawn = from_library or not (Path(spec).exists() or spec.endswith(".json"))  # a library or a painted map
        n = args.validation_n if args.validation_n is not None else (20 if drawn else None)
        validation = load_garage_set(spec, map=args.map if from_library else None,
                                     run_seeds=args.validation_run_seeds, n=n, seed=args.seed + 1)
        overlap = {s.hash for s in garages} & {s.hash for s in validation}
        if overlap:
            print(f"note: {len(overlap)} validation garage(s) are also training garages")
    print(f"training on {len(garages)} garages ({garages.origin}); validating on "
          f"{len(validation) if validation is not None else len(garages)}")
    # a failed start leaves no folder: train_driver undoes what it wrote, the lock the folder it made
    with FolderLock(args.out, "garage-mj train-driver", remove=True):
        model = train_driver(garages, args.out, validation=validation, config=config, seed=args.seed,
                             resume=args.resume, progress=not args.no_progress,
                             env_kwargs=None if scen is None else {"scenario": scen}, init=init)
    state = json.loads((args.out / "run.json").read_text())["state"]
    chosen = state.get("selected_iteration")
    row = next((r for r in state["curve"] if r["iteration"] == chosen), {})
    print(f"model -> {model} (iteration {chosen} of {state['iterations_done']}, validation success "
          f"{row.get('val_success', '-')}; {state['wall_s'] / 60:.1f} min); drive it with --driver learned:{model}")
    return 0


def _init_path(spec: str | None) -> Path | None:
    """The model file ``--init`` names (a zip, ``learned`` or ``learned:park``); one that is not a file: a
    :class:`UserError`, before anything is written."""
    if spec is None:
        return None
    name = spec.removeprefix("learned:") if spec.startswith("learned:") else ("" if spec == "learned" else None)
    if name == "avp":
        raise UserError("--init learned:avp is two models (cruise and park): name one, learned or learned:park")
    path = model_path(name) if name is not None else Path(spec).expanduser()
    if not path.is_file():
        raise UserError(f"--init {spec}: {path} is not a file; name a model zip (a run's model.zip or "
                        "checkpoints/iter_NNN.zip) or learned:park")
    return path
