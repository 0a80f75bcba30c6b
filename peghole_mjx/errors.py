"""Errors that the command line reports as a one-line message (no traceback)."""

from __future__ import annotations

import json
import zipfile


class UserInputError(ValueError):
    """Bad input from the user: a missing file, a malformed mesh, an unknown option value."""


class CorruptFileError(UserInputError):
    """A file that peghole_mjx wrote (or should have) is truncated, garbled or tampered with."""


class MissingExtraError(UserInputError, ImportError):
    """An optional dependency is not installed; the message names the extra that installs it."""


# after the classes above: specs validates its presets at import, with peghole_mjx.validation,
# which imports UserInputError from here
from peghole_mjx.geometry.specs import InfeasibleGeometryError  # noqa: E402

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
