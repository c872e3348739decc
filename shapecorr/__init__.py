"""The project's stage functions: importing this package registers them."""
from . import alignment, correspondence, generators, synthetic  # noqa: F401
