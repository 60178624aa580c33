"""``morfic trust``: the allow-list of user variants morfic may import when a stored run names them."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.markup import escape

from morfic_cli.cli._options import FormatOpt, OutputFormat
from morfic_cli.cli._render import Column, emit_rows, info
from morfic_cli.errors import MorficError, printable


def trust(
    names: Annotated[
        list[str] | None,
        typer.Argument(
            help="User variants to trust: import paths module.path:Class, or "
            "entry-point names. None: print the allow-list."
        ),
    ] = None,
    remove: Annotated[bool, typer.Option("--remove", help="Take the named variants off the allow-list.")] = False,
    list_: Annotated[bool, typer.Option("--list", help="Print the allow-list (also what no names does).")] = False,
    fmt: FormatOpt = OutputFormat.table,
) -> None:
    """Trust user variants: let every command import them when a stored run names them.

    A run records its critic variant, and a run can come from anyone's bundle, so morfic imports a user variant
    (your own critic class) only when you consented to that exact name: with --trust-variant on the command, or
    once here. The allow-list is a file in your config folder ($XDG_CONFIG_HOME/morfic/trusted-variants, else
    ~/.config/morfic/trusted-variants), never in a store, signed with a key of yours beside it (.trust-key): a list
    morfic trust did not write (a bundle's file, an edit by hand) trusts nothing. Trusting imports nothing;
    `morfic train --variant` adds the variant it trains. Stock variants need no trust.

    Example: morfic trust my_lab.critics:GatedCritic
    Example: morfic trust --remove my_lab.critics:GatedCritic
    """
    from morfic_cli.rl.variants import (
        STOCK,
        add_to_allow_list,
        allow_list_path,
        read_allow_list,
        remove_from_allow_list,
    )

    names = list(names or [])
    path = allow_list_path()
    if list_ and names:
        raise MorficError("--list takes no names; run `morfic trust NAME` or `morfic trust --remove NAME` first.")
    if remove and not names:
        raise MorficError("--remove needs the variants to remove, e.g. morfic trust --remove my_lab.critics:Critic.")
    if not names:
        trusted, ignored = read_allow_list()
        info(f"allow-list {path}: {len(trusted)} trusted user variant(s)")
        if ignored:
            shown = printable(", ".join(ignored[:5])) + (f" and {len(ignored) - 5} more" if len(ignored) > 5 else "")
            info(
                f"ignored: {shown}: the list is not signed by `morfic trust` (a file from elsewhere, e.g. fetched by "
                "`morfic store get`, or edited by hand), so it trusts nothing; `morfic trust NAME` for each you "
                "trust writes it again, signed."
            )
        emit_rows([{"variant": n} for n in trusted], fmt, columns=[Column("variant", "trusted user variant")])
        return
    try:
        if remove:
            removed = remove_from_allow_list(names)
            missing = [n for n in names if n not in removed]
            for n in removed:
                info(f"no longer trusted: {n} ({path})")
            if missing:
                raise MorficError(
                    f"{', '.join(missing)} {'is' if len(missing) == 1 else 'are'} not on the allow-list "
                    f"{path}; `morfic trust --list` shows it."
                )
            return
        for n in names:
            if n in STOCK:
                info(f"{n} is a stock variant; it needs no trust.")
        added = add_to_allow_list(names)
    except OSError as exc:
        raise MorficError(
            f"cannot write the allow-list {path} ({exc.strerror or exc}); check that folder's "
            "permissions, or pass --trust-variant to each command instead."
        ) from exc
    for n in names:
        if n in added:
            info(
                f"trusted: {n} ({path}); commands import it when a stored run names it (`morfic trust --remove "
                f"{n}` undoes it)."
            )
        elif n not in STOCK:
            info(f"{n} was already trusted ({path}).")


def remember_variants(names: list[str], quiet: bool = False) -> None:
    """Add user variants the user named to train with (``train --variant``, ``reproduce --variants``) to the allow-list.

    The user named the code on the command line, so later commands on the runs it trains import it too. A config
    folder that cannot be written is a note, not an error (the training already runs).
    """
    from morfic_cli.rl.variants import add_to_allow_list, allow_list_path

    try:
        added = add_to_allow_list(names)
    except (OSError, MorficError) as exc:  # a folder that cannot be written; a key morfic trust did not write
        if not quiet:
            why = exc.strerror if isinstance(exc, OSError) else str(exc).rstrip(".")
            info(
                f"note: could not add {', '.join(names)} to the allow-list {allow_list_path()} ({why}); "
                "later commands on its runs need --trust-variant."
            )
        return
    if added and not quiet:
        info(
            f"trusted {', '.join(added)} for later commands on its runs (added to {allow_list_path()}; `morfic "
            f"trust --remove {added[0]}` undoes it)."
        )


def note_skipped(ref: str, why: str) -> None:
    """The note when a default choice of runs leaves ``ref`` out (``diagnostics.fixed_rollout.newest_runs``)."""
    info(f"note: {escape(printable(ref))} left out of the default runs: {escape(printable(why))}")
