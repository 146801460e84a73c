"""The rule book: what the fit's evidence says about its values (reliable, identifiable, warnings)."""
