"""The Ray driver of ``morfic reproduce --executor ray``: jobs as Ray tasks, results home through the store.

Every job that the user's store does not already hold becomes one Ray task (:func:`morfic_cli.cluster.worker.
execute`) declaring ``num_cpus`` from the preset (:data:`~morfic_cli.cluster.jobs.CPUS_PER_JOB`) and
``num_gpus=1`` for ``--device cuda``. Tasks are submitted at once in dependency order: an eval or diagnose task
takes its train task's result as an argument, so Ray starts it when that finished (and moves the bundle to its
node); a fixed-rollout task takes every train result. Inputs the store already holds travel as export tars made
here. Each result bundle is imported into the user's store as it arrives (all or nothing), so a Ctrl-C or a
failed job leaves every finished job in the store and no partial artifact; the next run skips them.

Faults: Ray retries a task whose worker died (``max_retries``, ``--retries``); a user error comes back as a
message and fails the job once; a job whose input failed fails with that reason.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from morfic_cli import __version__
from morfic_cli.cluster.jobs import CPUS_PER_JOB, Job, plan_jobs, stored
from morfic_cli.cluster.worker import export_inputs, import_outcome
from morfic_cli.errors import MorficError
from morfic_cli.pipeline import Pipeline, ReproduceResult, StepResult

#: Retries of a job whose worker process died (Ray's ``max_retries``).
DEFAULT_RETRIES = 3


def import_ray():
    """The ``ray`` module, or MorficError saying what to install."""
    try:
        import ray
    except ImportError as exc:
        raise MorficError(
            "--executor ray needs Ray, which is not installed: pip install 'morfic[cluster]' (or pip install "
            "'ray[default]>=2.40') on this machine and on every node of the cluster; see docs/cluster.md."
        ) from exc
    return ray


@dataclass
class JobState:
    """A job as the progress view shows it: queued, running, done, skipped or failed, and where it ran."""

    job: Job
    state: str = "queued"
    node: str = ""
    detail: str = ""
    started: float = 0.0
    seconds: float = 0.0


@dataclass
class RayRun:
    """The state of one ``--executor ray`` run (what the progress view draws)."""

    jobs: dict[str, JobState] = field(default_factory=dict)
    address: str = ""
    resources: str = ""


def _board_class(ray):
    @ray.remote(num_cpus=0)
    class Board:
        """Where and when each job started (workers report, the driver polls)."""

        def __init__(self) -> None:
            self.started: dict[str, tuple[str, int, float]] = {}

        def start(self, key: str, node: str, pid: int) -> None:
            self.started[key] = (node, pid, time.time())

        def snapshot(self) -> dict[str, tuple[str, int, float]]:
            return dict(self.started)

    return Board


class RayExecutor:
    """Run a :class:`Pipeline`'s jobs on Ray; the critic study, compare and report on the driver.

    Args:
        pipeline: The pipeline over the user's store.
        address: A running cluster (``HOST:PORT`` of ``ray start --head``); None starts a local one.
        retries: Retries of a job whose worker died.
        on_update: Called with the :class:`RayRun` whenever a job changes state (the CLI's progress view).
    """

    def __init__(
        self,
        pipeline: Pipeline,
        address: str | None = None,
        retries: int = DEFAULT_RETRIES,
        on_update: Callable[[RayRun], None] | None = None,
    ) -> None:
        self.pipeline, self.address, self.retries = pipeline, address, retries
        self.on_update = on_update or (lambda _run: None)
        self.state = RayRun()
        self.jobs = plan_jobs(pipeline)

    def run(self) -> ReproduceResult:
        """Run every job not in the store, then compare and report; ``interrupted`` after a Ctrl-C.

        Raises:
            MorficError: Ray is not installed, the cluster cannot be reached, or a job failed (the message
                names it; every job that finished is in the store).
        """
        ray = import_ray()
        result = ReproduceResult()
        start = time.perf_counter()
        self._connect(ray)
        try:
            steps = self._run_jobs(ray, result)
        finally:
            ray.shutdown()
        result.steps = steps
        if not result.interrupted:
            failed = [s for s in self.state.jobs.values() if s.state == "failed"]
            if failed:
                first = failed[0]
                finished = sum(s.state in ("done", "skipped") for s in self.state.jobs.values())
                raise MorficError(
                    f"{len(failed)} job(s) failed; the {finished} that finished are in the store "
                    f"(run the command again to retry the rest). First: {first.job.key}: "
                    f"{first.detail}"
                )
            study = [fn for kind, _, fn in self.pipeline.plan() if kind == "critic-study"]
            for fn in (*study, self.pipeline.compare, self.pipeline.report):  # the study on the driver, after the jobs
                t0 = time.perf_counter()
                step = fn()
                step.seconds = time.perf_counter() - t0
                result.steps.append(step)
                self.pipeline.progress.step_end(step)
            result.report = self.pipeline.report_result
        result.seconds = time.perf_counter() - start
        return result

    def _connect(self, ray) -> None:
        if self.address is not None and self.address != "auto":
            _probe(self.address)
        try:  # "local": always a new instance (None would join whatever cluster /tmp/ray last recorded)
            ray.init(
                address=self.address or "local",
                log_to_driver=False,
                configure_logging=True,
                logging_level="ERROR",
                include_dashboard=False if self.address is None else None,
            )
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"the Ray cluster at {self.address}" if self.address else "a local Ray instance"
            raise MorficError(
                f"cannot connect to {where}: {str(exc).splitlines()[0] if str(exc) else exc!r}; "
                f"start one with `ray start --head` and pass its address (docs/cluster.md)."
            ) from exc
        res = ray.cluster_resources()
        self.state.address = self.address or "local"
        self.state.resources = f"{len(ray.nodes())} node(s), {res.get('CPU', 0):g} CPU, {res.get('GPU', 0):g} GPU"

    def _options(self, job: Job) -> dict[str, Any]:
        cfg = self.pipeline.cfg
        return {
            "num_cpus": CPUS_PER_JOB.get(cfg.preset, 1),
            "num_gpus": 1 if cfg.device.startswith("cuda") else 0,
            "max_retries": self.retries,
            "retry_exceptions": False,
            "name": f"morfic-{job.kind}-{job.label.replace('/', '-')}",
        }

    def _export(self, specs: list[str], *, with_resume: bool = False) -> bytes:
        return export_inputs(self.pipeline.store, specs, with_resume=with_resume)

    def _run_jobs(self, ray, result: ReproduceResult) -> list[StepResult]:
        from morfic_cli.cluster.worker import Outcome, execute
        from morfic_cli.rl.variants import trusted_variants

        store, cfg = self.pipeline.store, self.pipeline.cfg
        trusted = tuple(trusted_variants())  # the driver's consent travels with each job (workers re-resolve variants)
        board = _board_class(ray).remote()
        task = ray.remote(execute)
        steps: dict[str, StepResult] = {}
        pending: dict[Any, Job] = {}
        train_refs: dict[str, Any] = {}
        for job in self.jobs:
            self.state.jobs[job.key] = JobState(job)
        for job in self.jobs:
            js = self.state.jobs[job.key]
            found = stored(self.pipeline, job) if all(n not in train_refs for n in job.needs) else None
            if found is not None:
                steps[job.key] = found
                js.state, js.detail = "skipped", "in the store"
                self.pipeline.progress.step_end(found)
                continue
            if job.kind == "train":
                inputs = [self._export([job.label], with_resume=True)] if store.has_ref(job.label) else []
            else:
                inputs = [train_refs[n] if n in train_refs else ray.put(self._export([n])) for n in job.needs]
            ref = task.options(**self._options(job)).remote(
                job, cfg, __version__, *inputs, board=board, trusted=trusted
            )
            pending[ref] = job
            if job.kind == "train":
                train_refs[job.label] = ref
        self.on_update(self.state)
        # Results are imported in plan order (a finished job waits for the jobs before it), so refs that every
        # job of a kind appends to (diagnoses/calibration) get their versions in the order --executor local gives.
        order = [j for j in self.jobs if j.key not in steps]
        finished: dict[str, Any] = {}

        def import_ready(all_finished: bool = False) -> None:
            while order and (order[0].key in finished or all_finished):
                job = order.pop(0)
                if job.key in finished:
                    steps[job.key] = self._finish(ray, finished.pop(job.key), job, Outcome)

        with _ctrl_c() as stop:
            while pending and not stop.is_set():
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
                self._poll(ray, board)
                for ref in ready:
                    job = pending.pop(ref)
                    finished[job.key] = ref
                    self.state.jobs[job.key].detail = "finished; imported after the jobs before it"
                import_ready()  # an import is never cut by Ctrl-C: the flag is read between jobs
                self.on_update(self.state)
            import_ready(all_finished=True)
            if pending:
                for ref, job in pending.items():
                    ray.cancel(ref, force=True, recursive=True)
                    js = self.state.jobs[job.key]
                    js.state, js.detail = "cancelled", "Ctrl-C"
                result.interrupted = True
                self.on_update(self.state)
        return [steps[j.key] for j in self.jobs if j.key in steps]

    def _poll(self, ray, board) -> None:
        try:
            started = ray.get(board.snapshot.remote(), timeout=5)
        except Exception:  # noqa: BLE001 -- the view is best effort; the results are what counts
            return
        for key, (node, pid, t) in started.items():
            js = self.state.jobs.get(key)
            if js is not None and js.state == "queued":
                js.state, js.node, js.started = "running", f"{node} pid {pid}", t

    def _finish(self, ray, ref, job: Job, outcome_cls) -> StepResult:
        """Import a finished job's bundle into the user's store; its step result (failed: a message)."""
        js = self.state.jobs[job.key]
        try:
            out = ray.get(ref)
        except ray.exceptions.TaskCancelledError:
            js.state, js.detail = "cancelled", ""
            return StepResult(job.kind, job.label, "cancelled")
        except ray.exceptions.RayError as exc:
            js.state, js.detail = "failed", _short(exc)
            return StepResult(job.kind, job.label, "failed", detail=js.detail)
        assert isinstance(out, outcome_cls)
        js.node = f"{out.node} pid {out.pid}"
        error = import_outcome(self.pipeline.store, out)
        if error:
            js.state, js.detail = "failed", error
            return StepResult(job.kind, job.label, "failed", detail=error)
        step = out.step
        js.state = "done"
        js.seconds = time.time() - js.started if js.started else 0.0
        step.seconds = js.seconds
        step.detail = "; ".join(x for x in (step.detail, f"on {out.node} pid {out.pid}") if x)
        self.pipeline.progress.step_end(step)
        return step


def _probe(address: str, timeout_s: float = 10.0) -> None:
    """MorficError unless something listens at ``HOST:PORT`` (Ray itself would retry for minutes)."""
    import socket

    host, port = address.rsplit(":", 1)
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise MorficError(
            f"cannot reach a Ray cluster at --address {address} ({exc.strerror or exc}); start one "
            f"with `ray start --head` there and pass the address it prints (docs/cluster.md)."
        ) from exc


@contextlib.contextmanager
def _ctrl_c() -> Iterator[threading.Event]:
    """A flag that the first Ctrl-C sets (the second aborts at once); the old handler comes back after."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum, frame):  # noqa: ARG001
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, previous)


def _short(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return (text[-1] if text else repr(exc))[:300]
