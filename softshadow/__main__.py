"""``python -m softshadow``: the ``softshadow`` command (the command line lives in ``softshadow_cli``)."""

from softshadow_cli.main import run

run()
