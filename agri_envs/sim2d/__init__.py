"""Shared 2D simulation below every 2D env: the engine and the pure algorithms the envs share.

``world`` (pymunk), ``diff_drive`` (bodies and their limits), ``sensors`` and ``raycast`` (LIDAR, sonar),
``odometry`` (wheel odometry, track encoders, compass), ``crowd`` (walking people), ``geometry`` and
``gridmap`` (scenes and occupancy grids), ``astar`` (grid A*), ``polyline`` (paths by arc length),
``render`` (the top-down renderer) and ``view`` (each env's render mode, renderer and ``close()``).
Nothing here imports an env or Gymnasium.
"""
