"""Errors the package raises for users' arguments."""

from __future__ import annotations


class SetupError(ValueError):
    """Arguments that cannot be set up (a chain longer than its floor holds), raised where first knowable.

    That is construction where the arguments alone decide it, else the ``reset`` that draws the scene. A
    ``ValueError`` like every bad argument: callers that run episodes (``agri evaluate``) report it as the
    user's one-line error, not as a failed episode, even when a reset raised it.
    """
