"""``python -m armreach_core.cli``: the same as the ``armreach`` command."""

import sys

from armreach_core.cli import main

sys.exit(main())
