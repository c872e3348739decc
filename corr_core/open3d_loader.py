"""Import Open3D on machines without a system libusb.

``import open3d`` links against ``libusb-1.0.so.0``. The PyPI package ``libusb-package`` ships that
library; loading it with ``RTLD_GLOBAL`` before importing open3d makes a plain ``pip install`` enough.
"""
from __future__ import annotations

import ctypes
import functools


@functools.lru_cache(maxsize=1)
def load_open3d():
    """Return the ``open3d`` module, preloading libusb from ``libusb-package`` when needed."""
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
        import open3d
        return open3d
