"""``garage-mj generate``: N garages of a map in a difficulty (and coverage) band, from a trained generator."""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

from garage_mj.cli import UserError
from garage_mj.cli._common import (
    SHIPPED_ROUTE_MODELS,
    add_geometry_args,
    geometry_world,
    int_in,
    positive_seconds,
    seed,
    unit_range,
    user_errors,
)
from garage_mj.driving.park_geometries import PARK_GEOMETRIES, geometry_names
from garage_mj.generation.library import check_writable
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.scene.park_difficulty import DEFAULT_PARK_MODEL, SHIPPED_PARK_MODELS, load_park_model
from garage_mj.scene.route_difficulty import load_route_model, route_difficulty
from garage_mj.scene.world import GEOMETRY_KEYS, geometry, world_with

#: garage_mj.generation.generator's bounds, named here so that --help stays light (no torch import)
MAX_COUNT = 1_000_000  # [garages] one call's --count
MAX_EPISODES = 1_000_000_000  # --max-episodes
MAX_TRAIN_TIMESTEPS = 1_000_000_000  # --train-timesteps (a shipped protocol run is 2,000,000)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "generate",
        help="store N garages of a map in a difficulty band, from a trained conditioned generator",
        description=(
            "Roll out the map's difficulty-conditioned DQN generator (shipped in models/generators/ for "
            "every shipped map, or --model) with the band in its observation, epsilon-greedy with a "
            "seeded epsilon per episode so that distinct garages appear, and store every distinct "
            "usable garage whose difficulty (and coverage) lies in the band in the library, until "
            "--count are found. If the rollouts do not fill the band within 100 + 10 x COUNT episodes, "
            "a local search takes over (unless --no-search): it mutates the road sets of the usable "
            "garages the policy painted (nearest to the band first) and of a few scripted-painter garages "
            "toward the band and inside it, and "
            "re-paints each one that lands there through the painter env before storing it (library run "
            "generate:<model>+search). The same --seed gives the same garages. If the budget "
            "(--max-episodes, --max-seconds) does not find --count, the ones found are kept and the "
            "command says how many (exit status 2). For your own map file without --model, a "
            "generator is trained first (--train-timesteps, default 200,000: about 30 s for a 13x13 "
            "map on one core), saved to --model-out (default: next to the library, "
            "<library stem>.<map name>.generator.zip) and reused by later calls; or pass a shipped "
            "generator (--model m4_13x13_offset): generators see only a window around the car, so "
            "they run on any map. With --metric route the band is one of the route-aware difficulty "
            "(garage-mj difficulty): the policy's first 20 rollouts (asking in turn for each tenth of the paper's "
            "difficulty, for seeds of every kind) and every search step are rated by "
            "planning the routes to all stalls (about 0.1-0.2 CPU-s per 13x13 garage), the search climbs and "
            "walks by that rating, and each garage stored gets its value in the library (library ls "
            "--route-difficulty LO HI finds them). With --metric park the band is one of the park difficulty "
            "(docs/difficulty.md): each garage is rated by the reference park plans of 6 seeded target stalls' park "
            "tests in the park geometry of the options below (about 0.2-0.4 CPU-s per 13x13 garage), and stored "
            "with its value under the key park:<model>:<geometry>."
        ),
        epilog="example: garage-mj generate --map m5_13x13_aligned --difficulty 0.3 0.4 --count 20 "
               "--library garages.sqlite",
    )
    p.add_argument("--map", required=True, help="shipped map name (garage-mj maps list) or map file")
    p.add_argument("--difficulty", required=True, nargs=2, type=unit_range, metavar=("LO", "HI"),
                   help="difficulty band [LO, HI] (0-1), of the --metric")
    p.add_argument("--metric", choices=("paper", "route", "park"), default="paper",
                   help="paper: the paper's difficulty (road length and intersections of the grid; default); "
                        "route: the route-aware difficulty, the expected failure rate of a cruise test predicted "
                        "from the planned routes (garage-mj difficulty); park: the park difficulty, the mean "
                        "predicted failure rate of the garage's park tests in the park geometry given; each garage "
                        "stored gets its route or park difficulty in the library")
    p.add_argument("--route-model", type=Path, metavar="FILE",
                   help=f"with --metric route: a model of garage-mj difficulty fit (default: the shipped one; {SHIPPED_ROUTE_MODELS})")
    p.add_argument("--park-model", metavar="FILE",
                   help="with --metric park: a model of garage-mj difficulty fit --task park, or a shipped one's name "
                        f"(default: {DEFAULT_PARK_MODEL}; shipped: {', '.join(SHIPPED_PARK_MODELS)})")
    p.add_argument("--coverage", nargs=2, type=unit_range, metavar=("LO", "HI"), help="coverage band [LO, HI] (0-1)")
    p.add_argument("--count", required=True, type=int_in(1, MAX_COUNT),
                   help=f"distinct garages to find (1 to {MAX_COUNT:,})")
    p.add_argument("--library", required=True, type=Path, help="library file (created if missing)")
    p.add_argument("--model", help="generator file, or a shipped map's name to use its generator "
                   "(default: the shipped generator of --map)")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--max-episodes", type=int_in(1, MAX_EPISODES), metavar="E",
                   help="episode budget (default 2,000 + 200 x COUNT; with --metric route, where each garage "
                        f"rated counts as an episode, 100 + 20 x COUNT; at most {MAX_EPISODES:,})")
    p.add_argument("--max-seconds", type=positive_seconds, metavar="S",
                   help="stop after S seconds of rollouts and search (wall clock; a number of seconds > 0)")
    p.add_argument("--no-search", action="store_true",
                   help="policy rollouts only (rejection sampling), no search stage")
    p.add_argument("--train-timesteps", type=int_in(1, MAX_TRAIN_TIMESTEPS), default=200_000, metavar="T",
                   help="map file without a generator: timesteps to train one with the fast learner "
                        f"(default 200,000; at most {MAX_TRAIN_TIMESTEPS:,})")
    p.add_argument("--model-out", type=Path, metavar="PATH",
                   help="map file without --model: where the trained generator goes (reused when it exists; "
                   "default <library stem>.<map name>.generator.zip next to the library)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--geometries", metavar="NAMES", type=lambda v: [n.strip() for n in v.split(",") if n.strip()],
                   help="with --metric park: search these named park geometries too, comma-separated (docs/spec.md "
                        f"section 9: {', '.join(PARK_GEOMETRIES)}); the geometries whose painted garages rate "
                        "nearest the band are tried first, each garage is stored under the key of the geometry it "
                        "was found in, and the geometry options below are then left out")
    add_geometry_args(p)  # with --metric park: the geometry the garages are rated in
    p.set_defaults(func=run)


