"""Import Open3D on machines without a system libusb, without its plotly drawing until it is used.

``import open3d`` links against ``libusb-1.0.so.0``. The PyPI package ``libusb-package`` ships that
library; loading it with ``RTLD_GLOBAL`` before importing open3d makes a plain ``pip install`` enough.

``open3d.visualization`` imports its plotly drawing functions at import time, and with them plotly, dash and
IPython: the import of open3d took 0.92-1.03 s with them, 0.31-0.50 s without (3 runs each, 2026-12-02, the last
line of ``python -X importtime -c "from corr_core.open3d_loader import load_open3d; load_open3d()"``), paid by
every worker process that renders. The
project never draws with plotly, so ``load_open3d`` puts a stand-in module there first: the same three functions,
each importing the real module on its first call (a user who calls ``open3d.visualization.draw_plotly`` gets the
real one, a moment later).
"""
from __future__ import annotations

import ctypes
import functools
import importlib
import sys
import types

_PLOTLY_MODULE = "open3d.visualization.draw_plotly"
_PLOTLY_FUNCTIONS = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")   # what open3d.visualization takes


@functools.lru_cache(maxsize=1)
def load_open3d():
    """Return the ``open3d`` module, preloading libusb from ``libusb-package`` when needed."""
    if "open3d" not in sys.modules:
        _defer_plotly_drawing()
    try:
        import open3d  # noqa: F401
        return open3d
    except ImportError as first_error:
        try:
            import libusb_package
        except ImportError:
            raise ImportError(
                "open3d needs libusb-1.0.so.0; install it with `pip install libusb-package`"
            ) from first_error
        ctypes.CDLL(str(libusb_package.get_library_path()), mode=ctypes.RTLD_GLOBAL)
        _defer_plotly_drawing()              # the failed import may have dropped the stand-in with open3d's modules
        import open3d
        return open3d


def _defer_plotly_drawing() -> None:
    """Put the stand-in for ``open3d.visualization.draw_plotly`` in ``sys.modules`` (unless a module is there)."""
    if _PLOTLY_MODULE in sys.modules:
        return
    stand_in = types.ModuleType(_PLOTLY_MODULE, "Stand-in: the real module is imported on the first call.")
    for name in _PLOTLY_FUNCTIONS:
        stand_in.__dict__[name] = _forwarding(name)
    sys.modules[_PLOTLY_MODULE] = stand_in


def _forwarding(name: str):
    """A function that imports the real plotly drawing module (once) and calls its ``name`` function."""
    def call(*args, **kwargs):
        return getattr(_real_plotly_drawing(), name)(*args, **kwargs)
    call.__name__ = call.__qualname__ = name
    return call


@functools.lru_cache(maxsize=1)
def _real_plotly_drawing() -> types.ModuleType:
    """Replace the stand-in with Open3D's real ``draw_plotly`` module and return it. Importing a submodule binds
    its name on the package, where open3d.visualization holds the function of the same name: put that back."""
    del sys.modules[_PLOTLY_MODULE]
    real = importlib.import_module(_PLOTLY_MODULE)
    visualization = sys.modules["open3d.visualization"]
    for name in _PLOTLY_FUNCTIONS:
        setattr(visualization, name, getattr(real, name))
    return real
