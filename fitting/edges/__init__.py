"""The no-geometry path: shadow edges found and measured in one photo."""
