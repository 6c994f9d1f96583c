"""Shared 2D simulation: pymunk world, differential-drive bodies, LIDAR and sonar, grid maps, rendering."""
