"""``garage-mj generate``: garages of a map in a difficulty band, from a trained conditioned generator.

:func:`generate` works in two stages. First it rolls the generator (:mod:`garage_mj.generation.conditioned`)
out in a batch of envs conditioned on the band asked for, epsilon-greedy with a per-episode epsilon drawn
from the seed so that distinct garages appear, and stores every distinct, usable garage that lands in the band
in the scenario library. When that does not fill the band within :data:`POLICY_PATIENCE`
episodes, a band-directed local search takes over (:class:`garage_mj.generation.search.BandClimber`): it
starts from the usable garages the policy painted, nearest to the band first (and a few of the
scripted painter's, for variety), mutates their road
sets under the painter's rules toward the band and then inside it, and re-paints every new road
set that lands in the band through ``GarageGenEnv`` (:func:`garage_mj.generation.search.replay`), so what
is stored is what the painter makes.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from garage_mj.generation.cond_env import GarageGenCondEnv, band_distance
from garage_mj.generation.conditioned import (
    GENERATOR,
    GENERATOR_META,
    GenerationError,
    load_policy,
    shipped_generator,
    train_command,
)
from garage_mj.generation.library import Library
from garage_mj.generation.search import BandClimber, replay
from garage_mj.generation.window_net import OneHotWindow, WindowLayer
from garage_mj.grid.blocks import AXES
from garage_mj.grid.garage import Garage
from garage_mj.grid.map_io import list_maps, load_map
from garage_mj.grid.metrics import GarageMetrics, evaluate
from garage_mj.grid.painters import paint_garage

EPS_RANGE = (0.02, 0.3)  # per-episode exploration of generate, drawn uniformly
GEN_ENVS = 16  # envs stepped together by generate (one batched Q-network call)
POLICY_PATIENCE = (100, 10)  # generate's policy stage gets a + b * count episodes before the search joins in
POLICY_TIME_SHARE = 0.5  # ... and at most this share of --max-seconds
SEARCH_STEPS_PER_EPISODE = 20  # search mutations that count as one episode of the budget (~0.1-0.3 ms each
#                                against ~5-10 ms for a rollout episode on a 13x13 map; a replay counts as one)
SEARCH_SEEDS = 8  # garages of the scripted painter per six-stall axis that seed the search next to the policy's
ROUTE_POLICY_EPISODES = 20  # by route difficulty: policy episodes (each usable garage rated) before the search
MAX_COUNT = 1_000_000  # [garages] the most one call stores (--count)
MAX_EPISODES = 1_000_000_000  # the largest episode budget (--max-episodes)


@dataclass(frozen=True)
class RouteMetric:
    """Generate by a route difficulty instead of the paper's: ``rate(garage)`` gives it (NaN: no feasible
    stall), ``key`` names the model it comes from (stored with each value in the library).

    The generation stage does not plan routes: the caller passes the rater
    (``garage_mj.scene.route_difficulty.route_difficulty`` with a model, as ``garage-mj generate --metric route`` does;
    ``garage_mj.scene.park_rating.ParkRater`` for ``--metric park``, ``name="park difficulty"``, its key naming the park
    model and geometry).
    """

    rate: Callable[[Garage], float]
    key: str
    name: str = "route difficulty"  # what the value is called in the progress bar and the error of an unfilled band


class _Rated:
    """A :class:`RouteMetric`'s ``rate`` with its values kept by garage hash (each garage is rated once a call)."""

    def __init__(self, metric: RouteMetric) -> None:
        self.metric = metric
        self.values: dict[str, float] = {}

    def __call__(self, garage: Garage) -> float:
        h = garage.canonical_hash()
        if h not in self.values:
            self.values[h] = float(self.metric.rate(garage))
        return self.values[h]


