"""``python -m softshadow_cli``: the ``softshadow`` command."""

import sys

from .main import main

sys.exit(main())
