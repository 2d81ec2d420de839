"""The project's own error types.

Every error a user can cause (a broken map, a bad rule file, a wrong model file) is raised as a
:class:`SemmapError`. Its message is one line that names the file and what is wrong, in the
``file:line:col: message`` form when a position is known. The command line prints that line and
exits non-zero; nothing else is allowed to escape to the user as a traceback.
"""

from __future__ import annotations

import os


def printable(text) -> str:
    """``text`` (a path, or text that holds one) as text that any UTF-8 output takes: a byte of a
    file name that is not UTF-8 (which Python keeps as a lone surrogate, ``os.fsdecode``) is
    shown as ``\\xNN``.

    >>> printable("/tmp/\\udcff.png"), printable("caf\\u00e9.yaml")
    ('/tmp/\\\\xff.png', 'café.yaml')
    """
    text = os.fspath(text) if isinstance(text, (str, bytes, os.PathLike)) else str(text)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        pass
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:      # a surrogate no file name gives (a JSON escape "\\ud800")
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


class SemmapError(Exception):
    """A user-facing error: one line naming the file and the problem."""

    def __init__(self, path: str | os.PathLike | None, message: str,
                 line: int | None = None, col: int | None = None):
        self.path = None if path is None else os.fspath(path)
        self.message = " ".join(str(message).split())  # always one line
        self.line = line
        self.col = col
        super().__init__(str(self))

    def __reduce__(self):
        # rebuilt from its fields, so an error raised in a sampling worker reaches the main
        # process as itself (the default pickling calls __init__ with the formatted string only)
        return (type(self), (self.path, self.message, self.line, self.col))

    def __str__(self) -> str:
        where = printable(self.path) if self.path is not None else "<input>"
        if self.line is not None:
            where += f":{self.line}"
            if self.col is not None:
                where += f":{self.col}"
        return f"{where}: {printable(self.message)}"


class MapError(SemmapError):
    """An occupancy grid map (YAML, image or array) cannot be read or makes no sense."""


class ModelError(SemmapError):
    """A model file (``models/*.toml``) is missing a value or holds an invalid one."""


class RuleError(SemmapError):
    """A rule file is malformed, unsafe or contradictory."""


class EvidenceError(SemmapError):
    """Evidence facts handed to the knowledge engine are malformed."""


class OutputError(SemmapError):
    """An output directory or file cannot be written as asked."""


class WriteError(OutputError):
    """A file cannot be written (a full disk, a quota, a read-only file system): the message is
    the reason, shown as ``cannot write PATH: reason``."""

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.message}"


class BusyError(OutputError):
    """An output folder another run holds (:mod:`semmap_pp.run.outdir`): shown as ``PATH message``."""

    def __str__(self) -> str:
        return f"{self.path} {self.message}"
