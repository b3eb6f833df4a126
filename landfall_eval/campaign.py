"""Where a campaign's episodes run: here on a thread pool, or as Ray tasks (``--executor ray``).

Either way an episode is :func:`landfall_eval.episode.run_episode`: its own simbridge and companion
processes, ports and directory, so episodes share nothing and the executor only decides where and how
many at once. Both executors hand back each episode's results.json entry as it ends (the caller writes
it at once, so an interrupted campaign loses nothing), retry only what never got as far as the alarm
(:func:`is_infrastructure_failure`: a port taken meanwhile, a process that did not start, a Ray worker
that died), never an outcome, and stop an episode that outlives its wall-time limit.

Ray is an optional extra (``pip install 'landfall[campaign]'``); it is imported only by
:class:`RayExecutor`. Without ``address`` a local Ray instance is started with ``workers`` CPUs; with
one (``auto``, ``ray://host:10001``, ``host:6379``) the episodes go to a cluster the user runs, each
task reserving ``cpus_per_episode`` CPUs. On a cluster every node needs this repository installed at
the same path as here and the campaign directory on a shared filesystem: the tasks write their episode
directories there (the entries themselves come back to this process, which writes results.json).
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from landfall_eval.episode import EpisodeSpec, EpisodeTimes, Launch, launch_episode, run_episode
from landfall_eval.processes import STOPPING, stop_running_episodes

__all__ = [
    "EXECUTORS",
    "EpisodeJob",
    "Executor",
    "LocalExecutor",
    "RayExecutor",
    "RayUnavailable",
    "error_entry",
    "fly",
    "is_infrastructure_failure",
    "launch_ahead",
    "make_executor",
]

EXECUTORS = ("local", "ray")
RAY_HINT = "pip install 'landfall[campaign]' (or: pip install ray)"


@dataclass(frozen=True, slots=True)
class EpisodeJob:
    """One episode to fly: what, where its files go, its limits, and how many tries an infrastructure
    failure gets (``tries`` 1: no retry)."""

    spec: EpisodeSpec
    workdir: Path
    times: EpisodeTimes
    config_path: Path | None = None
    sitl: Path | None = None
    tries: int = 3
    world_cache: Path | None = None  # built places kept here (simbridge --world-cache); None: none

    @property
    def wall_limit_s(self) -> float:
        """The longest one try may take, start to stop: simbridge ready, the flight, the settling."""
        t = self.times
        return t.ready_wall_s + t.start_wall_s + t.wall_s + t.settle_wall_s + 30.0


def is_infrastructure_failure(entry: dict[str, Any]) -> bool:
    """An episode that failed before the alarm went in: nothing about the landing was decided."""
    return entry.get("outcome") == "error" and entry.get("error_kind") == "infrastructure"


def error_entry(
    spec: EpisodeSpec, error: str, *, infrastructure: bool, wall_s: float = 0.0
) -> dict[str, Any]:
    """The results.json entry of an episode that the executor itself could not run to its end."""
    return {
        "id": spec.id, "kind": spec.kind, "scenario": spec.scenario, "seed": spec.seed,
        "city_seed": spec.city_seed, "place": spec.place if spec.kind == "city" else None,
        "launch_index": spec.launch_index, "run": spec.run,
        "reasoner": spec.reasoner, "context": spec.context, "weather": spec.weather,
        "autopilot": spec.autopilot, "ekf_error": spec.ekf_error, "gps_fault": spec.gps_fault_entry,
        "camera": spec.camera,
        "criticality": spec.criticality,
        "launch_height_m": spec.launch[2] if spec.launch is not None else None,
        "outcome": "error", "error": error,
        "error_kind": "infrastructure" if infrastructure else None,
        "safe": False, "surface": "no_landing", "reasons": ["no touchdown"], "rounds": 0, "calls": [],
        "rationales": [], "trajectory_ne_m": [], "last_state": None, "defects": 0,
        "wall_s": round(wall_s, 2),
    }  # fmt: skip


def fly(
    job: EpisodeJob,
    *,
    launched: Launch | None = None,
    in_flight: Callable[[], None] | None = None,
    on_stopped: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """Fly ``job``, again while it fails for infrastructure (``job.tries`` in all); the entry records
    ``attempts``. An exception out of the harness itself is an infrastructure failure. ``launched``:
    the job's processes started ahead (:func:`launch_episode`), flown by the first try;
    ``in_flight`` and ``on_stopped``: :func:`run_episode`'s, for every try."""
    entry: dict[str, Any] = {}
    for attempt in range(1, job.tries + 1):
        t0 = time.monotonic()
        try:
            entry = run_episode(
                job.spec, job.workdir, times=job.times, config_path=job.config_path, sitl=job.sitl,
                world_cache=job.world_cache, launched=launched if attempt == 1 else None,
                in_flight=in_flight, on_stopped=on_stopped,
            )  # fmt: skip
        except Exception as exc:  # the harness failed (e.g. no port to bind), not the episode
            if launched is not None and attempt == 1:
                launched.discard()
            entry = error_entry(
                job.spec, f"harness: {type(exc).__name__}: {exc}", infrastructure=True,
                wall_s=time.monotonic() - t0,
            )  # fmt: skip
        entry["attempts"] = attempt
        if not is_infrastructure_failure(entry):
            break
    return entry


