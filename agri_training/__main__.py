"""The ``agri`` command (``python -m agri_training``): pins numpy's and OpenBLAS's CPU kernels, then runs the CLI.

numpy picks its vectorised loops (``exp``, ``log``, ``arctan2``, ``power``, ``sin``, ...) and OpenBLAS its
kernels (``dot``, ``norm``, matrix products) from the CPU it runs on, at import. An AVX-512 machine then
computes some results one ulp away from an AVX2 machine, a scripted controller's trajectory parts over a
long episode, and a leaderboard entry written on one machine fails verify on the other. Every ``agri``
command therefore caps numpy's dispatch at ``X86_V3`` (AVX2 + FMA: the loops an AVX-512 machine would
otherwise replace) and selects OpenBLAS's Haswell kernels, before numpy is imported; the worker
processes inherit the pins. A variable the user has set is left alone. x86-64 CPUs without AVX2 and FMA
still compute differently (glibc and OpenBLAS pick other code there).

The pins are set only by this entry point and by the test suite (``tests/conftest.py``), never on
``import agri_envs``: a library does not change its user's process. A script that must reproduce entries
exactly sets the same variables (:data:`NUMERIC_PINS`) before it imports numpy.

The entry point also bounds how long torch's idle OpenMP threads spin before they sleep
(:data:`THREAD_SETTINGS`). A training whose gradient updates use both cores (``update_threads: 2``) shares
them with whatever else runs; with libgomp's default wait, a thread that waits at a parallel region for a
peer the OS has descheduled keeps spinning, and PPO's updates on GreenhouseNav ran 20-30 times slower than
on one thread while one other process ran (``benchmarks/bench_update_threads.py``).
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping

#: Environment variables that make numpy and OpenBLAS compute the same bits on every AVX2-or-better x86-64
#: CPU (read when numpy is imported).
NUMERIC_PINS = {
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Haswell",
}


#: Environment variables for torch's OpenMP threads (read when torch is imported): an idle thread spins for
#: 10,000 iterations, then sleeps.
THREAD_SETTINGS = {"GOMP_SPINCOUNT": "10000"}


def settle_idle_threads(environ: MutableMapping[str, str] = os.environ) -> None:
    """Set :data:`THREAD_SETTINGS` where unset (call before torch is imported; afterwards it has no effect)."""
    for key, value in THREAD_SETTINGS.items():
        environ.setdefault(key, value)


def pin_numeric_kernels(environ: MutableMapping[str, str] = os.environ) -> None:
    """Set :data:`NUMERIC_PINS` where unset (call before numpy is imported; afterwards it has no effect).

    Raises:
        RuntimeError: When numpy is already imported in this process (the pins would silently not apply).
    """
    if environ is os.environ and "numpy" in sys.modules:
        raise RuntimeError("pin_numeric_kernels() must run before numpy is imported")
    for key, value in NUMERIC_PINS.items():
        environ.setdefault(key, value)


def main() -> int:
    """Pin the kernels and settle torch's idle threads, then run ``agri`` with the command line's arguments."""
    pin_numeric_kernels()
    settle_idle_threads()
    from agri_training.cli import main as cli_main  # after the pins: this imports numpy

    return cli_main()


if __name__ == "__main__":
    sys.exit(main())
