"""Evaluation: any policy on any env of the package, over seeds, on one core, many, or a Ray cluster.

Above ``core`` and ``learned``: :mod:`.reference` (a policy in any format, resolved once into a typed
reference, and the env arguments merged with its needs), :mod:`.policies` (the request, the env arguments),
:mod:`.episode` (the one episode loop, for both env kinds), :mod:`.parallel` (episodes as jobs on the process
pool) and :mod:`.evaluate` (results with their statistics).
"""
