"""``morfic reproduce --jobs N``: the evaluations and diagnoses in N local worker processes, side by side.

One evaluation or diagnosis keeps about one core busy whatever torch's thread count (the env's Python code and
per-step tensors of a few hundred rows; docs/benchmarks.md, "Evaluations side by side"), so N of them side by side
on N cores take about 1/N of the time. Each job runs as under ``--executor ray``
(:func:`~morfic_cli.cluster.worker.execute`): a fresh store in a temporary folder fed with an export of its run,
its refs sent back as one export tar and imported into the user's store in plan order, so ``diagnoses/calibration``
gets its versions in the order of a one-process run and the store holds what ``--jobs 1`` writes. Every other step
(imports, training, the fixed-rollout analysis, the critic study, compare, report) runs in the calling process, one
after another (:meth:`~morfic_cli.pipeline.Pipeline.run`).

Faults: a user error in a job (``Error:``) fails that job and the command says which after the others finished; a
worker that dies fails its job; a bug in a worker re-raises here with its traceback. Ctrl-C stops the workers at
once; every job that finished is imported first, and a rerun skips it.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import shutil
import signal
import tempfile
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from morfic_cli import __version__
from morfic_cli.cluster.jobs import Job, plan_jobs, stored
from morfic_cli.cluster.worker import Outcome, execute, export_inputs, import_outcome
from morfic_cli.errors import MorficError
from morfic_cli.pipeline import Pipeline, ReproduceCfg, StepResult


def cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _ignore_ctrl_c() -> None:
    """Worker initializer: Ctrl-C is the driver's to handle (it stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_timed(
    job: Job, cfg: ReproduceCfg, driver_version: str, inputs: bytes, trusted: tuple[str, ...], workdir: str
) -> Outcome:
    """:func:`~morfic_cli.cluster.worker.execute` with the job's wall time in its step result (on the worker)."""
    start = time.perf_counter()
    out = execute(job, cfg, driver_version, inputs, trusted=trusted, workdir=workdir)
    if out.step is not None:
        out.step.seconds = time.perf_counter() - start
    return out


class JobPool:
    """A pipeline's eval and diagnose steps in ``jobs`` worker processes (``Pipeline.run``'s ``side_by_side``).

    Args:
        pipeline: The pipeline over the user's store.
        jobs: Worker processes (at least 2); each runs torch on ``max(1, cores // jobs)`` threads.
    """

    def __init__(self, pipeline: Pipeline, jobs: int) -> None:
        if jobs < 2:
            raise ValueError(f"a JobPool needs at least 2 workers, got {jobs}")
        self.pipeline, self.jobs = pipeline, jobs
        self.torch_threads = max(1, cores() // jobs)

    def __call__(self, steps: list[tuple[str, str]]) -> list[StepResult]:
        """Run ``steps`` ((kind, label) of eval and diagnose steps); their results in the order given.

        Raises:
            MorficError: A job failed (the message names the first; every job that finished is in the store).
        """
        from morfic_cli.rl.variants import trusted_variants

        pipeline = self.pipeline
        by_key = {j.key: j for j in plan_jobs(pipeline)}
        jobs = [by_key[f"{kind} {label}"] for kind, label in steps]
        results: dict[str, StepResult] = {}
        todo: list[Job] = []
        for job in jobs:
            found = stored(pipeline, job)
            if found is None:
                todo.append(job)
            else:
                results[job.key] = found
                pipeline.progress.step_end(found)
        if todo:
            results.update(self._run(todo, tuple(trusted_variants())))
        failed = [r for r in results.values() if r.status == "failed"]
        if failed:
            done = sum(r.status != "failed" for r in results.values())
            raise MorficError(
                f"{len(failed)} job(s) failed; the {done} that finished are in the store (run the command again "
                f"to retry the rest). First: {failed[0].kind} {failed[0].label}: {failed[0].detail}"
            )
        return [results[j.key] for j in jobs]

    def _run(self, todo: list[Job], trusted: tuple[str, ...]) -> dict[str, StepResult]:
        pipeline, store = self.pipeline, self.pipeline.store
        cfg = dataclasses.replace(pipeline.cfg, torch_threads=self.torch_threads)
        workers = min(self.jobs, len(todo))
        label = f"{len(todo)} evaluations and diagnoses, {workers} side by side"
        first = [k for k, _, _ in pipeline.plan()].index(todo[0].kind)
        total = len(pipeline.plan())
        pipeline.progress.step_start(first, total, label, len(todo), "jobs")
        finished: dict[str, Outcome | BaseException] = {}
        order = list(todo)
        results: dict[str, StepResult] = {}

        def import_ready(everything: bool = False) -> None:
            """Import finished jobs in plan order (after Ctrl-C: every finished one, skipping the rest)."""
            while order and (order[0].key in finished or everything):
                job = order.pop(0)
                if job.key in finished:
                    results[job.key] = self._finish(job, finished.pop(job.key))
                    if order:  # the view's current step ends with each result: show the rest as the next one
                        pipeline.progress.step_start(first, total, label, len(todo), "jobs")
                        pipeline.progress.step_advance(completed=len(results))

        workdir = tempfile.mkdtemp(prefix="morfic-jobs-")  # the jobs' stores: gone at the end, even after Ctrl-C
        try:
            pool = ProcessPoolExecutor(workers, multiprocessing.get_context("spawn"), initializer=_ignore_ctrl_c)
            try:
                futures: dict[Future, Job] = {}
                for job in todo:
                    inputs = export_inputs(store, list(job.needs))
                    futures[pool.submit(run_timed, job, cfg, __version__, inputs, trusted, workdir)] = job
                while futures:
                    ready, _ = wait(futures, timeout=0.5, return_when=FIRST_COMPLETED)
                    for future in ready:
                        job = futures.pop(future)
                        finished[job.key] = _outcome(future)
                        pipeline.progress.step_advance(advance=1, detail=job.key)
                    import_ready()
            except BaseException:  # Ctrl-C or a bug in a worker: stop the others now, keep what finished
                children = multiprocessing.active_children()
                for child in children:
                    child.terminate()
                for child in children:
                    child.join(5)
                pool.shutdown(wait=False, cancel_futures=True)
                import_ready(everything=True)
                raise
            pool.shutdown()
        finally:
            shutil.rmtree(workdir, ignore_errors=True)
        return results

    def _finish(self, job: Job, out: Outcome | BaseException) -> StepResult:
        """Import a finished job's results into the user's store; its step result (failed: why)."""
        if isinstance(out, BaseException):
            step = StepResult(job.kind, job.label, "failed", detail=f"its worker process died ({out})")
        else:
            error = import_outcome(self.pipeline.store, out) or ("" if out.step else "no result")
            step = out.step if out.step and not error else StepResult(job.kind, job.label, "failed", detail=error)
        self.pipeline.progress.step_end(step)
        return step


def _outcome(future: Future) -> Outcome | BaseException:
    """A finished job's outcome; a died worker as its exception; a bug in the job re-raises (traceback kept)."""
    try:
        return future.result()
    except BrokenProcessPool as exc:
        return exc
