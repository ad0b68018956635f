"""Loaders for external data sets (recorded pedestrian tracks)."""
