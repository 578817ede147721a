"""The main job end to end on one map: train -> library -> packs -> cruise tests -> park and AVP tests -> report.

Each stage resumes: a finished training run is reused, complete packs are skipped, cruise tests
already in the CSV are not run again. ``garage-mj demo`` and ``make demo`` call :func:`run_demo`.
"""

from __future__ import annotations

import re
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from garage_mj.core.backends import Compute
from garage_mj.core.config import load_config
from garage_mj.core.errors import GarageMJError
from garage_mj.core.fsutil import write_json
from garage_mj.core.words import a_noun
from garage_mj.driving.difficulty.regression import flat_note, too_few
from garage_mj.driving.results import COUNT_COLUMNS, HIT_CLASSES, failed_tests
from garage_mj.driving.sim.outcomes import HIT_KINDS, OUTCOMES, PAPER_CLASS, PAPER_CLASSES, OutcomeConfig
from garage_mj.driving.sources import CruiseSettings, CruiseSource
from garage_mj.export.artefacts import INDEX, PREVIEW
from garage_mj.generation.library import Library
from garage_mj.grid.map_io import load_map
from garage_mj.reporting.failures import run_failures
from garage_mj.reporting.report import (
    GalleryItem,
    ReportData,
    RunFailures,
    count_noun,
    fmt_difficulty,
    fmt_percent,
    write_report,
)

if TYPE_CHECKING:
    from garage_mj.reporting.demo_park import ParkPart

FIGURES = "figures"


class DemoError(GarageMJError):
    """The demo cannot go on (training stored no usable garage)."""


#: The actors of :attr:`DemoConfig.actors` in words (singular, plural).
ACTOR_NOUNS = {"pedestrians": ("pedestrian", "pedestrians"), "moving_cars": ("moving car", "moving cars"),
               "clutter": ("clutter object", "clutter objects")}


@dataclass(frozen=True)
class DemoConfig:
    map: str = "tiny_7x11"
    timesteps: int = 8000  # DQN timesteps per training seed
    train_seeds: tuple[int, ...] = (0, 1, 2)  # the convergence band (95% CI) needs several seeds
    garages: int = 8  # garages sampled from the library, stratified by difficulty
    tests: int = 5  # cruise tests per garage and driver
    drivers: tuple[str, ...] = ("oracle", "waypoint", "vision", "learned")  # learned: models/drivers/cruise_m5.zip
    # adverse events (garage_mj.driving.actors.scenario): these drivers run once more with these actors per test
    actor_drivers: tuple[str, ...] = ("oracle", "vision")
    actors: dict = field(default_factory=lambda: {"pedestrians": 1, "moving_cars": 1, "clutter": 1})
    failure_videos: int = 3  # failures shown per driver run, each with an MP4 and its .xosc
    # park and AVP tests (docs/spec.md section 9): per driver a park run per maneuver and an AVP run, on the first
    # park_garages garages of the sample; each run shows its first failure_videos failures with a top-down picture
    park_drivers: tuple[str, ...] = ("oracle", "park_assist")
    park_maneuvers: tuple[str, ...] = ("reverse", "forward")  # a park run each
    avp_maneuver: str = "any"  # the AVP run's ("": no AVP run)
    park_garages: int = 2
    park_tests: int = 1  # park or AVP tests per garage and run
    workers: int = 2
    seed: int = 0
    out: str = "out/demo"
    extra: dict = field(default_factory=dict)


def _say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


def _train(cfg: DemoConfig, out: Path, map_name: str) -> tuple[Path, list[Path]]:
    from garage_mj.generation.training import read_manifest, train

    library = out / "library.sqlite"
    runs = []
    for s in cfg.train_seeds:
        run = out / "runs" / f"{map_name}_s{s}"  # the map's name, never its path: runs stay inside out
        done = (run / "run.json").exists() and read_manifest(run).get("status") == "finished"
        if done and read_manifest(run).get("timesteps", 0) >= cfg.timesteps:
            _say(f"training {map_name} seed {s}: already finished, reusing {run}")
        else:
            resume = (run / "run.json").exists()
            _say(f"training DQN on {map_name}, seed {s}, {cfg.timesteps} timesteps")
            train(cfg.map, cfg.timesteps, s, run, resume=resume, library_path=library)
        runs.append(run)
    return library, runs


