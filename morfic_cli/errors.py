"""Errors a user can cause.

Every class here is a :class:`MorficError`. The CLI prints ``Error: <message>`` on stderr and exits
with status 1; the message says what was wrong and what to do about it. A traceback is shown only
with ``MORFIC_DEBUG=1``.
"""

from __future__ import annotations

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
