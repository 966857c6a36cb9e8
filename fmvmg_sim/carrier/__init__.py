"""Carrier-level engine: every cycle of the drive, the diagram compiled into one step function."""
