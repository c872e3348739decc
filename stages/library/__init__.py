"""The project's stage functions: importing this package registers them."""
from . import synthetic  # noqa: F401

for _mod in ("alignment", "correspondence", "generators", "report_stages"):
    try:
        __import__(f"{__name__}.{_mod}")
    except ModuleNotFoundError as exc:  # modules still to be written must not break the engine
        if exc.name != f"{__name__}.{_mod}":
            raise
