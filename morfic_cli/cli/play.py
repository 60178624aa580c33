"""``morfic play``: watch a trained policy walk, live in Foxglove (or MuJoCo's viewer)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from morfic_cli.cli._options import DEFAULT_STORE, EvalMode, ModeOpt, QuietOpt, SeedOpt, StoreOpt, TrustOpt
from morfic_cli.cli._render import info
from morfic_cli.errors import MorficError
from morfic_cli.validation import check_args


def play(
    run: Annotated[
        str, typer.Argument(help="Run ref (runs/film-cpu-s0 = its latest checkpoint), ref@N or checkpoint id.")
    ],
    robot: Annotated[str, typer.Option("--robot", help="Robot to walk (see `morfic robots ls`).")] = "go2",
    mode: ModeOpt = EvalMode.descriptor,
    command_vx: Annotated[float, typer.Option("--command-vx", help="Forward command in m/s.")] = 1.0,
    envs: Annotated[int, typer.Option("--envs", help="Envs simulated and shown side by side.")] = 1,
    host: Annotated[
        str,
        typer.Option(
            "--host",
            help="Interface the WebSocket server binds (127.0.0.1: this "
            "machine only; 0.0.0.0 exposes it to the network).",
        ),
    ] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", help="WebSocket port (0: any free port).")] = 8765,
    record: Annotated[
        Path | None,
        typer.Option(
            "--record", help="Also write the session as an MCAP rollout log (the channels of `morfic eval`'s logs)."
        ),
    ] = None,
    viewer: Annotated[
        bool,
        typer.Option("--viewer", help="MuJoCo's own viewer window (needs a display) instead of the Foxglove server."),
    ] = False,
    steps: Annotated[int, typer.Option("--steps", help="Stop after this many policy steps (0: run until Ctrl-C).")] = 0,
    seed: SeedOpt = 0,
    quiet: QuietOpt = False,
    trust_variant: TrustOpt = None,
    store: StoreOpt = DEFAULT_STORE,
) -> None:
    """Run a policy in real time (50 policy steps per second) and serve the 3D scene and its numbers live.

    Serves the channels of an eval log (/scene, /tf, /rollout/step; docs/mcap.md) over the Foxglove WebSocket
    protocol and prints the URL to open in Foxglove (Open connection -> Foxglove WebSocket). Ctrl-C stops.

    Example: morfic play runs/film-cpu-s0 --robot go1 --command-vx 1.5 --envs 4 --record go1.mcap
    """
    check_args(trust=trust_variant)
    from morfic_cli.evaluation.play import PlayCfg
    from morfic_cli.evaluation.play import play as run_play
    from morfic_cli.morphology.robots import load_robot
    from morfic_cli.rl.load import load_trained
    from morfic_cli.store import Store

    load_robot(robot)  # an unknown name: the error every command gives (UnknownNameError, the library's order)
    if envs < 1 or steps < 0 or not 0 <= port <= 65535:
        raise MorficError("--envs must be positive, --steps >= 0 and --port in 0..65535.")
    if not host.strip():  # an empty host would bind every interface
        raise MorficError(
            "--host must name an interface: 127.0.0.1 (this machine only, the default) or 0.0.0.0 (every interface)."
        )
    mode_name = mode.value if isinstance(mode, EvalMode) else str(mode)
    cfg = PlayCfg(
        robot=robot,
        mode=mode_name,
        command_vx=command_vx,
        num_envs=envs,
        seed=seed,
        steps=steps,
        host=host,
        port=port,
        record=record,
        viewer=viewer,
    )
    trained = load_trained(Store(store), run)  # bad refs fail here, before anything opens

    def ready(live) -> None:
        from morfic_cli.recording.ws_relay import is_loopback

        if live is not None and not is_loopback(host):  # even with --quiet
            info(
                f"warning: --host {host} serves the live view to other machines too, without authentication: "
                f"anyone who can reach port {live.port} can watch"
            )
        if quiet:
            return
        if live is None:
            info("MuJoCo viewer open; close its window or press Ctrl-C to stop")
            return
        info(
            f"Foxglove live view of {run} on {robot} ({mode_name}, vx={command_vx:g} m/s, {envs} env(s)): "
            f"ws://{host}:{live.port}"
        )
        info(
            f"open it in Foxglove: Open connection -> Foxglove WebSocket -> ws://{host}:{live.port}, "
            f"or {live.app_url()}"
        )
        info("Ctrl-C stops")

    def behind(rate: float, target: float) -> None:
        if not quiet:
            info(
                f"note: this machine runs {rate:.0f} policy steps/s, behind real time ({target:.0f} steps/s): the "
                f"robot moves at {rate / target:.2f}x speed; fewer --envs or a less busy machine keep up."
            )

    try:
        n = run_play(trained, cfg, on_ready=ready, on_behind=behind)
    except OSError as exc:  # e.g. the port is taken
        raise MorficError(f"could not serve on {host}:{port} ({exc}); pick another --port.") from exc
    if not quiet:
        info(f"stopped after {n} policy steps" + (f"; recorded {record}" if record is not None else ""))
