"""``python -m softshadow_cli``: the ``softshadow`` command."""


from .main import run

run()
