"""``python -m localize.grade SUBMISSIONS --out grades/``: see :mod:`localize.grade.cli`."""

import sys

from .cli import main

sys.exit(main())
