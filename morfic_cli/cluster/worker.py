"""One job on a worker: a store of its own, input bundles in, the job's refs out as one export bundle.

No shared filesystem is assumed: a job's inputs arrive as export tars (bytes, the ``morfic store export``
closure: a checkpoint bundle for an eval), it runs its pipeline step against a fresh store in a temporary folder,
and returns every ref the step created or extended as one export tar. The driver imports that tar into the
user's store (all or nothing; content addressing makes a retried or duplicated job import to the same ids).
"""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from morfic_cli import __version__
from morfic_cli.cluster.jobs import Job, run_job
from morfic_cli.errors import MorficError
from morfic_cli.pipeline import Pipeline, ReproduceCfg, StepResult


@dataclass
class Outcome:
    """What a job sends back to the driver.

    Attributes:
        key: The job's ``kind label``.
        node: Host name and IP of the worker it ran on.
        pid: The worker process.
        step: Its step result (ids are the worker store's, which are the ids the import gives).
        bundle: The export tar of the refs it created or extended (empty when it failed).
        error: The ``Error:`` message of a user error (MorficError): the job fails once, it is not retried.
        refs: The refs in ``bundle``.
    """

    key: str
    node: str
    pid: int
    step: StepResult | None = None
    bundle: bytes = b""
    error: str = ""
    refs: list[str] = field(default_factory=list)


def where() -> str:
    """``host (ip)`` of this process."""
    host = socket.gethostname()
    try:
        import ray

        return f"{host} ({ray.util.get_node_ip_address()})"
    except Exception:  # noqa: BLE001 -- outside Ray: the host name is enough
        return host


def check_version(driver_version: str) -> None:
    """Raise MorficError when this worker's morfic is not the driver's version."""
    if driver_version != __version__:
        raise MorficError(
            f"the worker on {where()} runs morfic {__version__}, the driver morfic {driver_version}; install the "
            f"same morfic on every node of the cluster (docs/cluster.md), then run the command again."
        )


def _histories(store) -> dict[str, list[str]]:
    return {name: [e.id for e in store.ref_history(name)] for name in store.list_refs()}


def input_bundle(result: Outcome | bytes) -> bytes:
    """The export tar of one input: a finished job's bundle, or a tar exported from the user's store.

    Raises:
        MorficError: The job that should have produced it failed.
    """
    if isinstance(result, Outcome):
        if result.error or not result.bundle:
            raise MorficError(f"its input job {result.key} failed: {result.error or 'no result'}")
        return result.bundle
    return result


def export_inputs(store, specs: list[str], *, with_resume: bool = False) -> bytes:
    """An export tar of ``specs`` from ``store`` (their latest versions; a run to resume: its full history)."""
    from morfic_cli.runs import RESUME_PREFIX, run_of

    refs = list(specs)
    if with_resume:
        refs += [RESUME_PREFIX + run_of(s) for s in specs if store.has_ref(RESUME_PREFIX + run_of(s))]
    with tempfile.TemporaryDirectory(prefix="morfic-bundle-") as tmp:
        path = Path(tmp) / "inputs.tar"
        store.export_tar(refs, path, latest=not with_resume)
        return path.read_bytes()


def import_outcome(store, out: Outcome) -> str:
    """Import a finished job's bundle into ``store`` (all or nothing); "" or why the job failed.

    The import appends (``import_tar(append=True)``): refs that every job of a kind extends (``diagnoses/
    calibration``) get one version per job, in the order the driver imports them.
    """
    if out.error:
        return out.error
    if out.bundle:
        with tempfile.TemporaryDirectory(prefix="morfic-result-") as tmp:
            path = Path(tmp) / "result.tar"
            path.write_bytes(out.bundle)
            try:
                store.import_tar(path, append=True)
            except MorficError as exc:  # nothing was imported (all or nothing)
                return f"import: {exc}"
    return ""


def execute(
    job: Job,
    cfg: ReproduceCfg,
    driver_version: str,
    *inputs: Outcome | bytes,
    board=None,
    trusted: tuple[str, ...] = (),
    workdir: str | None = None,
) -> Outcome:
    """Run ``job`` in a fresh store fed with ``inputs``; return its refs as one export bundle.

    ``trusted``: the user variants the driver's user consented to (its command line and allow-list,
    :func:`~morfic_cli.rl.variants.trusted_variants`); the job imports those and no other user code, whatever
    its input runs name (plus what this node's own allow-list holds). ``workdir``: where the job's temporary store
    goes (default the system's temporary folder; ``--jobs`` gives a folder it removes even after killing the job).

    A :class:`MorficError` (a user error: bad config, a mismatched morfic version, an input job that failed) is
    returned in ``Outcome.error``, so Ray does not retry it; anything else raises (a bug keeps its traceback).
    A killed worker process returns nothing and Ray retries the job.
    """
    import torch

    from morfic_cli.rl.variants import consent_scope
    from morfic_cli.store import Store

    out = Outcome(job.key, where(), os.getpid())
    if board is not None:
        board.start.remote(job.key, out.node, out.pid)
    root = Path(tempfile.mkdtemp(prefix="morfic-job-", dir=workdir))
    try:
        check_version(driver_version)
        store = Store(root / "store")
        for i, item in enumerate(inputs):
            tar = root / f"input-{i}.tar"
            tar.write_bytes(input_bundle(item))
            store.import_tar(tar)
        before = _histories(store)
        if cfg.torch_threads:
            torch.set_num_threads(cfg.torch_threads)
        with consent_scope(trusted):
            out.step = run_job(Pipeline(store, cfg), job)
        after = _histories(store)
        out.refs = sorted(name for name, ids in after.items() if before.get(name) != ids)
        if out.refs:
            tar = root / "result.tar"
            store.export_tar(out.refs, tar)
            out.bundle = tar.read_bytes()
    except MorficError as exc:
        out.error = str(exc)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return out
