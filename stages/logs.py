"""The engine's log: which library messages and Python warnings reach stderr, each as one line."""
from __future__ import annotations

import logging
import sys
import warnings

from . import registry


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
