"""``python -m stages``: see ``python -m stages --help``."""
import sys

from .cli import main

sys.exit(main())
