"""Evaluation: any policy on any env of the package, over seeds, on one core, many, or a Ray cluster.

Above ``core`` and ``learned``: :mod:`.policies` (the request, policies by name or path, the env
arguments), :mod:`.episode` (the one episode loop, for both env kinds), :mod:`.parallel` (episodes as
jobs on the process pool) and :mod:`.evaluate` (results with their statistics).
"""