@user_errors
def run(args: argparse.Namespace) -> int:
    from garage_mj.generation.conditioned import (
        GenerationError,
        default_model_out,
        shipped_generator,
        train_for_map,
    )
    from garage_mj.generation.generator import RouteMetric, generate

    route = rater = None
    if args.metric == "route":
        rmodel = load_route_model(args.route_model)
        route = RouteMetric(functools.partial(route_difficulty, model=rmodel), rmodel.key)
    elif args.route_model is not None:
        raise UserError("--route-model needs --metric route")
    given = [f"--{k.replace('_', '-')}" for k in (*GEOMETRY_KEYS, "layout") if getattr(args, k, None) is not None]
    if args.geometries is not None:
        if args.metric != "park":
            raise UserError("--geometries names the park geometries --metric park searches; add --metric park or "
                            "drop it")
        if given:
            raise UserError(f"--geometries names the park geometries to search; {given[0]} gives one of your own: "
                            "give one or the other")
        try:
            names = geometry_names(args.geometries, "--geometries")
        except ValueError as exc:
            raise UserError(str(exc)) from None
    if args.metric == "park":
        from garage_mj.scene.park_rating import ParkRater

        model_of_park = load_park_model(args.park_model)
        if args.geometries is not None:  # a rater per geometry searched (_in_geometries)
            raters = {n: ParkRater(world_with(PARK_GEOMETRIES[n].world, f"park geometry {n}"), model_of_park)
                      for n in names}
        else:
            rater = ParkRater(geometry_world(args), model_of_park)
            route = RouteMetric(rater, rater.key, "park difficulty")
    elif args.park_model is not None:
        raise UserError("--park-model needs --metric park")
    elif given:
        raise UserError(f"{given[0]} is a park geometry, which only --metric park rates garages in; add --metric park "
                        "or drop it")
    for name in ("difficulty", "coverage"):
        band = getattr(args, name)
        if band is not None and band[0] > band[1]:
            raise UserError(f"--{name} {band[0]} {band[1]}: LO is above HI")
    check_writable(args.library)  # before training a generator or rolling out: both end in the library
    model = args.model
    if model is not None and args.model_out is not None:
        raise UserError("--model-out is where a generator trained for a map file goes; with --model nothing is "
                        "trained: drop --model-out")
    if model is None:
        garage = load_map(args.map)
        shipped = "/" not in args.map and garage.name in {m.name for m in list_maps()}
        if shipped and shipped_generator(garage.name) is not None and args.model_out is not None:
            raise UserError(f"--model-out is where a generator trained for a map file goes; {garage.name} has a "
                            "shipped generator and nothing is trained: drop --model-out")
        if not (shipped and shipped_generator(garage.name) is not None):  # a map of your own: train a generator
            out = args.model_out or default_model_out(args.library, garage.name)
            above = next((p for p in out.parents if p.exists()), None)  # "." or "/" at the end
            if above is not None and not above.is_dir():
                raise UserError(f"--model-out {out}: {above} is a file, not a folder; name a path in a folder")
            if not out.is_file():
                print(f"{garage.name} has no generator: training one ({args.train_timesteps} timesteps) -> {out}",
                      flush=True)
            model, secs = train_for_map(args.map, out, args.train_timesteps, seed=args.seed,
                                        progress=not args.no_progress)
            print(f"trained the generator in {secs:.0f} s: {model}" if secs is not None
                  else f"using the generator trained earlier: {model}", flush=True)
    if args.geometries is not None:
        return _in_geometries(args, model, raters)
    try:
        r = generate(args.map, tuple(args.difficulty), args.count, args.library,
                     coverage=tuple(args.coverage) if args.coverage else None, model=model, seed=args.seed,
                     max_episodes=args.max_episodes, max_seconds=args.max_seconds, progress=not args.no_progress,
                     search=not args.no_search, route=route)
    except GenerationError as exc:
        if rater is None or not rater.unbuildable:
            raise
        err = GenerationError(f"{exc}; {_unbuildable(rater)}")
        err.result = exc.result
        raise err from None
    lo, hi = min(r.difficulties), max(r.difficulties)
    stages = f"{r.found_policy} from the policy's {r.episodes} episodes"
    if r.found_search or r.search_steps:
        stages += f", {r.found_search} from {r.search_steps} search steps"
    what = "difficulty" if route is None else route.name
    park = ""
    if rater is not None:
        shape = ", ".join(f"{k} {v:g}" for k, v in geometry(rater.world).items())
        park = f"; park model {rater.model.key}, geometry {shape} (library key {rater.key})"
        if rater.unbuildable:
            park += f"; {_unbuildable(rater)}"
    print(f"{r.found} distinct garages with {what} {lo:.3f}-{hi:.3f} ({stages}; {r.seconds:.1f} s); "
          f"{r.stored} new in {args.library}{park}")
    return 0


