"""The bottom layer of ``agri_training``: leaves that import nothing from the layers above.

Documents (typed dicts, JSON conversion), statistics, progress displays, the one process pool (local
workers or Ray) and the YAML reader; envs of both kinds come from :func:`agri_envs.make`. Layers, bottom to top, each
importing only from those below it: ``core`` -> ``learned`` -> ``evaluation`` -> ``leaderboard`` ->
``report`` -> the verbs ``train``, ``sweep``, ``tune`` -> ``cli``.
"""
