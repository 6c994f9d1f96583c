"""GreenhouseCoverage: González et al. (2009), the tracked Fitorobot covering every corridor of a greenhouse.

``config``, ``robot``, ``task`` (corridor coverage), ``greenhouse_coverage`` (the env); scenes from
:mod:`agri_envs.scenes`.
"""
