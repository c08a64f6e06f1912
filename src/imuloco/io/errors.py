"""The one error type of every file parser in imuloco."""

from __future__ import annotations

from pathlib import Path


class FormatError(ValueError):
    """A malformed input file: names the file, the line (1-based, when known) and what was
    expected there."""

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")
