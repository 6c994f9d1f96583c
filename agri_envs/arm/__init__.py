"""Grape harvesting with a 6-DOF arm (Luo 2018)."""