def _render_overview(garage, path: Path, width: int = 480, height: int = 360) -> Path:
    """A MuJoCo render of the garage's scene from the top-down ``overview`` camera."""
    import mujoco

    from garage_mj.scene.mjcf_scene import compile_scene

    model = compile_scene(garage)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with mujoco.Renderer(model, height, width) as renderer:
        renderer.update_scene(data, camera="overview")
        rgb = renderer.render()
    import cv2

    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def run_demo(cfg: DemoConfig) -> Path:
    """Run every stage into ``cfg.out``; returns the report's path."""
    from garage_mj.export.pack import export_pack, write_index
    from garage_mj.reporting import plots

    t0 = time.perf_counter()
    out = Path(cfg.out)
    map_name = load_map(cfg.map).name  # the library stores garages under the map's name, not its path
    figs = out / FIGURES  # after the map is read: a bad --map writes nothing
    figs.mkdir(parents=True, exist_ok=True)
    library_path, runs = _train(cfg, out, map_name)
    with Library(library_path) as lib:
        total = lib.count(map=map_name)
        if total == 0:
            raise DemoError(f"training on {cfg.map} stored no usable garage; raise --timesteps")
        points = lib.points(map=map_name)
        sample = lib.sample(cfg.garages, seed=cfg.seed, stratify="difficulty", map=map_name)
    _say(f"library {library_path}: {total} usable garages; sampled {len(sample)} stratified by difficulty")
    convergence = plots.convergence(runs, figs / "convergence.png")
    heatmap = plots.heatmap(points, figs / "heatmap.png", title=map_name)

    _say(f"exporting {len(sample)} asset packs")
    packs_dir = out / "packs"
    gallery = []
    packs = []
    for rec in sample:
        pack = export_pack(rec.garage, packs_dir)
        packs.append(pack)
        render = figs / f"render_{rec.id}.png"
        if not render.exists():
            _render_overview(rec.garage, render)
        gallery.append(
            GalleryItem(pack.name, rec.difficulty, rec.coverage, rec.stalls, pack / PREVIEW, render, pack)
        )
    write_index(packs_dir)

    cruise = _cruise(cfg, packs, out, figs)
    park = _park(cfg, packs, out)
    data = ReportData(
        title=f"garage-mj demo: {map_name}",
        subtitle=f"DQN {cfg.timesteps:,} timesteps x {count_noun(len(cfg.train_seeds), 'seed')}, "
        f"{count_noun(len(sample), 'garage')}, {count_noun(cfg.tests, 'cruise test')} per garage and driver"
        + (f"; {count_noun(cfg.park_tests, 'park or AVP test')} per garage and run on "
           f"{count_noun(min(cfg.park_garages, len(sample)), 'garage')}" if park.summary is not None else ""),
        kpis={"usable garages": str(total), "asset packs": str(len(packs)), **cruise.kpis, **park.kpis},
        convergence_png=convergence,
        heatmap_png=heatmap,
        gallery=gallery,
        cruise_columns=cruise.columns,
        cruise_rows=cruise.rows,
        cruise_note=cruise.note,
        park_summary=park.summary,
        park_tables=park.tables,
        failures=cruise.failures + park.failures,
        regression_png=cruise.regression_png,
        regression_route_png=cruise.regression_route_png,
        regression_text=cruise.regression_text,
        notes=[
            f"paths are relative to this report's folder ({out}): the folder can be moved",
            f"library: {library_path.relative_to(out).as_posix()}",
            f"asset packs: {packs_dir.relative_to(out).as_posix()}/ ({INDEX} lists them)",
            "cruise runs: cruise/<driver>/ (tests.csv, summary.csv, summary.json, xosc/ with every test "
            "as OpenSCENARIO, videos/ with the failures shown above)",
            *park.notes,
            "paper (docs/spec.md section 5): r(difficulty, success) = -0.638 over 16 garages of the 13x13 aligned map",
            "route difficulty: the expected failure rate of a cruise test predicted from the planned routes "
            "(garage-mj difficulty), beside the paper's difficulty, under the shipped model fitted on the driver "
            "and its action type; n/a where none was (summary.json's route_note)",
        ],
    )
    report = write_report(data, out)
    write_json(out / "demo.json", {"config": cfg.__dict__, "seconds": time.perf_counter() - t0}, indent=None,
               default=str, end="")
    for line in park.lines:
        _say(f"park and AVP: {line}")
    _say(f"report: {report}  ({time.perf_counter() - t0:.0f} s)")
    return report


@dataclass
class _CruisePart:
    """What the cruise stage adds to the report."""

    columns: list[str]
    rows: list[list[object]]
    note: str
    failures: list[RunFailures]
    regression_png: Path
    regression_route_png: Path | None
    regression_text: str
    kpis: dict[str, str]


def actors_text(actors: dict) -> str:
    """``1 pedestrian, 2 moving cars, 1 clutter object``: the actors asked for per test, in words."""
    return ", ".join(count_noun(int(v), *ACTOR_NOUNS.get(k, (k.replace("_", " "),))) for k, v in actors.items() if v)


