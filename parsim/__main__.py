"""``python -m parsim``: the ``parsim`` command."""

import sys

from parsim.cli import main

sys.exit(main())
