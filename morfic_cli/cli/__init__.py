"""The ``morfic`` command line: app assembly and central error handling.

Every subcommand lives in its own module and stays thin (parse -> call the library -> render).
``main()`` turns :class:`~morfic_cli.errors.MorficError` and usage errors into
``Error: <message>`` on stderr with exit status 1; ``MORFIC_DEBUG=1`` re-raises with a traceback.
Importing this module must not import torch or mujoco: heavy imports happen inside commands.
"""

from __future__ import annotations

import inspect
import os
import sys
import typing

import typer
import typer.core
import typer.models
from rich.markup import escape

try:  # typer >= 0.2x vendors its own copy of click
    from typer._click import exceptions as _click_exc
except ImportError:  # pragma: no cover - older typer depends on click
    from click import exceptions as _click_exc  # type: ignore[no-redef, import-not-found, unused-ignore]

from morfic_cli import __version__
from morfic_cli.cli import (
    bench,
    compare_baselines,
    critic_study,
    diagnose,
    distance,
    evaluate,
    export,
    play,
    report,
    reproduce,
    robots,
    store,
    train,
    trust,
)
from morfic_cli.cli._exit import freeze_at_exit
from morfic_cli.errors import MorficError, printable
from morfic_cli.threads import configure_openmp

app = typer.Typer(
    name="morfic",
    help=(
        "MorFiC: PPO locomotion with morphology-conditioned critics, zero-shot transfer to other "
        "quadrupeds, and critic-calibration diagnostics. Every result goes into a content-addressed "
        "artifact store (--store, env MORFIC_STORE, default ./artifacts).\n\n"
        "Example: morfic distance --format json"
    ),
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode="rich",
    context_settings={"help_option_names": ["-h", "--help"]},
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"morfic {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version."),
) -> None:
    """Root options."""


app.command("train")(train.train)
app.command("eval")(evaluate.evaluate)
app.command("play")(play.play)
app.command("diagnose")(diagnose.diagnose)
app.command("critic-study")(critic_study.critic_study)
app.command("compare-baselines")(compare_baselines.compare_baselines)
app.command("distance")(distance.distance)
app.command("export")(export.export)
app.command("report")(report.report)
app.command("reproduce")(reproduce.reproduce)
app.add_typer(store.app, name="store")
app.add_typer(robots.app, name="robots")
app.command("bench")(bench.bench)
app.command("trust")(trust.trust)


def unwrap_help(doc: str) -> str:
    """A docstring as help text: source line breaks inside a paragraph joined, rich markup escaped.

    Paragraphs (blank-line separated) stay apart; a line starting with ``Example``, ``Your own``, ``- `` (a list
    item) or indented starts a new line (command examples); a line starting with a flag (``--device``) continues
    the sentence before it. ``[gpu]`` in ``pip install 'morfic[gpu]'`` is escaped so rich shows it.
    """
    paragraphs = []
    for para in inspect.cleandoc(doc or "").split("\n\n"):
        lines: list[str] = []
        for line in para.splitlines():
            if lines and not line.startswith(("Example", "Your own", " ", "- ")):
                lines[-1] += " " + line.strip()
            else:
                lines.append(line)
        paragraphs.append("\n".join(lines))
    return escape("\n\n".join(paragraphs))


def _polish_help(typer_app: typer.Typer, seen: set[int]) -> None:
    """Unwrap and escape every command's docstring, escape every option's help (once per shared option object)."""
    for info in typer_app.registered_commands:
        if info.help is None and info.callback is not None:
            info.help = unwrap_help(info.callback.__doc__ or "")
        if info.callback is None:
            continue
        # the annotations are strings (``from __future__ import annotations``), evaluated anew on every read: evaluate
        # them once, escape the option help in place and keep the evaluated objects, so typer reads these
        hints = typing.get_type_hints(info.callback, include_extras=True)
        for hint in hints.values():
            for meta in getattr(hint, "__metadata__", ()):
                if isinstance(meta, typer.models.ParameterInfo) and meta.help and id(meta) not in seen:
                    seen.add(id(meta))
                    meta.help = escape(meta.help)
        info.callback.__annotations__ = hints
    for group in typer_app.registered_groups:
        if group.typer_instance is not None:
            _polish_help(group.typer_instance, seen)


_polish_help(app, set())


def _flag_type(self, ctx):  # noqa: ANN001, ANN202
    """Typer's TyperOption.display_type_rich, minus the ``<bool>`` of on/off flags (a flag takes no value)."""
    return None if getattr(self, "is_flag", False) else _display_type_rich(self, ctx)


# typer (0.29) prints `--quiet <bool>` for flags that take no value; show them as plain flags (one place).
_display_type_rich = typer.core.TyperOption.display_type_rich
typer.core.TyperOption.display_type_rich = _flag_type  # type: ignore[method-assign]


def _fail(message: str, code: int = 1) -> None:
    sys.stderr.write(f"Error: {printable(message, keep=chr(10))}\n")  # a bundle's text cannot drive the terminal
    sys.stderr.flush()
    sys.exit(code)


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: run the app with central error handling."""
    configure_openmp()  # before any command imports torch (morfic_cli/threads.py)
    freeze_at_exit()  # the exit after a torch-heavy command skips its garbage collection (cli/_exit.py)
    debug = os.environ.get("MORFIC_DEBUG", "") not in ("", "0")
    from morfic_cli.rl.variants import consent_scope

    try:
        with consent_scope():  # consent given on this command line (--trust-variant, --variant) ends with it
            rc = app(args=argv, prog_name="morfic", standalone_mode=False)
        if isinstance(rc, int) and rc != 0:
            sys.exit(rc)
    except MorficError as exc:
        if debug:
            raise
        _fail(str(exc))
    except _click_exc.NoArgsIsHelpError as exc:
        # typer's rich help is printed while the error is built; plain click returns it as the message.
        text = exc.format_message()
        if text.strip():
            sys.stdout.write(text + "\n")
        sys.exit(0)
    except _click_exc.UsageError as exc:
        if debug:
            raise
        hint = f" Try '{exc.ctx.command_path} --help'." if exc.ctx is not None else ""
        _fail(f"{exc.format_message()}.{hint}".replace("..", "."))
    except _click_exc.ClickException as exc:
        if debug:
            raise
        _fail(exc.format_message())
    except typer.Abort:
        sys.stderr.write("Aborted.\n")
        sys.exit(130)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        sys.stderr.write("Interrupted.\n")
        sys.exit(130)
