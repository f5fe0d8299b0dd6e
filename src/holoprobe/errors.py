"""Exceptions raised for a user's mistakes.

Every error that a user can cause (a wrong file, a missing field, an array of the
wrong shape, a grid that is not uniform) is raised as :class:`InputError` with a
message that names the file (when there is one), the field and what was expected.
The command-line interface prints that message on one line and exits with status 2.
"""

from __future__ import annotations

__all__ = ["InputError", "input_error"]


class InputError(ValueError):
    """A problem with user-supplied data or parameters.

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


def input_error(message: str, *, file: str | None = None, field: str | None = None) -> InputError:
    """Build an :class:`InputError` (a shorthand for ``raise input_error(...)``)."""
    return InputError(message, file=file, field=field)
