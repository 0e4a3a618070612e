"""``python -m hazard``: the ``hazard`` command line."""

import sys

from .cli import main

sys.exit(main())
