"""Errors that the command line reports as a one-line message (no traceback)."""

from __future__ import annotations

from peghole_mjx.geometry.specs import InfeasibleGeometryError


class UserInputError(ValueError):
    """Bad input from the user: a missing file, a malformed mesh, an unknown option value."""


#: Exceptions that ``peghole`` prints as ``peghole: error: ...`` with exit status 2.
REPORTED_ERRORS: tuple[type[BaseException], ...] = (
    UserInputError,
    InfeasibleGeometryError,
    FileNotFoundError,
    KeyError,
)
