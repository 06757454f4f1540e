"""``python -m explore.cli``: the ``ergo`` command."""

import sys

from explore.cli import main

sys.exit(main())