@dataclass
class GenerateResult:
    """What :func:`generate` did."""

    found: int  # distinct garages in the band found by this call
    stored: int  # of them, new to the library
    ids: list[int]  # library ids of the garages this call stored (new ones)
    episodes: int
    seconds: float  # wall-clock time of the rollouts
    difficulties: list[float]
    cpu_seconds: float = 0.0  # CPU time of this process during the rollouts and the search
    found_policy: int = 0  # of ``found``, painted by the policy's rollouts (library run ``generate:<model>``)
    found_search: int = 0  # of ``found``, from the search stage (run ``generate:<model>+search``)
    search_steps: int = 0  # mutations the search stage evaluated
    replays: int = 0  # road sets the search stage re-painted through GarageGenEnv
    search_seeds: int = 0  # garages the search started from (usable garages of the policy, or painter garages)


class _Collector:
    """What both stages share: the library, the bands, the clock, and the store of garages found.

    :meth:`keep` stores a garage that is usable, new to this call and in the bands, and counts
    it in :attr:`result`; :meth:`elapsed` is the ``clock`` time since ``c0``, when the call began.
    """

    def __init__(self, lib: Library, map_name: str, run: str, seed: int, difficulty: tuple[float, float],
                 coverage: tuple[float, float], count: int, result: GenerateResult, bar: Any,
                 clock: Callable[[], float], c0: float, route: _Rated | None = None) -> None:
        self.lib, self.map_name, self.run, self.seed, self.route = lib, map_name, run, seed, route
        self.difficulty, self.coverage, self.count, self.result, self.bar = difficulty, coverage, count, result, bar
        self.clock, self.c0 = clock, c0
        self.seen: set[str] = set()

    def elapsed(self) -> float:
        return self.clock() - self.c0

    def keep(self, g: Garage, m: GarageMetrics, stage: str, episode: int, timestep: int) -> bool:
        """Store ``g`` (metrics ``m``) if it is usable, new to this call and in the bands."""
        key = g.canonical_hash()
        if key in self.seen or not m.usable or band_distance(m.coverage, self.coverage) > 0.0:
            return False
        value = m.difficulty if self.route is None else self.route(g)
        if not value == value or band_distance(value, self.difficulty) > 0.0:  # NaN: no feasible stall
            return False
        self.seen.add(key)
        result = self.result
        new = self.lib.add(g, map=self.map_name, run=self.run + ("+search" if stage == "search" else ""),
                           seed=self.seed, episode=episode, timestep=timestep)
        if self.route is not None:
            stored = new if new is not None else self.lib.id_of(key)
            if stored is not None:
                self.lib.set_route_difficulty(stored, self.route.metric.key, value)
        result.found += 1
        if stage == "search":
            result.found_search += 1
        else:
            result.found_policy += 1
        result.stored += new is not None
        if new is not None:
            result.ids.append(new)
        result.difficulties.append(value)
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(stage=stage, episodes=result.episodes, search_steps=result.search_steps, refresh=False)
        return True


def _generator_path(map: str, garage0: Garage, model: str | Path | None) -> Path:
    """The generator file: ``model`` (a file, or a shipped map's name), else the shipped one of ``map``."""
    shipped_name = isinstance(map, str) and "/" not in map and garage0.name in {m.name for m in list_maps()}
    if model is None:
        path = shipped_generator(garage0.name) if shipped_name else None
        if path is None:
            raise GenerationError(f"no trained generator for map {map!r}; train one with: {train_command(map)}")
    else:
        path = Path(model)
        if not path.is_file() and "/" not in str(model) and shipped_generator(str(model)) is not None:
            path = shipped_generator(str(model))  # a shipped generator by its map's name
        if not path.is_file():
            raise GenerationError(f"--model {model} does not exist (a generator file, or a shipped map's name)")
    return path


def generator_meta(path: Path) -> dict[str, Any]:
    """The ``generator.json`` beside a generator (its env settings), or {} when there is none."""
    meta_path = path.with_suffix(".json") if path.with_suffix(".json").is_file() else path.with_name(GENERATOR_META)
    return json.loads(meta_path.read_text()) if meta_path.is_file() else {}


def reads_codes(policy: Any) -> bool:
    """Whether a generator's Q-network reads the window as block codes (trained on the vector env, ``fast``
    learner: :class:`WindowLayer` or :class:`OneHotWindow` first) rather than as the single env's one-hot rows."""
    return isinstance(policy.q_net.features_extractor, (WindowLayer, OneHotWindow))