def _in_geometries(args: argparse.Namespace, model, raters: dict) -> int:
    """``--metric park --geometries``: :func:`~garage_mj.scene.park_rating.generate_in_geometries`, and a closing
    line per geometry tried (what it found, its library key)."""
    from garage_mj.scene.park_rating import generate_in_geometries

    tried = generate_in_geometries(args.map, tuple(args.difficulty), args.count, args.library, raters,
                                   max_seconds=args.max_seconds, max_episodes=args.max_episodes, seed=args.seed,
                                   model=model, progress=not args.no_progress, search=not args.no_search,
                                   coverage=tuple(args.coverage) if args.coverage else None)
    done = [t for t in tried if t.result is not None]
    found = sum(t.result.found for t in done)
    stored = sum(t.result.stored for t in done)
    print(f"{found} distinct garages with park difficulty {args.difficulty[0]:g}-{args.difficulty[1]:g} in "
          f"{len(done)} of {len(tried)} park geometries; {stored} new in {args.library} (park model "
          f"{next(iter(raters.values())).model.key})")
    for t in done:
        values = t.result.difficulties
        span = f" ({min(values):.3f}-{max(values):.3f})" if values else ""
        extra = f"; {_unbuildable(t.rater)}" if t.rater.unbuildable else ""
        print(f"  {t.name}: {t.result.found} found{span} in {t.result.episodes} ratings and {t.result.seconds:.1f} s, "
              f"library key {t.rater.key}{extra}")
    return 0


def _unbuildable(rater) -> str:
    """The closing words on the garages ``rater``'s park geometry could not build (skipped, never stored)."""
    n = rater.unbuildable
    return f"{n} garage{'s' if n != 1 else ''} of {rater.rated} rated skipped: the park geometry cannot build them"
