"""The library's exception classes: every error a user can cause is one of these.

Each prints a plain message (no quotes, no traceback needed) and also derives from the
built-in type callers already catch (``ValueError``, ``KeyError``, ...), so code written
against the built-ins keeps working. The command line turns any :class:`ImulocoError` into a
one-line ``Error: ...``.
"""

from __future__ import annotations

from pathlib import Path


class ImulocoError(Exception):
    """Base class: an error caused by the user's input, files or options."""

    def __str__(self) -> str:  # KeyError would quote its message
        return str(self.args[0]) if self.args else ""


class FormatError(ImulocoError, ValueError):
    """A malformed input file: names the file, the line (1-based, when known) and what was
    expected there."""

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


class InputError(ImulocoError, ValueError):
    """An input that is well formed but cannot be used as asked: a model trained for another
    placement, motions that cannot be compared, a recording that cannot be calibrated."""


class ModelFileError(ImulocoError, ValueError):
    """A model file that cannot be loaded: corrupted, of another format version or method."""


class UnknownNameError(ImulocoError, KeyError):
    """A name that is not known: a method, placement, noise preset, split, clip or joint."""


class MissingExtraError(UnknownNameError):
    """A feature whose optional dependency is not installed; names the extra to install."""

    def __init__(self, what: str, module: str, extra: str) -> None:
        self.module = module
        self.extra = extra
        super().__init__(f"{what} needs {module}: pip install 'imuloco[{extra}]'")


class NotFittedError(ImulocoError, ValueError, AttributeError):
    """A method used before :meth:`fit` (or loading a model file), as scikit-learn's."""


class OutputExistsError(ImulocoError, FileExistsError):
    """An output file that exists already and was not to be replaced."""


class MissingInputError(ImulocoError, FileNotFoundError):
    """An input file or folder that does not exist, or a folder without what is read from it
    (a data folder without motion files)."""


class ParameterError(InputError):
    """A method's hyperparameter that its constraint table refuses (of another kind, outside
    its interval, not one of its options, unknown); ``key`` names it."""

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        super().__init__(message)


EXCERPT_CHARS = 24  # the most of a user's file an error message quotes


def excerpt(text: str, limit: int = EXCERPT_CHARS) -> str:
    """A cell of a user's file as an error message quotes it: stripped, at most ``limit``
    characters (``...`` marks a cut), non-printable characters escaped (``repr``).

    The rule for every reader's errors: name the file and line, and quote at most one cell (or
    column name) so, never a whole line: the file may be another's (a link, a mistaken path),
    and a line of it is none of the log's business."""
    s = str(text).strip()
    quoted = repr(s[:limit])
    return f"{quoted[:-1]}...{quoted[-1]}" if len(s) > limit else quoted


def excerpts(cells: list[str], most: int = 8) -> str:
    """Up to ``most`` cells (column names of a header) as :func:`excerpt` quotes each, and how
    many more there are."""
    shown = ", ".join(excerpt(c) for c in cells[:most])
    return f"[{shown}{f', ... {len(cells) - most} more' if len(cells) > most else ''}]"
