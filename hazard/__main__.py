"""``python -m hazard``: the ``hazard`` command line."""

import sys

from hazard.cli import main

sys.exit(main())
