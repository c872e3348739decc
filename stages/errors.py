"""Errors the engine reports to users: each names the file, the key and what to do."""
from __future__ import annotations

import logging
import sys
import warnings

_WARNED: set[str] = set()


class _OneLine(logging.Formatter):
    """``warning: message`` on one line (a message's own line breaks become spaces), no logger name or source."""

    def format(self, record: logging.LogRecord) -> str:
        return f"{record.levelname.lower()}: {' '.join(record.getMessage().split())}"


class _ProjectOnly(logging.Filter):
    """Log records of the plugins' own packages (``registry.fingerprint_packages``: e.g. a mesh repair), of the
    engine and Python warnings; not the chatter of the libraries underneath (dask workers shutting down, ...)."""

    packages: tuple[str, ...] | None = None

    def filter(self, record: logging.LogRecord) -> bool:
        if self.packages is None:
            from . import registry
            try:
                registry.load_library()
            except Exception:  # noqa: BLE001 - a plugin that cannot be loaded is reported where a stage needs it;
                pass           # the messages of the plugins that did load still count
            self.packages = ("stages", "py.warnings", *registry.fingerprint_packages())
        return any(record.name == p or record.name.startswith(p + ".") for p in self.packages)


def _warning_line(message, category, filename, lineno, line=None) -> str:
    """A Python warning as one line: its message and its category, without the source file or line."""
    return f"{message} ({category.__name__})"


def configure_logging() -> None:
    """The engine's reporter for library messages: every ``logging`` warning or error of the plugins' packages
    (e.g. a mesh repair) and every Python warning printed to stderr as one line
    (``warning: 008.obj: dropped 4,780 duplicate faces ...``) without the source line a Python warning shows.
    Idempotent; the CLI calls it, and so does every task on a dask worker."""
    root = logging.getLogger()
    if any(isinstance(h.formatter, _OneLine) for h in root.handlers):
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLine())
    handler.setLevel(logging.WARNING)
    handler.addFilter(_ProjectOnly())
    root.addHandler(handler)
    if root.level == logging.NOTSET or root.level > logging.WARNING:
        root.setLevel(logging.WARNING)
    warnings.formatwarning = _warning_line
    logging.captureWarnings(True)


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