def policy_observation_space(policy: Any, env: GarageGenCondEnv) -> Any:
    """The space of the observations ``policy`` reads from ``env``: its codes window when it :func:`reads_codes`,
    else the env's own (one-hot) observation."""
    return env.codes_observation_space() if reads_codes(policy) else env.observation_space


def _policy_stage(policy: Any, envs: list[GarageGenCondEnv], rng: np.random.Generator, collector: _Collector,
                  episodes: int, seconds: float | None, pool: list[tuple[float, int, Garage]] | None) -> int:
    """Stage 1: roll the policy out in ``envs`` for up to ``episodes`` episodes (and ``seconds``).

    Each episode draws its reset seed and its epsilon from ``rng``. Garages that land in the bands go
    to the collector; when ``pool`` is given, every usable garage goes there too as (distance to
    the bands, episode, garage), for the search. The policy sees the envs' observations, or their windows
    as block codes when it :func:`reads_codes`. Returns the env steps taken.
    """
    result, n_envs = collector.result, len(envs)
    codes = reads_codes(policy)
    by_route = collector.route is not None
    paper_band = tuple(collector.difficulty)
    started = 0
    eps = np.zeros(n_envs)
    episode_of = [0] * n_envs
    obs = np.zeros((n_envs,) + policy_observation_space(policy, envs[0]).shape, dtype=np.float32)
    active = np.zeros(n_envs, dtype=bool)

    def observe(i: int, one_hot: np.ndarray) -> None:
        if codes:
            envs[i]._codes_obs(obs[i])
        else:
            obs[i] = one_hot

    def start(i: int) -> None:
        nonlocal started
        # by route difficulty, episode j asks the policy for the paper's band j mod 10 (0-0.1, 0.1-0.2, ...):
        # seeds of every kind for the search, which the two difficulties' correlation spreads over route bins
        band = paper_band if not by_route else (started % 10 / 10, (started % 10 + 1) / 10)
        observe(i, envs[i].reset(seed=int(rng.integers(2**31)),
                                 options={"difficulty": band, "coverage": collector.coverage})[0])
        eps[i] = rng.uniform(*EPS_RANGE)
        episode_of[i] = started
        active[i] = True
        started += 1

    steps = 0
    for i in range(min(n_envs, episodes)):
        start(i)
    while active.any() and result.found < collector.count:
        if seconds is not None and collector.elapsed() >= seconds:
            break
        with torch.no_grad():
            greedy = policy.q_net(torch.as_tensor(obs)).argmax(dim=1).numpy()
        explore = rng.random(n_envs) < eps
        random_a = rng.integers(4, size=n_envs)
        for i in np.flatnonzero(active):
            a = int(random_a[i] if explore[i] else greedy[i])
            one_hot, _, term, trunc, info = envs[i].step(a)
            observe(i, one_hot)
            steps += 1
            if not (term or trunc):
                continue
            result.episodes += 1
            active[i] = False
            if info["usable"]:
                g = envs[i].garage()
                if pool is not None:
                    d = collector.route(g) if by_route else info["difficulty"]  # a rating is kept: rated once
                    dist = (band_distance(d, collector.difficulty) if d == d else float("inf")) \
                        + band_distance(info["coverage"], collector.coverage)
                    pool.append((dist, episode_of[i], g))
                if (by_route or info["in_band"]) and result.found < collector.count:
                    collector.keep(g, evaluate(g), "policy", episode_of[i], steps)
            if started < episodes and result.found < collector.count:
                start(i)
    return steps


