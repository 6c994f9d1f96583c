"""Greenhouse row navigation (Harik 2018): ``config``, ``robot``, ``task`` (waypoints), ``greenhouse_nav`` (the env).

Its scenes come from :mod:`agri_envs.scenes`.
"""