def launch_ahead(job: EpisodeJob) -> Launch | None:
    """``job``'s processes started and held (:func:`launch_episode`); None when they could not be
    (its flight then starts them itself, and meets the same error there, tried again as usual)."""
    try:
        return launch_episode(
            job.spec, job.workdir, times=job.times, config_path=job.config_path, sitl=job.sitl,
            world_cache=job.world_cache, held=True,
        )  # fmt: skip
    except Exception:
        return None


class Executor(Protocol):
    def run(self, jobs: Sequence[EpisodeJob]) -> Iterator[dict[str, Any]]:
        """Every job's entry, in the order the episodes end."""
        ...

    def close(self) -> None: ...


class LocalExecutor:
    """``workers`` episodes in flight at once on this machine, one thread each (the work is in the
    processes). With ``ahead`` (the default) each worker launches its next episode once the alarm of
    the one it flies has gone in: the next simbridge builds its world and warms its sensors, and its
    companion starts, while this flight runs; both then wait, using no CPU, and the simulation's
    clock starts once this flight's processes have stopped, while it is graded
    (:func:`launch_episode`). So neither the starting nor the grading costs wall time between
    flights, and the flights themselves are as they were."""

    def __init__(self, workers: int, *, ahead: bool = True) -> None:
        self.workers = workers
        self.ahead = ahead
        self._jobs: deque[EpisodeJob] = deque()
        self._lock = threading.Lock()
        self._threads: list[threading.Thread] = []
        self._ended: queue.Queue[dict[str, Any] | BaseException] = queue.Queue()

    def _take(self) -> EpisodeJob | None:
        with self._lock:
            return self._jobs.popleft() if self._jobs and not STOPPING.is_set() else None

    def _work(self) -> None:
        """One worker: fly a job, launching the next while it flies (``ahead``), until none is left."""
        nxt: tuple[EpisodeJob, Launch | None] | None = None  # the next job, launched ahead (or not)
        asked = False  # the next job was asked for during this flight (none may be left)

        def in_flight() -> None:
            nonlocal nxt, asked
            if self.ahead and not asked:
                asked = True
                following = self._take()
                if following is not None:
                    nxt = (following, launch_ahead(following))

        def on_stopped() -> None:  # the next one's clock runs while this one is graded
            if nxt is not None and nxt[1] is not None:
                nxt[1].go()

        try:
            while not STOPPING.is_set():
                if nxt is not None:
                    (job, launched), nxt = nxt, None
                else:
                    first = self._take()
                    if first is None:
                        return
                    job, launched = first, None
                asked = False
                self._ended.put(fly(job, launched=launched, in_flight=in_flight, on_stopped=on_stopped))
        except BaseException as exc:  # the harness itself: the caller raises it
            self._ended.put(exc)
        finally:
            if nxt is not None and nxt[1] is not None:  # stopped before its turn: nothing left running
                nxt[1].discard()

    def run(self, jobs: Sequence[EpisodeJob]) -> Iterator[dict[str, Any]]:
        STOPPING.clear()
        self._jobs = deque(jobs)
        self._threads = [
            threading.Thread(target=self._work, name=f"episode-{k}", daemon=True)
            for k in range(min(self.workers, len(jobs)))
        ]
        for t in self._threads:
            t.start()
        for _ in range(len(jobs)):
            ended = self._ended.get()
            if isinstance(ended, BaseException):
                raise ended
            yield ended

    def close(self) -> None:
        """After the last entry: nothing to do. Before it (an interrupted campaign): the episodes not
        started are dropped and those in flight or launched ahead stopped, their processes terminated."""
        if any(t.is_alive() for t in self._threads):
            with self._lock:
                self._jobs.clear()
            stop_running_episodes()
        for t in self._threads:
            t.join()
        self._threads = []


