"""``python -m hope_rs.cli``: the ``hope-rs`` command."""

import sys

from .main import main

sys.exit(main())
