"""``morfic export``: deployable ONNX / TorchScript policies with their metadata, and ``--check``."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, ExportTo, FormatOpt, OutputFormat, QuietOpt, StoreOpt, TrustOpt
from morfic_cli.cli._render import emit_object, err_console, info
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args

if TYPE_CHECKING:
    from morfic_cli.store import Store


def export(
    run: Annotated[
        str,
        typer.Argument(
            help="Run ref (runs/film-cpu-s0 = its latest checkpoint), ref@N or checkpoint id; with --check: an export "
            "(exports/... ref or id) or a directory written with --out."
        ),
    ],
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot",
            help="Bake this robot's descriptor into the model (its gains, pose and limits go into the "
            "metadata). Default: the descriptor stays a model input and every robot is described.",
        ),
    ] = None,
    to: Annotated[
        ExportTo,
        typer.Option(
            "--to",
            help="Model format: onnx (onnxruntime-verified), torchscript, or rsl-rl (a checkpoint "
            "rsl-rl's OnPolicyRunner.load reads, with its runner config agent.json).",
        ),
    ] = ExportTo.onnx,
    targets: Annotated[
        bool,
        typer.Option("--targets", help="Also output the joint position targets q0 + action_scale * a (needs --robot)."),
    ] = False,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Also write the model and policy.json into this directory.")
    ] = None,
    check: Annotated[
        bool, typer.Option("--check", help="Re-verify an existing export against its checkpoint instead of exporting.")
    ] = False,
    samples: Annotated[int, typer.Option("--samples", help="Random inputs of the verification.")] = 256,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Export a deployable policy with the metadata a robot stack needs.

    The model is the deployed actor path (adaptation module + morphology encoder + actor, observation
    normalisation included): inputs `history` (N, 16, 48) (15 for runs before issue 16) and, unless --robot
    bakes it in, `morphology` (N, 11);
    output `actions` (N, 12) (and `joint_targets` with --targets). ONNX has opset 18 and a dynamic batch axis.
    policy.json beside it holds the joint order, default pose, action scale, Kp/Kd, torque and joint limits,
    observation layout and scales, history length, control dt, descriptor, run and checkpoint ids. The export is
    verified against the torch actor (max |Δ| < 1e-5) before it is stored (ref exports/<run>/<robot>-<format>).
    docs/deploy.md runs it in a 50 Hz sim-to-sim loop.

    --to rsl-rl writes rsl-rl's own checkpoint layout instead (model_<iteration>.pt with actor_state_dict,
    critic_state_dict, optimizer_state_dict, iter, infos; agent.json = the runner config; train.json = morfic's
    config), stored as exports/<run>/rsl-rl.

    Example: morfic export runs/film-cpu-s0 --robot go1 --to onnx --out deploy/go1
    """
    check_args(store=store, out_dir=out, specs=[run], trust=trust_variant)
    from morfic_cli.store import Store

    st = Store(store)
    if not (check and Path(run).is_dir()):
        st.resolve(run)  # an unknown ref fails here in a second, before torch and the exporters are imported
    from morfic_cli.export.artifact import ExportCfg, export_policy

    if check:
        _check(st, run, samples, quiet, fmt)
        return
    if to is ExportTo.rsl_rl:
        _rsl_rl(st, run, out, robot, targets, quiet, fmt)
        return
    cfg = ExportCfg(robot=robot, fmt=to.value, targets=targets, samples=samples)
    with _phases(quiet) as on_phase:
        result = export_policy(st, run, cfg, out=out, on_phase=on_phase)
    meta = result.metadata
    if not quiet:
        info(f"verified: {result.verification.summary()}")
        info(f"stored {result.ref} ({result.id[:12]})" + (f", wrote {out}" if out is not None else ""))
    emit_object(
        {
            "ref": result.ref,
            "id": result.id,
            "checkpoint": meta["checkpoint"],
            "format": meta["format"],
            "robot": meta["baked_robot"],
            "inputs": [s["name"] for s in meta["inputs"]],
            "outputs": [s["name"] for s in meta["outputs"]],
            "files": {name: len(data) for name, data in result.files.items()},
            "written": [str(p) for p in result.written],
            "verification": result.verification.to_dict(),
        },
        fmt,
    )


@contextlib.contextmanager
def _phases(quiet: bool) -> Iterator[Callable[[str], None]]:
    """A spinner on stderr naming the export's current phase; a line with its time as each phase ends."""
    if quiet:
        yield lambda _text: None
        return
    current: list[tuple[str, float]] = []

    def finish() -> None:
        if current:
            text, start = current.pop()
            info(f"export: {text}: {time.perf_counter() - start:.1f} s")

    with err_console.status("export") as status:

        def on_phase(text: str) -> None:
            finish()
            current.append((text, time.perf_counter()))
            status.update(f"export: {text}")

        yield on_phase
        finish()


def _rsl_rl(
    st: Store, run: str, out: Path | None, robot: str | None, targets: bool, quiet: bool, fmt: OutputFormat
) -> None:
    """``--to rsl-rl``: the checkpoint in rsl-rl's layout (the actor keeps the descriptor as an input)."""
    from morfic_cli.export.artifact import export_rsl_rl

    if robot is not None or targets:
        raise MorficError(
            "--to rsl-rl exports the whole checkpoint (actor and critic, the descriptor stays an "
            "input); drop --robot / --targets."
        )
    result = export_rsl_rl(st, run, out=out)
    if not quiet:
        info(
            f"{'reused' if result.reused else 'stored'} {result.ref} ({result.id[:12]})"
            + (f", wrote {out}" if out is not None else "")
            + ("; optimizer state: fresh (this checkpoint carries weights only)" if result.optimizer == "fresh" else "")
        )
    emit_object(
        {
            "ref": result.ref,
            "id": result.id,
            "checkpoint": result.checkpoint,
            "format": "rsl-rl",
            "optimizer": result.optimizer,
            "files": {name: len(data) for name, data in result.files.items()},
            "written": [str(p) for p in result.written],
        },
        fmt,
    )


def _check(st: Store, source: str, samples: int, quiet: bool, fmt: OutputFormat) -> None:
    """``--check``: re-verify an export, print the result, fail (exit 1) when anything is wrong."""
    from morfic_cli.export.artifact import check_export

    result = check_export(st, source, samples=samples)
    meta = result.metadata
    if not quiet:
        info(f"check: {result.verification.summary()}")
    emit_object(
        {
            "source": source,
            "ok": result.ok,
            "checkpoint": meta.get("checkpoint"),
            "format": meta.get("format"),
            "robot": meta.get("baked_robot"),
            "verification": result.verification.to_dict(),
            "problems": result.problems,
        },
        fmt,
    )
    if not result.ok:
        reasons = result.problems or [result.verification.summary()]
        raise MorficError(f"export check of {source} failed: " + "; ".join(reasons))
