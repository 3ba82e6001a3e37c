"""``python -m vibid`` is the ``vibid`` command."""

import sys

from vibid.cli import main

sys.exit(main())
