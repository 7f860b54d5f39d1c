"""Presliding analysis of displacement-driven records (force against an imposed displacement): reversal points,
the Masing and wiping-out checks on the measured data, force-from-displacement identification (Maxwell-slip by
NNLS), derived quantities with uncertainties and what the encoder resolution no longer resolves.
See docs/presliding.md."""
