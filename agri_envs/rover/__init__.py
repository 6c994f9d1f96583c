"""Greenhouse row navigation (Harik 2018): layout generator, rover, waypoint task and the env."""
