"""Averaged (complex-envelope) engine: the same diagram, for hours-long temperature scenarios."""