class RayUnavailable(RuntimeError):
    pass


class RayExecutor:
    """Each episode a Ray task reserving ``cpus_per_episode`` CPUs; Ray reruns a task whose worker
    died (``max_retries``), :func:`fly` reruns an infrastructure failure inside the task, and a task
    past its job's wall-time limit is cancelled (its processes die with it) and entered as a timeout."""

    def __init__(self, *, address: str | None, workers: int, cpus_per_episode: float) -> None:
        try:
            import ray
        except ImportError:
            raise RayUnavailable(f"--executor ray needs Ray: {RAY_HINT}") from None
        self._ray = ray
        self.cpus_per_episode = cpus_per_episode
        self._own = not ray.is_initialized()
        if self._own:
            kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
            if address is None:
                kwargs["num_cpus"] = workers
            ray.init(address=address, **kwargs)
        self.cpus = float(ray.cluster_resources().get("CPU", 0.0))  # type: ignore[no-untyped-call]
        if self.cpus < cpus_per_episode:
            raise RayUnavailable(
                f"the Ray cluster has {self.cpus:g} CPUs; an episode asks for {cpus_per_episode:g} "
                "(--cpus-per-episode)"
            )

    def run(self, jobs: Sequence[EpisodeJob]) -> Iterator[dict[str, Any]]:
        """At most as many tasks in flight as the cluster has room for, so a task starts when it is
        submitted and its wall-time clock with it."""
        ray = self._ray
        task = ray.remote(fly).options(
            num_cpus=self.cpus_per_episode, max_retries=max(j.tries for j in jobs) - 1 if jobs else 0,
            retry_exceptions=False, name="landfall-episode",
        )  # fmt: skip
        slots = max(1, int(self.cpus // self.cpus_per_episode))
        queue = list(jobs)[::-1]
        running: dict[Any, tuple[EpisodeJob, float]] = {}
        while queue or running:
            while queue and len(running) < slots:
                job = queue.pop()
                running[task.remote(job)] = (job, time.monotonic())
            ready, _ = ray.wait(list(running), num_returns=1, timeout=5.0)
            for ref in ready:
                job, _t = running.pop(ref)
                try:
                    yield ray.get(ref)
                except ray.exceptions.RayError as exc:  # the worker died more often than retried
                    yield error_entry(
                        job.spec, f"Ray: {type(exc).__name__}: {exc}"[:500], infrastructure=True
                    )
            now = time.monotonic()
            for ref, (job, t0) in list(running.items()):
                if now - t0 > job.wall_limit_s * job.tries:
                    ray.cancel(ref, force=True)  # the worker process ends, and the episode's with it
                    running.pop(ref)
                    entry = error_entry(
                        job.spec, f"no result within {now - t0:.0f} wall seconds: task cancelled",
                        infrastructure=False, wall_s=now - t0,
                    )  # fmt: skip
                    entry["outcome"] = "timeout"
                    yield entry

    def close(self) -> None:
        if self._own and self._ray.is_initialized():
            self._ray.shutdown()


def make_executor(
    kind: str, *, workers: int, address: str | None, cpus_per_episode: float, ahead: bool = True
) -> Executor:
    """The executor ``kind`` names; ``ahead``: the local one launches each worker's next episode
    while it flies one (:class:`LocalExecutor`)."""
    if kind == "local":
        if address is not None:
            raise ValueError("--ray-address goes with --executor ray")
        return LocalExecutor(workers, ahead=ahead)
    if kind == "ray":
        return RayExecutor(address=address, workers=workers, cpus_per_episode=cpus_per_episode)
    raise ValueError(f"unknown executor {kind!r}; known: {', '.join(EXECUTORS)}")
