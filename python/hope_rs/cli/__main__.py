"""``python -m hope_rs.cli``: the ``hope-rs`` command."""

import sys

from .commands import main

sys.exit(main())
