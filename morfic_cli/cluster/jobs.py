"""The jobs of a pipeline as a graph: which ran, which the store holds, which read which checkpoints.

Pure planning over a :class:`~morfic_cli.pipeline.Pipeline`; no Ray. A job is one train, eval, diagnose or
fixed-rollout step; compare and report read the whole store and run on the driver after the jobs.
"""

from __future__ import annotations

from dataclasses import dataclass

from morfic_cli.pipeline import Pipeline, StepResult

#: Pipeline steps that become cluster jobs, in dependency order.
JOB_KINDS: tuple[str, ...] = ("train", "eval", "diagnose", "fixed-rollout")

#: CPUs one job declares per preset (the smoke preset's tiny batches run on one thread; cpu is sized for two
#: cores; paper runs on a GPU with a few CPU threads feeding it).
CPUS_PER_JOB: dict[str, int] = {"smoke": 1, "cpu": 2, "paper": 4}


@dataclass(frozen=True)
class Job:
    """One job of the pipeline.

    Attributes:
        kind: train, eval, diagnose or fixed-rollout.
        label: The run ref ``runs/NAME`` (train, eval, diagnose) or the robot (fixed-rollout).
        variant: Variant of a train job ("" otherwise).
        seed: Seed of a train job (0 otherwise).
        needs: Run refs whose checkpoints the job reads (eval and diagnose: its run; fixed-rollout: the frozen
            actor's run and every run).
    """

    kind: str
    label: str
    variant: str = ""
    seed: int = 0
    needs: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        """``kind label``: unique in a pipeline."""
        return f"{self.kind} {self.label}"


def plan_jobs(pipeline: Pipeline) -> list[Job]:
    """Every job of ``pipeline`` in the order :meth:`Pipeline.plan` runs them (trains first)."""
    runs = pipeline.run_specs()
    jobs = [Job("train", spec, variant=v, seed=s) for v, s, spec in runs]
    jobs += [Job("eval", spec, needs=(spec,)) for _, _, spec in runs]
    jobs += [Job("diagnose", spec, needs=(spec,)) for _, _, spec in runs]
    if pipeline.fixed_rollout_unavailable() is None:  # else the local executor reports it as not run
        actor, critics = pipeline.fixed_rollout_models()
        needs = tuple(dict.fromkeys((actor, *critics)))
        jobs += [Job("fixed-rollout", robot, needs=needs) for robot in pipeline.cfg.fixed_rollout_robots]
    return jobs


def stored(pipeline: Pipeline, job: Job) -> StepResult | None:
    """The skipped result when ``pipeline``'s store already holds the job's result, else None.

    The same checks the local executor makes before each step, so a rerun skips the same work whatever executor
    ran it first.

    Raises:
        MorficError: A train job's run exists with another config.
    """
    if job.kind == "train":
        return pipeline.stored_train(job.variant, job.seed, job.label)
    if job.kind == "eval":
        return pipeline.stored_eval(job.label)
    if job.kind == "diagnose":
        return pipeline.stored_diagnosis(job.label)
    return pipeline.stored_fixed_rollout(job.label)


def run_job(pipeline: Pipeline, job: Job) -> StepResult:
    """Run ``job`` as its pipeline step (on a worker, against the worker's store)."""
    if job.kind == "train":
        return pipeline.train(job.variant, job.seed, job.label)
    if job.kind == "eval":
        return pipeline.evaluate(job.label)
    if job.kind == "diagnose":
        return pipeline.diagnose(job.label)
    return pipeline.fixed_rollout(job.label)
