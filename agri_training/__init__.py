"""Training, evaluation reports and the leaderboard for agri_envs (needs the ``train``/``report`` extras).

The Python API for training scripts, importable from here: :func:`~agri_training.api.load_policy` (any policy
format, built on an env) and :func:`~agri_training.api.evaluate_suite` (a policy on a pinned suite, returning
the document a leaderboard entry holds). They are imported on first use, so that ``python -m agri_training``
pins numpy's kernels before anything imports numpy.
"""

from __future__ import annotations

from typing import Any

__all__ = ["evaluate_suite", "load_policy"]


def __getattr__(name: str) -> Any:
    """``agri_training.load_policy`` and ``agri_training.evaluate_suite``, imported on first use."""
    if name in __all__:
        from agri_training import api

        return getattr(api, name)
    raise AttributeError(f"module 'agri_training' has no attribute {name!r}")