def _search_stage(garage0: Garage, coverage: tuple[float, float] | None, seed: int, max_errors: int,
                  collector: _Collector, pool: list[tuple[float, int, Garage]], max_episodes: int,
                  max_seconds: float | None, steps: int) -> None:
    """Stage 2: the band-directed local search from the policy's usable garages (``pool``).

    The climb starts from the pool, nearest to the bands first, and from the scripted painter's
    garages; every road set it finds in the bands is re-painted through the painter env and kept
    if the painter makes the same usable garage. Stops at ``max_episodes`` (rollout episodes,
    replays and search steps / :data:`SEARCH_STEPS_PER_EPISODE`) or ``max_seconds``.
    """
    result = collector.result
    climber = BandClimber(garage0, collector.difficulty, coverage, rng=np.random.default_rng([seed, 1]),
                          metric=collector.route)
    pool.sort(key=lambda e: (e[0], e[1]))  # nearest to the band first, then oldest
    for _, _, g in pool:
        result.search_seeds += climber.add(g) is not None
    # and the scripted painter's garages, as the search baseline starts from: the policy's garages are
    # often one family, and the climb restarts from these too when it stalls (they alone seed it when
    # the policy painted nothing usable)
    for k in range(SEARCH_SEEDS):
        for axis in AXES:
            result.search_seeds += climber.add(
                paint_garage(garage0, seed=seed * 1000 + k, six_stall_axis=axis)) is not None
    if collector.bar is not None:
        collector.bar.set_postfix(stage="search", episodes=result.episodes, refresh=True)
    while result.found < collector.count and (climber.climbers or climber.inside):
        if collector.route is None:
            spent = result.episodes + result.replays + result.search_steps / SEARCH_STEPS_PER_EPISODE
        else:  # by route difficulty, what costs is a rating (a failed mutation or a repeat costs next to nothing)
            spent = result.episodes + len(collector.route.values)
        if spent >= max_episodes:
            break
        if max_seconds is not None and (collector.route is not None or result.search_steps % 16 == 0) \
                and collector.elapsed() >= max_seconds:
            break
        found = climber.step()
        result.search_steps += 1
        if found is None:
            continue
        painted, info = replay(found[0], max_errors=max_errors)
        result.replays += 1
        if info.get("usable") and np.array_equal(painted.grid, found[0].grid):
            collector.keep(painted, evaluate(painted), "search", result.search_steps, steps)


def _not_filled(result: GenerateResult, count: int, map_name: str, difficulty: tuple[float, float],
                coverage: tuple[float, float] | None, search: bool, max_seconds: float | None,
                library: str | Path, metric: str = "difficulty") -> GenerationError:
    """The error of a call that did not find ``count`` garages, carrying its result."""
    cov = coverage or (0.0, 1.0)
    what = f"{metric} in [{difficulty[0]}, {difficulty[1]}]" + (
        f" and coverage in [{cov[0]}, {cov[1]}]" if coverage is not None else "")
    searched = f" and {result.search_steps} search steps" if search and result.search_steps else ""
    exc = GenerationError(
        f"found {result.found} of {count} distinct usable garages of {map_name} with {what} in "
        f"{result.episodes} episodes{searched} ({result.seconds:.0f} s; {result.stored} new stored in {library}); "
        f"{'' if max_seconds is None else f'--max-seconds {max_seconds:g}; '}"
        "widen the band, raise --max-episodes, or see what the map admits (eval/admissible.py)")
    exc.result = result
    return exc


