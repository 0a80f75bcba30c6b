"""Errors that the command line reports as a one-line message (no traceback).

The package's exception classes live here and import nothing from the package, so that any
module can raise them (``geometry.specs`` re-exports :class:`InfeasibleGeometryError`).
"""

from __future__ import annotations

import json
import zipfile


class UserInputError(ValueError):
    """Bad input from the user: a missing file, a malformed mesh, an unknown option value."""


class CorruptFileError(UserInputError):
    """A file that peghole_mjx wrote (or should have) is truncated, garbled or tampered with."""


class InfeasibleGeometryError(ValueError):
    """A peg-hole specification violates a size or extractability condition.

    ``condition`` names the violated condition (e.g. ``"eq 2.1"``), ``values`` the numbers.
    """

    def __init__(self, condition: str, message: str, values: dict[str, float] | None = None):
        self.condition = condition
        self.values = dict(values or {})
        detail = ", ".join(f"{k} = {v:g}" for k, v in self.values.items())
        super().__init__(f"{condition} violated: {message}" + (f" ({detail})" if detail else ""))


class MissingExtraError(UserInputError, ImportError):
    """An optional dependency is not installed; the message names the extra that installs it."""


#: Exceptions that ``peghole`` prints as ``peghole: error: ...`` with exit status 2: wrong
#: user values, and the expected failures of files (missing, unreadable, not writable, a
#: full disk, truncated or garbled JSON and npz). Anything else is a bug: a traceback.
REPORTED_ERRORS: tuple[type[BaseException], ...] = (
    UserInputError,
    InfeasibleGeometryError,
    KeyError,
    OSError,  # FileNotFoundError, PermissionError, ENOSPC, EROFS, ...
    json.JSONDecodeError,
    UnicodeDecodeError,
    zipfile.BadZipFile,
    EOFError,
)
