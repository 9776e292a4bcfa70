"""``python -m pinobs.cli``: the ``pinobs`` command."""

import sys

from pinobs.cli import main

sys.exit(main())
