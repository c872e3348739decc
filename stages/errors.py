"""Errors the engine reports to users: each names the file, the key and what to do."""
from __future__ import annotations

import sys

_WARNED: set[str] = set()


def warn_once(message: str) -> None:
    """Print ``warning: message`` to stderr, once per process for the same message."""
    if message in _WARNED:
        return
    _WARNED.add(message)
    print(f"warning: {message}", file=sys.stderr, flush=True)


class PipelineError(Exception):
    """A problem with a pipeline file, a parameter or a data path.

    Formatted as ``FILE:LINE: KEY: message (fix: ...)`` so editors can jump to it.
    """

    def __init__(self, message: str, file: str | None = None, key: str | None = None,
                 line: int | None = None, fix: str | None = None):
        self.message, self.file, self.key, self.line, self.fix = message, file, key, line, fix
        super().__init__(self.format())

    def format(self) -> str:
        where = ""
        if self.file:
            where = self.file + (f":{self.line}" if self.line else "") + ": "
        key = f"{self.key}: " if self.key else ""
        fix = f"\n  fix: {self.fix}" if self.fix else ""
        return f"{where}{key}{self.message}{fix}"


class UserError(Exception):
    """A problem outside the pipeline file (a folder that cannot be written, a scheduler that does not answer,
    a bad command-line value): the CLI prints ``error: message`` and ``fix: ...`` and exits with 1."""

    def __init__(self, message: str, fix: str | None = None):
        self.message, self.fix = message, fix
        super().__init__(message + (f"\n  fix: {fix}" if fix else ""))


class CorruptEntry(Exception):
    """A cache entry whose data does not match its recorded checksum."""

    def __init__(self, key: str, detail: str):
        self.key, self.detail = key, detail
        super().__init__(f"cache entry {key[:12]} is corrupt: {detail}")
