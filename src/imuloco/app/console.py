"""The terminal's one channel for log records: each on a line of its own above any progress
bar (``tqdm.write``), each kind of warning once, with a count of the repeats at the end.

A warning's *kind* is its logger and format string (``"%s: no samples from %.3f s ..."``), or
the ``kind`` a relay gives in ``extra`` (:mod:`imuloco.app.batch` passes on its workers'
warnings so). The command line installs :class:`Console` for the run of a command
(:func:`console`); library callers keep Python's logging as they configured it.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator


def write_line(text: str) -> None:
    """``text`` on a line of its own on the current ``sys.stderr``, above any tqdm bar (a bar
    can only be open when tqdm was imported: importing it here would slow every command)."""
    tqdm = sys.modules.get("tqdm")
    if tqdm is not None:
        tqdm.tqdm.write(text, file=sys.stderr)
    else:
        print(text, file=sys.stderr)


class Console(logging.Handler):
    """Writes records with ``tqdm.write`` to the current ``sys.stderr``; a warning (or worse)
    whose kind was written before is counted instead (:attr:`repeats`), and
    :meth:`summary_lines` says how many of each kind were left out."""

    def __init__(self, level: int = logging.NOTSET) -> None:
        super().__init__(level)
        self.first: dict[tuple[str, str], str] = {}  # kind -> its first message
        self.repeats: dict[tuple[str, str], int] = {}

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            if record.levelno >= logging.WARNING:
                kind = (record.name, str(getattr(record, "kind", record.msg)))
                if kind in self.first:
                    self.repeats[kind] = self.repeats.get(kind, 0) + 1
                    return
                self.first[kind] = text
            write_line(text)
        except Exception:  # noqa: BLE001 - logging's own contract: never raise from emit
            self.handleError(record)

    def summary_lines(self) -> list[str]:
        """One line per kind that repeated: how many more, and the first one's start."""
        out = []
        for kind, n in self.repeats.items():
            first = self.first[kind].splitlines()[0]
            first = first if len(first) <= 90 else first[:87] + "..."
            out.append(f"({n} more warning{'s' if n > 1 else ''} like: {first})")
        return out


class _Format(logging.Formatter):
    """Warnings as their message (what the user reads); other records, the live server's
    events, with the time: ``12:03:04 viewer connected``."""

    def __init__(self) -> None:
        super().__init__("%(asctime)s %(message)s", datefmt="%H:%M:%S")

    def format(self, record: logging.LogRecord) -> str:
        if record.levelno >= logging.WARNING:
            return record.getMessage()
        return super().format(record)


@contextlib.contextmanager
def console() -> Iterator[Console]:
    """A :class:`Console` on the root logger for the block (Python's last-resort handler,
    which wrote warnings at the end of a progress bar's line, is then not used; the root
    logger's level decides what reaches it), then the repeats' counts."""
    root = logging.getLogger()
    handler = Console()
    handler.setFormatter(_Format())
    root.addHandler(handler)
    try:
        yield handler
    finally:
        root.removeHandler(handler)
        for line in handler.summary_lines():
            write_line(line)
