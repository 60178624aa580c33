"""Well-formed variant names, checked without importing anything: the store checks a bundle's with them.

Below :mod:`morfic_cli.rl.variants` (the registry, which imports the classes) so that the store can refuse a
bundle that names a malformed variant without importing ``rl``.
"""

from __future__ import annotations

import keyword
import re
from collections.abc import Collection, Mapping
from typing import Any

from morfic_cli.errors import MorficError


def is_import_path(name: str) -> bool:
    """Whether ``name`` names a user class (``module:Class``) rather than a stock or entry-point variant."""
    return ":" in name


# ---------------------------------------------------------------------------- well-formed names
MAX_NAME_LENGTH = 200
"""The longest variant name morfic accepts (a stored run's, or one on the command line)."""

_IDENT = r"[A-Za-z_][A-Za-z0-9_]*"
_IMPORT_PATH = re.compile(rf"{_IDENT}(?:\.{_IDENT})*:{_IDENT}(?:\.{_IDENT})*")
_BARE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*(?:\.[A-Za-z0-9_-]+)*")


def _shown(value: object) -> str:
    """A value as an error message shows it: quoted, cut at 80 characters, control characters escaped."""
    if not isinstance(value, str):
        return f"{type(value).__name__} {ascii(value)[:80]}"
    cut = value[:80] + ("..." if len(value) > 80 else "")
    return f"'{cut}'" if cut.isascii() and cut.isprintable() else ascii(cut)


def check_variant_name(name: object, stock: Collection[str] = ()) -> str:
    """``name`` when it is a well-formed variant name, else MorficError; never imports anything.

    Well-formed: a stock name; an entry-point-style name (ASCII letters, digits, ``_``, ``-``, dots between
    parts); or an import path ``module.path:Class.attr`` whose parts are Python identifiers (ASCII, not keywords):
    no relative import (leading dot), no empty part, no whitespace or other characters; at most
    :data:`MAX_NAME_LENGTH` characters. ``morfic store import`` refuses a bundle whose manifests name anything else,
    and :func:`resolve_variant` checks it again before it imports (a store written before the check).

    Raises:
        MorficError: Not a string, too long, or not of either form.
    """
    if not isinstance(name, str):
        raise MorficError(
            f"variant {_shown(name)} is not a variant name; a variant is a stock name "
            f"({_stock_names(stock)}), an entry-point name, or an import path module:Class."
        )
    if name in stock:
        return name
    if len(name) > MAX_NAME_LENGTH:
        raise MorficError(
            f"variant {_shown(name)} is {len(name)} characters long; a variant name has at most {MAX_NAME_LENGTH}."
        )
    if is_import_path(name):
        parts = re.split(r"[.:]", name)
        if not _IMPORT_PATH.fullmatch(name) or any(keyword.iskeyword(p) for p in parts):
            raise MorficError(
                f"variant {_shown(name)} is not an import path; write it as module.path:Class, Python "
                "identifiers joined by dots, without a leading dot or spaces (e.g. "
                "my_lab.critics:GatedCritic)."
            )
        return name
    if not _BARE_NAME.fullmatch(name):
        raise MorficError(
            f"variant {_shown(name)} is not a variant name; give a stock name ({_stock_names(stock)}), "
            "an entry-point name (letters, digits, _ and -), or your own critic class by import path, "
            "module:Class (docs/extending.md)."
        )
    return name


def stored_variants(config: Mapping[str, Any], meta: Mapping[str, Any], stock: Collection[str] = ()) -> list[str]:
    """The variant names a stored manifest records (``variant`` and ``variants`` of its config and meta), checked.

    Only checked for form (:func:`check_variant_name`); nothing is imported. Order kept, each once.

    Raises:
        MorficError: One of them is not a well-formed variant name, or ``variants`` is not a list.
    """
    out: list[str] = []
    for doc in (config, meta):
        named = [doc["variant"]] if "variant" in doc else []
        if "variants" in doc:
            if not isinstance(doc["variants"], list):
                raise MorficError(f"its 'variants' is {type(doc['variants']).__name__}, not a list of variant names.")
            named += doc["variants"]
        for name in named:
            if check_variant_name(name, stock) not in out:
                out.append(name)
    return out


def _stock_names(stock: Collection[str]) -> str:
    """The stock names as an error message lists them: given, or where to find them."""
    return ", ".join(stock) if stock else "`morfic train --help` lists them"
