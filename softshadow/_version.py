"""The version of the softshadow distribution (its one source; pyproject reads it)."""

__version__ = "0.2.0"
