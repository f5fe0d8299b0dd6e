"""Exceptions: a user's mistake (:class:`InputError`) or a fit the data do not support
(:class:`FitError`), both :class:`HoloprobeError`.

Every error that a user can cause (a wrong file, a missing field, an array of the
wrong shape, a grid that is not uniform) is raised as :class:`InputError` with a
message that names the file (when there is one), the field and what was expected.
An estimation that fails on valid inputs (no onset above the noise, no aperture edge
inside the grid, a fit that does not converge) raises :class:`FitError`, whose message
names what in the data caused it. The command-line interface prints either message on
one line and exits with status 2.
"""

from __future__ import annotations

__all__ = ["FitError", "HoloprobeError", "InputError", "input_error", "require_instance"]


class HoloprobeError(ValueError):
    """Base of holoprobe's errors: a message, and the file and field it concerns.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    file : str, optional
        The file the data came from.
    field : str, optional
        The name of the field (dataset, variable, argument) that is wrong.
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None):
        self.file = None if file is None else str(file)
        self.field = field
        self.detail = message
        parts = []
        if self.file:
            parts.append(self.file)
        if field:
            parts.append(field)
        prefix = ": ".join(parts)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class InputError(HoloprobeError):
    """A problem with user-supplied data or parameters (a wrong file, a missing field, an
    array of the wrong shape, a value out of range)."""


class FitError(HoloprobeError):
    """An estimation that the data do not support (valid inputs, but e.g. no onset above
    the noise or no aperture edge inside the grid); the message says what in the data
    caused it and ``field`` names the quantity."""


def input_error(message: str, *, file: str | None = None, field: str | None = None) -> InputError:
    """Build an :class:`InputError` (a shorthand for ``raise input_error(...)``)."""
    return InputError(message, file=file, field=field)


def require_instance(value: object, cls: type, field: str) -> None:
    """Raise :class:`InputError` "expected a <cls>, got <type of value>" naming ``field``
    unless ``value`` is an instance of ``cls`` (the check of every writer's argument)."""
    if not isinstance(value, cls):
        article = "an" if cls.__name__[:1] in "AEIOU" else "a"
        raise InputError(f"expected {article} {cls.__name__}, got {type(value).__name__}",
                         field=field)
