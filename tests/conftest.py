"""Test set-up: headless SDL, and the numeric kernel pins and thread settings of the ``agri`` command.

Tests compare against committed leaderboard entries, which ``agri`` computes with numpy's and OpenBLAS's
CPU dispatch pinned (:mod:`agri_training.__main__`); the tests run under the same pins. The library itself
never sets environment variables.
"""

import os

from agri_training.__main__ import pin_numeric_kernels, settle_idle_threads

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
pin_numeric_kernels()
settle_idle_threads()