def generate(map: str, difficulty: tuple[float, float], count: int, library: str | Path, *,
             coverage: tuple[float, float] | None = None, model: str | Path | None = None, seed: int = 0,
             max_episodes: int | None = None, max_seconds: float | None = None, progress: bool = True,
             n_envs: int = GEN_ENVS, clock: Callable[[], float] = time.perf_counter,
             search: bool = True, route: RouteMetric | None = None) -> GenerateResult:
    """Store ``count`` distinct usable garages of ``map`` with difficulty (and coverage) in the bands.

    Stage 1 rolls out the generator; if it has not filled the band after ``POLICY_PATIENCE``
    episodes (``a + b * count``) or :data:`POLICY_TIME_SHARE` of ``max_seconds``, stage 2 (unless
    ``search=False``) climbs from the usable garages it painted toward the band (module docstring).
    The budget is shared: a rollout episode or a replay counts one episode,
    :data:`SEARCH_STEPS_PER_EPISODE` search mutations count one. Raises :class:`GenerationError`
    (after storing what it found) when ``max_episodes`` (default ``2,000 + 200 * count``) or
    ``max_seconds`` measured by ``clock`` (wall time; ``time.process_time`` for CPU time on a
    shared machine) do not find ``count``. The same seed gives the same garages (unless
    ``max_seconds`` cuts a run short).

    ``route`` generates by a route difficulty instead (:class:`RouteMetric`): ``difficulty`` is then a band
    of it; the policy's rollouts (:data:`ROUTE_POLICY_EPISODES`, asking in turn for each tenth of the
    paper's difficulty, for seeds of every kind) and the
    search's new road sets are each rated (a rating counts one episode of the budget, whose default is
    then ``100 + 20 * count``), and every garage stored gets its value in the library.
    """
    for name, band in (("difficulty", difficulty), ("coverage", coverage)):
        if band is not None and not 0.0 <= band[0] <= band[1] <= 1.0:
            raise GenerationError(f"--{name} {band[0]} {band[1]}: need 0 <= LO <= HI <= 1")
    if not 1 <= count <= MAX_COUNT:
        raise GenerationError(f"--count {count} is not allowed: give an integer from 1 to {MAX_COUNT:,}")
    if max_episodes is not None and not 1 <= max_episodes <= MAX_EPISODES:
        raise GenerationError(f"--max-episodes {max_episodes} is not allowed: give an integer from 1 to "
                              f"{MAX_EPISODES:,}")
    if max_seconds is not None and not (math.isfinite(max_seconds) and max_seconds > 0):
        raise GenerationError(f"--max-seconds {max_seconds:g} is not allowed: give a number of seconds > 0")
    garage0 = load_map(map)
    path = _generator_path(map, garage0, model)
    meta = generator_meta(path)
    if max_episodes is None:
        max_episodes = 2_000 + 200 * count if route is None else 100 + 20 * count
    rated = _Rated(route) if route is not None else None
    max_errors = meta.get("max_errors", 10)
    torch.set_num_threads(1)
    policy = load_policy(path)
    policy.set_training_mode(False)
    envs = [GarageGenCondEnv(map=garage0, view_size=meta.get("view_size", 7), max_errors=max_errors)
            for _ in range(n_envs)]
    space = policy_observation_space(policy, envs[0])
    if policy.observation_space.shape != space.shape:
        raise GenerationError(f"{path} was trained with observations of shape {policy.observation_space.shape}, "
                              f"this map's env gives {space.shape}")
    rng = np.random.default_rng(seed)
    run = f"generate:{path.stem if path.name != GENERATOR else path.parent.name}"
    usable_pool: list[tuple[float, int, Garage]] | None = [] if search else None  # of the rollouts, for the search
    result = GenerateResult(0, 0, [], 0, 0.0, [])
    t0, cpu0, c0 = time.perf_counter(), time.process_time(), clock()
    patience = POLICY_PATIENCE[0] + POLICY_PATIENCE[1] * count if search else max_episodes
    if rated is not None and search:
        patience = ROUTE_POLICY_EPISODES
    policy_seconds = None if max_seconds is None else (max_seconds * POLICY_TIME_SHARE if search else max_seconds)
    bar = None
    if progress:
        from tqdm import tqdm

        what = "difficulty" if route is None else route.name
        bar = tqdm(total=count, desc=f"{garage0.name} {what} {difficulty[0]:.2f}-{difficulty[1]:.2f}",
                   unit="garage", dynamic_ncols=True)
    try:
        with Library(library) as lib:
            collector = _Collector(lib, garage0.name, run, seed, difficulty, coverage or (0.0, 1.0), count, result,
                                   bar, clock, c0, rated)
            steps = _policy_stage(policy, envs, rng, collector, min(max_episodes, patience), policy_seconds,
                                  usable_pool)
            if usable_pool is not None and result.found < count:
                _search_stage(garage0, coverage, seed, max_errors, collector, usable_pool, max_episodes, max_seconds,
                              steps)
    finally:  # an error is printed on a line of its own, never after the bar
        if bar is not None:
            bar.close()
    result.seconds = time.perf_counter() - t0
    result.cpu_seconds = time.process_time() - cpu0
    if result.found < count:
        raise _not_filled(result, count, garage0.name, difficulty, coverage, search, max_seconds, library,
                          "difficulty" if route is None else route.name)
    return result


__all__ = ["GenerateResult", "GenerationError", "RouteMetric", "generate", "generator_meta", "policy_observation_space",
           "reads_codes"]