def run_folder(driver: str, actors: bool = False) -> str:
    """The folder of a driver's cruise run under ``OUT/cruise``: its name (a ``module:Class`` spec with ``:``
    and other characters a file name or a link would trip on as ``_``), ``_actors`` for the run with actors."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", driver)
    return f"{name}_actors" if actors else name


def _cruise(cfg: DemoConfig, packs: list[Path], out: Path, figs: Path) -> _CruisePart:
    """Cruise tests with every driver, each with the action type it declares; the report's table, failures,
    regression figure and KPIs."""
    from garage_mj.driving.drivers import choose_action_type  # MuJoCo (the car), deferred like the runner
    from garage_mj.reporting.cruise import record_cruise_videos, run_cruise  # matplotlib, for regression.png

    sources = [CruiseSource.from_pack(p) for p in packs]
    difficulty = {s.name: s.difficulty for s in sources}  # unrounded, as the gallery's (summary.csv rounds)
    columns = ["garage", "driver", "actions", "difficulty", "route difficulty", "E[X]", "E[Y]", "tests", "infeasible",
               *_failure_cells({k: c.replace("_", " ") for k, c in COUNT_COLUMNS.items()}, "what was hit"),
               "success of feasible"]
    rows: list[list[object]] = []
    failures: list[RunFailures] = []
    fits: dict[str, dict] = {}
    points: dict[str, tuple[Path, list[float], list[float]]] = {}  # per run: its folder, difficulties, success %
    kpis: dict[str, str] = {}
    actors = actors_text(cfg.actors)
    runs = [(d, d, {}) for d in cfg.drivers]
    runs += [(d, f"{d} + actors", {"scenario": dict(cfg.actors)}) for d in cfg.actor_drivers if any(cfg.actors.values())]
    for driver, label, env in runs:
        # the action type the driver is made for (a continuous driver rounded to 4 actions fails far more), recorded as its own
        choice = choose_action_type(driver)
        action = choice.action_type
        _say(f"cruise tests: driver {label} ({action} actions), {count_noun(cfg.tests, 'test')} x "
             f"{count_noun(len(sources), 'garage')}, {count_noun(cfg.workers, 'worker')}")
        folder = out / "cruise" / run_folder(driver, actors=bool(env))
        # xosc: every test as OpenSCENARIO, written as the test starts (cheap), so each failure shown links its own
        result = run_cruise(sources, cfg.tests, CruiseSettings(driver, cfg.seed, env=env), folder,
                            compute=Compute(workers=cfg.workers), choice=choice, xosc=True)
        fits[label] = result.stats
        rated = [r for r in result.summary if r["success_pct"] is not None]
        points[label] = (folder, [float(difficulty[r["garage"]]) for r in rated], [float(r["success_pct"]) for r in rated])
        kpis[f"{label} ({action} actions) success"] = (
            f"{fmt_percent(result.stats['success_pct'])} of {result.stats['feasible']} feasible"
            if result.stats["success_pct"] is not None else "no feasible test")
        hits = result.stats["hits"]
        kpis[f"{label}: collisions by what was hit"] = ", ".join(f"{k} {v}" for k, v in hits.items()) or "none"
        if not env:
            kpis["infeasible tests"] = str(result.stats["infeasible"])  # the same for every driver: scene only
        else:
            kpis[f"infeasible tests with actors ({actors})"] = str(result.stats["infeasible"])
        n_failed = len(failed_tests(result.rows))
        # MP4s of the first failures (with the run's settings, explicit action type included): failures come first
        record_cruise_videos(result, sources, min(cfg.failure_videos, n_failed))
        failed = run_failures(label, folder, result.rows, sources, shown=cfg.failure_videos)
        failures.append(failed)
        _say(f"{label}: {count_noun(sum(failed.counts.values()), 'failure')}; the report shows "
             f"{len(failed.shown)} with an MP4 and a .xosc each")
        for r in result.summary:
            hit = ", ".join(f"{c} {r[f'hit_{c}']}" for c in HIT_CLASSES if int(r[f"hit_{c}"]))
            route = "n/a" if r["route_difficulty"] is None else fmt_difficulty(r["route_difficulty"])
            rows.append([r["garage"], label, action, fmt_difficulty(difficulty[r["garage"]]), route,
                         float(r["E[X]"]), float(r["E[Y]"]), int(r["tests"]), int(r["infeasible"]),
                         *_failure_cells({k: int(r[c]) for k, c in COUNT_COLUMNS.items()}, hit or "-"),
                         fmt_percent(r["success_pct"])])
    main = "vision" if "vision" in fits else cfg.drivers[0]
    shown = figure_run(main, {label: success for label, (_, _, success) in points.items()})
    regression_png = figs / "regression.png"
    if shown == main:
        shutil.copyfile(out / "cruise" / run_folder(main) / "regression.png", regression_png)
    else:  # the main driver's success is the same on every garage: the headline shows a run where it varies
        from garage_mj.reporting.analysis import regression_plot

        _, xs, ys = points[shown]
        regression_plot(xs, ys, regression_png, title=f"Cruise success vs. difficulty ({shown})")
    regression_route_png: Path | None = figs / "regression_route.png"
    # drawn for a run with a route difficulty: a shipped model fitted on its driver and action type
    drawn = [d for d in (main, *cfg.drivers) if (out / "cruise" / run_folder(d) / "regression_route.png").is_file()]
    if drawn:
        shutil.copyfile(out / "cruise" / run_folder(drawn[0]) / "regression_route.png", regression_route_png)
    else:
        regression_route_png = None
    text = "; ".join(
        f"{d}: Pearson r = {_fmt_r(f.get('r'), f['n'])} on the paper's difficulty, {_route_r(f)}, "
        f"over {count_noun(f['garages'], 'garage')}, {count_noun(f['tests'], 'test')}"
        for d, f in fits.items()
    )
    route_fig = f"; route difficulty: the {drawn[0]} driver" if drawn and drawn[0] != shown else ""
    text += f". Figures: the {shown} driver{route_fig}"
    success = points[main][2]
    if flat_note(success) is not None:  # say why the figure is not the main driver's, or why it is flat
        text += (f" (the {main} driver has {success[0]:.0f}% success on each of its {count_noun(len(success), 'garage')}"
                 f" here, so its success does not vary with difficulty"
                 + (f"; its figure is cruise/{run_folder(main)}/regression.png)" if shown != main else ")"))
    text += ". Paper: r = -0.638."
    return _CruisePart(columns, rows, _cruise_note(), failures, regression_png, regression_route_png, text, kpis)


def figure_run(main: str, success: dict[str, list[float]]) -> str:
    """The run the report's regression figure shows: ``main`` unless its success rate is the same on every garage
    (a tiny garage where every test succeeds: a flat line says nothing), then the first run of ``success`` (by
    label, in run order; ``main`` with actors first) whose success varies; ``main`` when none does."""
    if flat_note(success.get(main, [])) is None:
        return main
    order = [f"{main} + actors", *success]
    return next((label for label in order if label in success and len(success[label]) > 1
                 and flat_note(success[label]) is None), main)


def _park(cfg: DemoConfig, packs: list[Path], out: Path) -> ParkPart:
    """Park tests (each maneuver of ``cfg.park_maneuvers``) and AVP tests with each parking driver on the first
    ``cfg.park_garages`` garages; nothing when ``cfg.park_drivers`` is empty."""
    from garage_mj.reporting.demo_park import ParkPart, park_runs, run_park_part  # matplotlib: deferred

    runs = park_runs(cfg.park_drivers, cfg.park_maneuvers, cfg.avp_maneuver)
    sources = [CruiseSource.from_pack(p) for p in packs[: cfg.park_garages]]
    if not runs or not sources:
        return ParkPart()
    return run_park_part(runs, sources, cfg.park_tests, out, cfg.seed, cfg.workers, cfg.failure_videos, _say)


def _failure_cells(per_kind: dict[str, object], hit: object) -> list[object]:
    """The cruise table's failure cells: one per failure kind, in display order, each kind that ends on
    touching something followed by ``hit`` (what was hit)."""
    cells: list[object] = []
    for kind, cell in per_kind.items():
        cells += [cell, hit] if kind in HIT_KINDS else [cell]
    return cells


def _cruise_note() -> str:
    """What the failure columns count (each kind's note in :data:`~garage_mj.driving.sim.outcomes.OUTCOMES`),
    and how they map onto the paper's three classes."""
    values = asdict(OutcomeConfig())
    notes = "; ".join(f"{s.column.replace('_', ' ')}: {s.note.format(**values)}" for s in OUTCOMES if s.note)
    mapped = ", ".join(f"{a_noun(k)} counts as {a_noun(v)}" for k, v in PAPER_CLASS.items() if k != v)
    return (f"{notes[:1].upper()}{notes[1:]}. In the paper's three failure classes ({', '.join(PAPER_CLASSES)}) "
            f"{mapped}. Success is over feasible tests; an infeasible test (no driver of this car can reach the "
            "stall) is never driven.")


def _route_r(stats: dict) -> str:
    """A run's r on the route difficulty, naming the model, or why it has none."""
    if not stats.get("route_model"):
        return "no route difficulty (no shipped model was fitted on this driver with these actions)"
    return f"{_fmt_r(stats.get('route_r'), stats['route_n'])} on the route difficulty ({stats['route_model_name']} model)"


def _fmt_r(r: float | None, n: int) -> str:
    """r as the report says it: 3 decimals, or why there is none (too few garages, a constant success rate)."""
    return too_few(n) or ("n/a (success rate constant)" if r is None or r != r else f"{r:.3f}")


def demo_config(**overrides) -> DemoConfig:
    return load_config(DemoConfig, {k: v for k, v in overrides.items() if v is not None})
