"""Where the long jobs run: :func:`map_unordered` over a local process pool or a Ray cluster, as a
:class:`Compute` says (workers, backend, Ray address, progress bar).

Used by ``garage-mj cruise`` (one job per test), ``generation/run.py`` (one job per DQN run)
and meant for any batch of independent jobs (``garage-mj hunt``). Results come back as jobs
end, in no fixed order; the caller writes each one down as it arrives, so an interrupted batch
loses nothing that ended and a re-run resumes. Job results never depend on the backend: every
job carries its own seed.

Backends:

``local`` (default)
    ``workers <= 1``: the jobs run one after another in this process (a crash of a job is a crash
    of this process; a time limit is an interval timer, SIGALRM, on the main thread). Otherwise a
    supervised pool of ``spawn`` processes (each worker imports the package afresh, so it opens its
    own GL context), one job at a time per worker, jobs handed out in the given order. The parent
    waits on the workers' pipes and process sentinels, so a worker that dies (a segfault, the OOM
    killer, ``kill -9``) is noticed at once: it is replaced and its job given again, once
    (:data:`LOCAL_RETRIES`); a job past its time limit has its worker killed and replaced. A job
    lost so is the caller's ``on_lost`` to record (:class:`LostJob`), else one :class:`BackendError` line.
``ray``
    One Ray actor per worker slot (a long-lived process, ``num_cpus=1``), so per-process caches
    (cruise keeps one compiled MuJoCo scene per garage) survive from job to job as in a pool
    worker; jobs are handed out in the given order to whichever actor is free, so jobs sorted
    by garage build each scene at most once per actor. Without ``address`` a private local Ray
    is started (node address 127.0.0.1, ``num_cpus=workers``, no dashboard, warnings only; its
    gRPC ports still listen on every interface, behind Ray's token auth) and shut down at the
    end; with ``address`` (``HOST:6379``) the batch joins a running cluster (``ray start
    --head``). A Ray already initialised in this process (:func:`ray_session`) is used as it is.
    Workers get the parent's :data:`WORKER_ENV` variables (``MUJOCO_GL`` ...) through the
    runtime env, as spawned pool workers inherit them. A job whose worker process or node dies
    is retried on a restarted actor up to ``max_retries`` times (Ray's actor restarts), then the
    batch stops with one :class:`BackendError` line (or the caller's ``on_lost`` records it); an
    exception the job itself raises is re-raised here as it is, without retry. A time limit is the
    actor's interval timer, as in this process.

:func:`stream_unordered` is for long jobs that report as they go (a DQN run sends each garage
and checkpoint as it is made, :mod:`garage_mj.generation.remote`): the job is a generator, and
every item it yields comes back to this process at once. On Ray each job is a task (one CPU,
any node, at most ``workers`` at a time); a job whose worker process or node is lost is
submitted again as the caller says (a run resumes from the newest checkpoint this process
holds), so a lost node costs the work since that checkpoint, not the batch.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import multiprocessing as mp
import numbers
import os
import signal
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing import connection
from typing import Any

from garage_mj.core.errors import GarageMJError

BACKENDS = ("local", "ray")
#: Environment variables a Ray worker gets from the parent (when set there), as a spawned pool worker would.
WORKER_ENV = ("MUJOCO_GL", "PYOPENGL_PLATFORM", "MUJOCO_EGL_DEVICE_ID", "EGL_DEVICE_ID", "OMP_NUM_THREADS",
              "MKL_NUM_THREADS")
#: ... and every variable with this prefix (``GARAGE_MJ_QC_OPENDRIVE`` ...).
WORKER_ENV_PREFIX = "GARAGE_MJ_"
#: How many times the local pool gives a job again after its worker process died (a segfault, the OOM killer, kill -9).
LOCAL_RETRIES = 1
#: Exit status of a pool worker that ended because its parent process had ended.
PARENT_GONE_EXIT = 70
#: The private local Ray: workers at the parent's priority (Ray's default niceness 15 starves them on a machine
#: busy with other jobs, where pool workers would compete as equals), and no idle workers started ahead (the
#: actors need their own, with the runtime env).
_LOCAL_CONFIG = {"worker_niceness": 0, "prestart_worker_first_driver": False, "enable_worker_prestart": False}


class BackendError(GarageMJError):
    """The backend cannot run the batch (unknown backend, Ray missing or unreachable, a worker lost for good)."""


@dataclass(frozen=True)
class Compute:
    """How a batch of jobs runs: how many at a time, where, and whether a progress bar shows.

    Results never depend on it (every job carries its own seed). Built once (the CLI from
    ``--workers``, ``--backend``, ``--address`` and ``--quiet``) and passed down whole. A bad value
    is one :class:`BackendError` line, raised here; :func:`check_backend` also checks that Ray is there.
    """

    workers: int = 1  # processes at a time: the local pool's size, Ray actors or tasks
    backend: str = "local"  # one of BACKENDS (module docstring)
    address: str | None = None  # with backend "ray": a running cluster's HOST:PORT; None: a private local Ray
    progress: bool = True  # a tqdm progress bar on stderr

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise BackendError(f"unknown backend {self.backend!r}; choose one of {', '.join(BACKENDS)}")
        if self.address is not None and self.backend != "ray":
            raise BackendError("--address names a Ray cluster; use it with --backend ray")
        if self.address is not None and not isinstance(self.address, str):
            raise BackendError(f"address must be a Ray cluster's HOST:PORT, got {self.address!r}")
        if not isinstance(self.workers, numbers.Integral) or isinstance(self.workers, bool) or self.workers < 1:
            raise BackendError(f"workers must be >= 1, got {self.workers!r}")
        if not isinstance(self.progress, bool):
            raise BackendError(f"progress must be True or False, got {self.progress!r}")


#: One job at a time in this process, with a progress bar: what every long job does unless told otherwise.
DEFAULT_COMPUTE = Compute()


def check_backend(compute: Compute, reach: bool = False) -> None:
    """Fail fast, before any job, when the backend cannot run: Ray not installed for ``backend="ray"``
    (the values themselves were checked when ``compute`` was made); with ``reach``, also a cluster
    ``address`` that accepts no connection (a command checks it before it writes anything)."""
    if compute.backend == "ray":
        _ray()
        if reach and compute.address is not None:
            _reachable(compute.address)


def worker_env() -> dict[str, str]:
    """The variables Ray workers get from this process (see :data:`WORKER_ENV`).

    MUJOCO_GL has its default here already: importing any ``garage_mj`` module runs the package's
    ``__init__``, which sets it.
    """
    return {k: v for k, v in os.environ.items() if k in WORKER_ENV or k.startswith(WORKER_ENV_PREFIX)}


def map_unordered(func: Callable[[Any], Any], jobs: Sequence[Any], *, compute: Compute = DEFAULT_COMPUTE,
                  max_retries: int = 3, timeout: float | Callable[[Any], float | None] | None = None,
                  on_lost: Callable[[Any, LostJob], Any] | None = None) -> Iterator[Any]:
    """``func(job)`` for every job, yielded as each ends (in no fixed order), on ``compute``'s backend.

    ``func`` must be a module-level function (pickled by reference: a Ray node needs the same
    package installed); ``compute.workers`` is the number of processes (local pool size or Ray
    actors). ``compute.progress`` is the caller's to show. Closing the iterator early (an exception,
    Ctrl-C) stops the workers; what was yielded stays done.

    ``timeout`` [s]: the wall time a job may take (None: no limit; a function: each job's own). A job
    that the backend loses (its worker died again after the retries, or it ran past its time) yields ``on_lost(job,`` a
    :class:`LostJob` ``)`` in place of its result; without ``on_lost`` it stops the batch with one
    :class:`BackendError` line. A job's own exception is re-raised here as it is, never retried; a job that raises
    ``SystemExit`` (``sys.exit``, which would end the process running it) is lost as a ``"crash"`` on its one try,
    the same in this process and in a worker, and ``KeyboardInterrupt`` stops the batch.
    """
    check_backend(compute)
    jobs = list(jobs)
    if not jobs:
        return iter(())
    limits = [timeout(job) if callable(timeout) else timeout for job in jobs]
    if compute.backend == "ray":
        return _ray_map(func, jobs, compute, max_retries, limits, on_lost)
    return _local_map(func, jobs, compute.workers, limits, on_lost)


# -- local --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LostJob:
    """A job the local backend gave up on: its worker process died twice (``kind`` ``"crash"``), or it ran
    past the time limit (``"timeout"``). What :func:`map_unordered`'s ``on_lost`` gets, with the job."""

    kind: str  # "crash" or "timeout"
    reason: str  # one line: the signal or exit code, or the limit
    seconds: float  # [s] wall time of its last try


_REPEAT_S = 0.25  # [s] how often a time limit that ran out raises again, until the job gives way


class _JobTimeout(BaseException):
    """Raised inside a job run in this process when its time is up (a BaseException: a job's ``except
    Exception`` does not swallow it)."""


def timeout_reason(seconds: float) -> str:
    """What a job that ran past ``seconds`` is told, the same wherever it ran."""
    return f"ran past the time limit of {seconds:g} s of wall time"


def _in_finalizer(frame) -> bool:
    """Whether ``frame`` runs inside a finalizer (``__del__``, a ``weakref.finalize`` callback) or a callback of the
    garbage collector (``gc.callbacks``; hypothesis's pytest plugin keeps one): Python swallows what is raised there
    and reports it as unraisable, so a time limit must wait for its next alarm."""
    gc_codes = {getattr(getattr(cb, "__func__", cb), "__code__", None) for cb in gc.callbacks}
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or code.co_filename.endswith("weakref.py") or code in gc_codes:
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def _time_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`_JobTimeout` in this block after ``seconds`` of wall time (an interval timer, SIGALRM:
    only on the main thread of a POSIX process; elsewhere no limit). Interrupts Python code and waits
    (``time.sleep``, locks, sockets), not a C call that never returns: a pool worker is killed for that.
    The timer repeats every :data:`_REPEAT_S` until the block ends, since a raise that lands in a
    ``__del__``, a weakref or a gc callback is swallowed there: :func:`_in_finalizer` holds it back where it can
    tell, and where it cannot (a dealloc in C code) the swallowed raise is not reported as an unraisable
    exception, since the next alarm raises it again."""
    usable = (seconds is not None and hasattr(signal, "setitimer")
              and threading.current_thread() is threading.main_thread())
    if not usable:
        yield
        return
    armed = [True]

    def expire(signum, frame):  # noqa: ARG001
        if armed[0] and not _in_finalizer(frame):  # in a finalizer the raise is lost: the next alarm raises
            raise _JobTimeout

    def unraisable(info) -> None:
        """A raise of ours that landed where Python swallows it is no error (the next alarm raises it again);
        anything else is reported as before."""
        if not isinstance(info.exc_value, _JobTimeout):
            outer_hook(info)

    outer_hook = sys.unraisablehook
    sys.unraisablehook = unraisable
    old = signal.signal(signal.SIGALRM, expire)
    start = time.monotonic()
    outer, _ = signal.setitimer(signal.ITIMER_REAL, seconds, _REPEAT_S)  # a timer of the caller's (pytest-timeout)
    try:
        yield
    finally:
        while True:  # a last alarm may land in here: disarm, then put everything back
            try:
                armed[0] = False
                signal.setitimer(signal.ITIMER_REAL, 0)
                signal.signal(signal.SIGALRM, old)
                if sys.unraisablehook is unraisable:
                    sys.unraisablehook = outer_hook
                if outer > 0:  # the caller's timer goes on with what it had left
                    signal.setitimer(signal.ITIMER_REAL, max(outer - (time.monotonic() - start), 1e-3))
                break
            except _JobTimeout:
                continue


def _exits(exc: BaseException) -> bool:
    """An exception a job raised that would end the process running it (``SystemExit`` from ``sys.exit``, or another
    ``BaseException`` that is not an ``Exception``): the job is lost as a crash, as when its worker process dies.
    Not Ctrl-C (``KeyboardInterrupt`` stops the batch) and not a time limit running out."""
    return not isinstance(exc, (Exception, KeyboardInterrupt, _JobTimeout))


def exit_reason(exc: BaseException) -> str:
    """What a job that raised ``exc`` (:func:`_exits`) is told, the same wherever it ran: ``it raised SystemExit(0)``."""
    args = ", ".join(map(repr, exc.args))
    text = f"{type(exc).__name__}({args})"
    return f"it raised {text if len(text) <= 200 else text[:197] + '...'}"


def _limited(func: Callable[[Any], Any], job: Any, timeout: float | None) -> Any:
    """``func(job)``, or a :class:`LostJob` of kind ``"timeout"`` when it runs past ``timeout`` seconds, or of kind
    ``"crash"`` when it raises ``SystemExit`` (or another exception that would end the process, :func:`_exits`)."""
    start = time.perf_counter()
    try:
        with _time_limit(timeout):
            return func(job)
    except _JobTimeout:
        return LostJob("timeout", timeout_reason(timeout), time.perf_counter() - start)
    except BaseException as exc:
        if not _exits(exc):
            raise
        return LostJob("crash", exit_reason(exc), time.perf_counter() - start)


def _tries(n: int) -> str:
    return "on its one try" if n == 1 else f"on each of {n} tries"


def process_end(exitcode: int | None) -> str:
    """How a worker process ended, in words (``was killed by signal SIGSEGV``, ``exited with code 3``)."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"was killed by signal {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"was killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


def _exit_with_parent() -> None:
    """End this worker process as soon as the process that started it has ended, however it ended.

    A parent stopped by SIGTERM or SIGKILL runs no ``finally``, so it cannot stop its workers; without
    this they would go on with their jobs (writing into the batch's folder) with nobody to read the results.
    """
    parent = mp.parent_process()
    if parent is None:
        return

    def watch() -> None:
        connection.wait([parent.sentinel])  # readable once the parent is gone
        os._exit(PARENT_GONE_EXIT)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _serve(conn, func: Callable[[Any], Any]) -> None:
    """A pool worker: run the jobs that arrive on ``conn`` one at a time, sending ("start", i) as each begins
    and ("done", i, ok, result or exception) as it ends, until None arrives or the parent process ends."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's: it stops the workers
    _exit_with_parent()
    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        if msg is None:
            return
        index, job = msg
        conn.send(("start", index))
        start = time.perf_counter()
        try:
            reply = ("done", index, True, func(job))
        except Exception as exc:  # noqa: BLE001  (the job's own error: re-raised in the parent)
            reply = ("done", index, False, exc)
        except BaseException as exc:
            if not _exits(exc):
                raise
            # sys.exit in the job: lost as a crash, as in the parent's own process; the parent starts a fresh worker
            conn.send(("done", index, True, LostJob("crash", exit_reason(exc), time.perf_counter() - start)))
            return
        try:
            conn.send(reply)
        except Exception as exc:  # noqa: BLE001  (a result or error that does not pickle)
            conn.send(("done", index, False, BackendError(f"job {index}: its result cannot be sent back to the "
                                                          f"parent process: {_first_line(exc)}")))


class _Worker:
    """One spawned worker process of the supervised local pool, and the job it is running."""

    def __init__(self, ctx, func: Callable[[Any], Any]) -> None:
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(child, func), daemon=True)
        self.proc.start()
        child.close()
        self.job: int | None = None  # the index of the job it was given
        self.since: float | None = None  # when that job started (the worker said so)

    def give(self, index: int, job: Any) -> None:
        self.job, self.since = index, None
        with contextlib.suppress(OSError):  # it died while idle: read() finds it gone, the job goes to another
            self.conn.send((index, job))

    def read(self) -> tuple[str, Any] | None:
        """What became of its job: ("done", (ok, result or exception)), ("died", how), or None (still running)."""
        try:
            while self.conn.poll():
                msg = self.conn.recv()
                if msg[0] == "start":
                    self.since = time.monotonic()
                    continue
                self.job = None
                return "done", (msg[2], msg[3])
        except (EOFError, OSError):
            pass
        if self.proc.is_alive():
            return None
        self.proc.join()
        return "died", process_end(self.proc.exitcode)

    def overdue(self, limit: float | None) -> bool:
        return limit is not None and self.since is not None and time.monotonic() - self.since >= limit

    def stop(self, kill: bool = False) -> None:
        if kill:
            self.proc.kill()
        else:
            with contextlib.suppress(OSError):
                self.conn.send(None)
        self.proc.join(5.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def _local_map(func: Callable[[Any], Any], jobs: list, workers: int, limits: list[float | None],
               on_lost: Callable[[Any, LostJob], Any] | None) -> Iterator[Any]:
    lost = on_lost if on_lost is not None else _stop_batch
    if workers <= 1:  # in this process (a kill of it is a kill of the batch)
        for job, limit in zip(jobs, limits):
            result = _limited(func, job, limit)
            yield lost(job, result) if isinstance(result, LostJob) else result
        return
    yield from _supervised(func, jobs, min(workers, len(jobs)), limits, lost)


def _stop_batch(job: Any, why: LostJob) -> Any:
    """Without ``on_lost``: a lost job stops the batch, in one line."""
    raise BackendError(f"local: a job was lost ({why.reason}); finished jobs are saved, run again to resume")


def _supervised(func: Callable[[Any], Any], jobs: list, size: int, limits: list[float | None],
                lost: Callable[[Any, LostJob], Any]) -> Iterator[Any]:
    """The jobs over ``size`` spawned workers (each opens its own GL context), handed out in the given order,
    one at a time per worker. A worker that dies is replaced at once and its job given again, at the front of
    the queue, once (:data:`LOCAL_RETRIES`); a job past its limit (``limits``) has its worker killed and replaced."""
    ctx = mp.get_context("spawn")
    queue, losses, unborn = deque(range(len(jobs))), Counter(), 0
    pool = [_Worker(ctx, func) for _ in range(size)]
    try:
        while queue or any(w.job is not None for w in pool):
            for w in pool:
                if w.job is None and queue:
                    w.give(queue[0], jobs[queue.popleft()])
            busy = [w for w in pool if w.job is not None]
            ends = [w.since + limits[w.job] for w in busy if w.since is not None and limits[w.job] is not None]
            wait_s = max(0.0, min(ends) - time.monotonic()) if ends else None
            connection.wait([w.conn for w in busy] + [w.proc.sentinel for w in busy], wait_s)
            for k, w in enumerate(pool):
                index, since = w.job, w.since
                if index is None:
                    continue
                event = w.read()
                if event is not None and event[0] == "done":
                    ok, value = event[1]
                    if not ok:
                        raise value  # the job's own error, as it raised it
                    if isinstance(value, LostJob):  # it raised SystemExit: its worker has ended, a fresh one
                        w.stop(kill=True)
                        pool[k] = _Worker(ctx, func)
                        yield lost(jobs[index], value)
                        continue
                    if queue:  # its next job first: it works while the caller writes this result down
                        w.give(queue[0], jobs[queue.popleft()])
                    yield value
                    continue
                seconds = time.monotonic() - (w.since or since or time.monotonic())
                if event is not None and w.since is None:  # died before it began the job: not the job's doing
                    w.stop(kill=True)
                    unborn += 1
                    if unborn > size + LOCAL_RETRIES:
                        raise BackendError(f"local: worker processes end before their first job (the last one "
                                           f"{event[1]}); check that the package imports in a fresh process")
                    pool[k] = _Worker(ctx, func)
                    queue.appendleft(index)
                elif event is not None:  # the process is gone: a fresh one, and the job again (once)
                    w.stop(kill=True)
                    pool[k] = _Worker(ctx, func)
                    losses[index] += 1
                    if losses[index] <= LOCAL_RETRIES:
                        queue.appendleft(index)
                    else:
                        yield lost(jobs[index], LostJob("crash", f"its process {event[1]} {_tries(losses[index])}",
                                                                 seconds))
                elif w.overdue(limits[index]):
                    w.stop(kill=True)
                    pool[k] = _Worker(ctx, func)
                    yield lost(jobs[index], LostJob("timeout", timeout_reason(limits[index]), seconds))
    finally:
        for w in pool:
            w.stop(kill=w.job is not None)


# -- ray ----------------------------------------------------------------------------------------------
def _ray():
    try:
        import ray
    except ImportError:
        raise BackendError("--backend ray needs Ray: pip install 'garage-mj[ray]' (or make install)") from None
    return ray


def _start(ray, workers: int, address: str | None, env: dict[str, str]) -> bool:
    """Connect to ``address`` or start a private local Ray of ``workers`` CPUs; True when this call started it
    (shut it down)."""
    if address is not None:
        _reachable(address)
    if ray.is_initialized():
        return False
    os.environ.setdefault("RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO", "0")  # no FutureWarning about GPU env vars
    # a new local instance turns Ray's token auth on (a token in ~/.ray/auth_token) and says so: keep it, quietly
    logging.getLogger("ray._private.authentication.authentication_token_setup").setLevel(logging.ERROR)
    quiet = {"logging_level": logging.WARNING, "log_to_driver": True, "runtime_env": {"env_vars": env}}
    try:
        if address is not None:
            ray.init(address=address, **quiet)
        else:  # "local": a fresh instance, never a cluster found through RAY_ADDRESS or /tmp/ray
            ray.init(address="local", num_cpus=workers, include_dashboard=False, _node_ip_address="127.0.0.1",
                     object_store_memory=128 * 1024**2, _system_config=_LOCAL_CONFIG, **quiet)
    except Exception as exc:  # ConnectionError, TimeoutError, RuntimeError ... from Ray's start-up
        where = f"the Ray cluster at {address}" if address else "a local Ray instance"
        raise BackendError(f"cannot start or reach {where}: {_first_line(exc)}") from None
    return True


def _reachable(address: str, timeout: float = 10.0) -> None:
    """A ``HOST:PORT`` that accepts no TCP connection is one line now, not Ray's minutes of retries."""
    import socket

    host, sep, port = address.rpartition(":")
    if "://" in address or not sep or not port.isdigit():  # ray://..., "auto": let Ray resolve it
        return
    try:
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as exc:
        raise BackendError(f"cannot reach the Ray cluster at {address}: {exc.strerror or exc}; start it with "
                           "ray start --head --port=PORT on that host") from None


class _Slot:
    """One worker slot: a long-lived process that runs jobs (its module-level caches survive between jobs)."""

    def run(self, func: Callable[[Any], Any], job: Any, timeout: float | None = None) -> Any:
        return _limited(func, job, timeout)


@contextlib.contextmanager
def ray_session(compute: Compute) -> Iterator[Any]:
    """Ray for a block of batches (yields the ``ray`` module): the cluster at ``compute.address``, else a
    private local instance of ``compute.workers`` CPUs; shut down at the end if this call started it.
    Batches inside (:func:`map_unordered` with ``backend="ray"``) reuse it instead of starting their own."""
    ray = _ray()
    auth_mode = os.environ.get("RAY_AUTH_MODE")  # ray.init of a local instance sets it in this process
    started = _start(ray, compute.workers, compute.address, worker_env())
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()
            if auth_mode is None:
                os.environ.pop("RAY_AUTH_MODE", None)
            else:
                os.environ["RAY_AUTH_MODE"] = auth_mode


def _ray_map(func: Callable[[Any], Any], jobs: list, compute: Compute, max_retries: int,
             limits: list[float | None], on_lost: Callable[[Any, LostJob], Any] | None) -> Iterator[Any]:
    with ray_session(compute) as ray:
        yield from _ray_actors(ray, func, jobs, compute.workers, max_retries, limits, on_lost)


def _ray_actors(ray, func: Callable[[Any], Any], jobs: list, workers: int, max_retries: int,
                limits: list[float | None], on_lost: Callable[[Any, LostJob], Any] | None) -> Iterator[Any]:
    from ray.exceptions import RayActorError, RayTaskError

    env = worker_env()
    actors: list = []
    try:
        # one job at a time per actor (a job queued behind a dying one would spend a retry too); a dead actor is
        # restarted (on another node when its own is gone) and its job retried, up to max_retries times per job
        slot = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=max_retries)(_Slot)
        actors = [slot.options(runtime_env={"env_vars": env}).remote() for _ in range(min(workers, len(jobs)))]
        fn = ray.put(func)
        todo = iter(enumerate(jobs))
        pending: dict[Any, tuple[int, int]] = {}  # ref -> (job index, actor index)

        def submit(a: int) -> bool:
            nxt = next(todo, None)
            if nxt is None:
                return False
            pending[actors[a].run.remote(fn, nxt[1], limits[nxt[0]])] = (nxt[0], a)
            return True

        for a in range(len(actors)):
            submit(a)
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            ref = ready[0]
            index, a = pending.pop(ref)
            try:
                result = ray.get(ref)
            except RayTaskError as exc:  # the job raised: its own exception, one line, no retry
                _raise_own(exc)
            except RayActorError as exc:  # its process or node died, more than max_retries times
                if on_lost is None:
                    raise BackendError(f"ray: job {index} lost its worker {max_retries + 1} times (node or process "
                                       f"died: {_first_line(exc)}); finished jobs are saved, run again to resume"
                                       ) from None
                result = LostJob("crash", f"its process or node died {_tries(max_retries + 1)}", 0.0)
            submit(a)
            if isinstance(result, LostJob):
                result = (on_lost or _stop_batch)(jobs[index], result)
            yield result
    finally:
        for actor in actors:
            try:
                ray.kill(actor)
            except Exception:  # noqa: BLE001  (already gone)
                pass


# -- streams ------------------------------------------------------------------------------------------
def stream_unordered(func: Callable[[Any], Iterator[Any]], jobs: Sequence[Any], *,
                     compute: Compute = DEFAULT_COMPUTE, prepare: Callable[[Any], Any] | None = None,
                     resume: Callable[[int, str], Any] | None = None, max_retries: int = 3,
                     name: Callable[[int], str] | None = None) -> Iterator[tuple[int, Any]]:
    """``(job index, item)`` for every item the generator ``func(prepare(job))`` yields, as soon as it is made.

    ``compute.backend`` ``local``: the jobs one after another in this process. ``ray``: up to
    ``compute.workers`` jobs at a time, each a Ray task of one CPU on any node of the cluster at
    ``compute.address`` (else a private local Ray);
    the items of all of them arrive here as they are yielded. ``prepare`` (default: none) turns a job
    into what is sent, right before it is sent (so a job can carry what its folder holds then, and
    only the running jobs' payloads are in memory). A job whose worker process or node is lost (not
    one that raised) is submitted again as ``resume(index, why)`` (default: the same job), to the
    front of the queue, up to ``max_retries`` times; then one :class:`BackendError` line, naming the
    job as ``name(index)``. An exception the job raises is re-raised here as it is. Closing the
    iterator early cancels the running jobs.
    """
    check_backend(compute)
    jobs = list(jobs)
    if not jobs:
        return iter(())
    prepare = prepare or (lambda job: job)
    if compute.backend == "ray":
        return _ray_stream(func, jobs, compute, prepare, resume, max_retries, name or (lambda i: f"job {i}"))
    return ((i, item) for i, job in enumerate(jobs) for item in func(prepare(job)))


def _stream_job(func: Callable[[Any], Iterator[Any]], job: Any) -> Iterator[Any]:
    """A Ray task body: a generator function, so Ray streams its items back as they are yielded."""
    yield from func(job)


def _lost(ray) -> tuple[type, ...]:
    """The Ray errors that mean the worker process or node went away (the job itself did not fail)."""
    from ray import exceptions as e

    return (e.WorkerCrashedError, e.NodeDiedError, e.ObjectLostError, e.OutOfMemoryError, e.RayActorError,
            e.LocalRayletDiedError)


def _ray_stream(func: Callable[[Any], Iterator[Any]], jobs: list, compute: Compute,
                prepare: Callable[[Any], Any], resume: Callable[[int, str], Any] | None, max_retries: int,
                name: Callable[[int], str]) -> Iterator[tuple[int, Any]]:
    workers = compute.workers
    with ray_session(compute) as ray:
        from ray.exceptions import RayError, RayTaskError

        lost, env = _lost(ray), worker_env()
        task = ray.remote(num_cpus=1, max_retries=0)(_stream_job).options(runtime_env={"env_vars": env})
        fn = ray.put(func)
        queue, running, losses = deque(enumerate(jobs)), {}, Counter()

        def submit() -> None:
            while queue and len(running) < workers:
                index, job = queue.popleft()
                running[task.remote(fn, prepare(job))] = index

        try:
            submit()
            while running:
                ready, _ = ray.wait(list(running), num_returns=1)
                gen = ready[0]
                index = running[gen]
                try:
                    item = ray.get(next(gen))
                except StopIteration:
                    del running[gen]
                    submit()
                    continue
                except RayTaskError as exc:  # the job raised: its own exception, one line, no retry
                    _raise_own(exc)
                except lost as exc:  # its process or node died: submit it again, as the caller says
                    del running[gen]
                    why = _first_line(exc)
                    losses[index] += 1
                    if losses[index] > max_retries:
                        raise BackendError(f"ray: {name(index)} lost its worker {losses[index]} times (node or "
                                           f"process died: {why}); finished work is saved, run again to resume") from None
                    queue.appendleft((index, resume(index, why) if resume is not None else jobs[index]))
                    submit()
                    continue
                except RayError as exc:  # the runtime env, scheduling ...: not something a retry mends
                    raise BackendError(f"ray: {name(index)} failed: {_first_line(exc)}") from None
                yield index, item
        finally:
            for gen in running:
                try:
                    ray.cancel(gen)
                except Exception:  # noqa: BLE001  (already ended)
                    pass


def _raise_own(exc: BaseException) -> None:
    """Raise the job's own exception behind Ray's ``RayTaskError`` (the wrapper itself if it carries none)."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        raise cause from None
    raise exc


def _first_line(exc: BaseException) -> str:
    """``Type: first sentence`` of an error (Ray's run on for lines)."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    text = text.split(". ")[0][:200]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
