"""Errors a user can cause.

Every class here is a :class:`MorficError`. The CLI prints ``Error: <message>`` on stderr and exits
with status 1; the message says what was wrong and what to do about it. A traceback is shown only
with ``MORFIC_DEBUG=1``.
"""

from __future__ import annotations

import unicodedata
from collections.abc import Iterable


class MorficError(Exception):
    """Base class for every error a user can cause (bad input, missing artifact, ...)."""


class UnknownNameError(MorficError):
    """A name (robot, variant, ...) that is not one of the valid choices."""

    def __init__(self, what: str, name: str, valid: Iterable[str]) -> None:
        valid = sorted(valid)
        self.valid = valid
        super().__init__(f"unknown {what} '{name}'; valid {what}s are: {', '.join(valid)}.")


class RobotSpecError(MorficError):
    """A robot TOML that is malformed or physically impossible."""


class StoreError(MorficError):
    """A problem with the artifact store (corrupt object, bad ref, lock, ...)."""


class ArtifactNotFoundError(StoreError):
    """An artifact id, prefix or ref that does not resolve to anything in the store."""


class DescriptorError(MorficError):
    """A morphology descriptor with the wrong shape or values outside any sane range."""


class UntrustedVariantError(MorficError):
    """A user variant (code) a stored run names that the user has not consented to import (docs/extending.md)."""


def printable(text: object, *, keep: str = "") -> str:
    r"""``text`` with every control or format character (C0, C1, DEL, bidi overrides, zero-width) escaped.

    The one helper for text a bundle supplies (a manifest's meta and config, a trainer state's values, file names)
    on its way to a terminal: ESC ``[2J`` prints as the characters ``[2J``, never as an escape sequence.
    ``keep``: characters left as they are (the CLI keeps the newline in multi-line messages).
    Example: ``printable("a]0;pwned")`` -> ``a]0;pwned`` as plain, visible text.
    """
    text = str(text)
    if text.isprintable() and text.isascii():
        return text
    return "".join(c if c in keep or unicodedata.category(c) not in UNPRINTABLE else ascii(c)[1:-1] for c in text)


UNPRINTABLE = ("Cc", "Cf", "Cs", "Co", "Zl", "Zp")
"""Unicode categories :func:`printable` escapes: controls, format characters, surrogates, private use, separators."""
