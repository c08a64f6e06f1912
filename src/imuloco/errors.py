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
