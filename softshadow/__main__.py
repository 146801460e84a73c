"""``python -m softshadow``: the ``softshadow`` command (the command line lives in ``softshadow_cli``)."""

import sys

from softshadow_cli.main import main

sys.exit(main())
