"""Validation campaign: encounters flown twice, risk ratios (DESIGN section 13)."""
