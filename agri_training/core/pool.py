"""The one way ``agri_training`` runs work on several cores: a process pool, or Ray tasks of one CPU each.

Evaluation (one episode per item) and sweeps (one training run per item) both hand a picklable function
and a list of items to :func:`run_items`, and get each result back through a callback in this process as
it finishes, with the item's index, so that results can be put back in item order. Three backends:

- ``workers=1``: in this process, one item after the other (the reference).
- ``workers=N > 1``: N worker processes started with ``forkserver`` (so no thread or pybullet client of
  the caller is forked) from a server that imported the ``preload`` modules once. At most
  ``in_flight_per_worker * N`` items are submitted at a time, in order. If a worker dies (a crash, not
  an exception), the items in flight get ``lost(index, message)`` as their result and a fresh pool runs
  the rest.
- ``ray=ADDRESS``: Ray tasks of one CPU each. ``"local"`` starts a private Ray instance for this call and
  shuts it down at the end; ``"auto"`` joins the cluster started here with ``ray start``; anything else is
  a cluster address (``HOST:PORT`` or ``ray://HOST:PORT``). Ray is the optional ``ray`` extra.

Workers and Ray tasks limit torch to one thread, so N workers use N cores, not N^2. Functions report
their own failures in their results; an exception raised by ``on_done`` (the caller's verdict on a failed
item) stops the run and cancels what is still pending.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

RAY_EXTRA_HINT = 'pip install -e ".[ray]"'

Item = TypeVar("Item")
Result = TypeVar("Result")


def default_workers() -> int:
    """The number of cores this process may use (the ``--workers`` default)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def check_workers(workers: int | None) -> None:
    """Raise ``ValueError`` unless ``workers`` is None or an int >= 1."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")


def limit_torch_threads() -> None:
    """One intra-op thread for torch, when torch is loaded, so that parallel workers do not oversubscribe."""
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def run_items(
    fn: Callable[[Item], Result],
    items: Sequence[Item],
    on_done: Callable[[int, Result], None],
    workers: int | None = None,
    ray: str | None = None,
    preload: Sequence[str] = (),
    lost: Callable[[int, str], Result] | None = None,
    in_flight_per_worker: int = 1,
) -> None:
    """Run ``fn`` on every item, calling ``on_done(index, result)`` here as each finishes.

    Args:
        fn: A module-level (picklable) function.
        items: Its arguments.
        on_done: Called in this process in completion order.
        workers: Worker processes (None: :func:`default_workers`; 1: in this process). With ``ray``, the
            CPUs of a ``"local"`` Ray instance (None: all).
        ray: None (local workers), ``"local"``, ``"auto"`` or a Ray cluster address.
        preload: Modules the forkserver imports once for all workers.
        lost: The result of an item whose worker process died (default: re-raise the pool's error).
        in_flight_per_worker: Items submitted ahead per worker (more keeps workers busy; fewer loses less
            when one dies).

    Raises:
        ValueError: For a bad ``workers``, or ``ray`` without the ``ray`` extra.
    """
    check_workers(workers)
    if not items:
        return
    if ray is not None:
        _run_ray(fn, items, on_done, ray, workers, lost)
        return
    n = min(workers if workers is not None else default_workers(), len(items))
    if n == 1:
        for i, item in enumerate(items):
            on_done(i, fn(item))
        return
    _run_pool(fn, items, on_done, n, preload, lost, in_flight_per_worker)


def _pool_context(preload: Sequence[str]) -> Any:
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(list(preload))
    return ctx


def _run_pool(
    fn: Callable[[Item], Result],
    items: Sequence[Item],
    on_done: Callable[[int, Result], None],
    n: int,
    preload: Sequence[str],
    lost: Callable[[int, str], Result] | None,
    ahead: int,
) -> None:
    todo = list(range(len(items)))
    while todo:
        context = _pool_context(preload)
        with ProcessPoolExecutor(max_workers=n, mp_context=context, initializer=limit_torch_threads) as pool:
            pending: dict[Future[Result], int] = {}
            broken = False
            try:
                while (todo or pending) and not broken:
                    while todo and len(pending) < ahead * n:
                        i = todo.pop(0)
                        pending[pool.submit(fn, items[i])] = i
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for fut in sorted(done, key=pending.__getitem__):
                        i = pending.pop(fut)
                        try:
                            result = fut.result()
                        except BrokenProcessPool as exc:
                            if lost is None:
                                raise
                            broken = True
                            result = lost(i, f"worker process died ({exc}); this item or one running beside it "
                                             "crashed the process")  # fmt: skip
                        on_done(i, result)
            except BaseException:
                for fut in pending:
                    fut.cancel()
                raise
            if broken and lost is not None:  # the pool is gone with what was in it; a fresh pool runs the rest
                for i in pending.values():
                    on_done(i, lost(i, "the worker pool broke while this item was in flight"))


def import_ray() -> Any:
    """The ``ray`` module, or a ``ValueError`` naming the extra that installs it."""
    try:
        import ray
    except ImportError:
        raise ValueError(f"--ray needs Ray, the optional 'ray' extra: {RAY_EXTRA_HINT}") from None
    return ray


def init_ray(address: str, workers: int | None = None) -> bool:
    """Connect to Ray: ``"local"`` starts a private instance, else join ``address`` (``"auto"`` or a cluster).

    Returns:
        Whether this call started Ray here (the caller then shuts it down with ``ray.shutdown()``).

    Raises:
        ValueError: Without the ``ray`` extra, or for an empty address.
    """
    ray = import_ray()
    if not address:
        raise ValueError("--ray expects 'local', 'auto' or a cluster address HOST:PORT, got an empty string")
    if ray.is_initialized():
        return False
    if address == "local":
        ray.init(
            num_cpus=workers if workers is not None else default_workers(),
            include_dashboard=False,
            logging_level="ERROR",
            log_to_driver=False,
        )
    else:
        ray.init(address=address, logging_level="ERROR")
    return True


def _with_one_thread(fn: Callable[[Item], Result], item: Item) -> Result:
    limit_torch_threads()
    return fn(item)


def _run_ray(
    fn: Callable[[Item], Result],
    items: Sequence[Item],
    on_done: Callable[[int, Result], None],
    address: str,
    workers: int | None,
    lost: Callable[[int, str], Result] | None,
) -> None:
    ray = import_ray()
    started = init_ray(address, workers)
    remaining: list[Any] = []
    try:
        # One CPU per item; Ray reuses its worker processes (and their imports) across items, like the pool.
        task = ray.remote(num_cpus=1, max_retries=0)(_with_one_thread)
        refs = [task.remote(fn, item) for item in items]
        index = {ref: i for i, ref in enumerate(refs)}
        remaining = list(refs)
        while remaining:
            # A timeout, so that Ctrl-C reaches Python between waits (a blocking wait would swallow it).
            done, remaining = ray.wait(remaining, num_returns=1, timeout=1.0)
            for ref in done:
                try:
                    result = ray.get(ref)
                except Exception as exc:  # the worker died or Ray failed the task
                    if lost is None:
                        raise
                    result = lost(index[ref], f"{type(exc).__name__}: {exc}")
                on_done(index[ref], result)
    except BaseException:
        for ref in remaining:
            ray.cancel(ref, force=True)
        raise
    finally:
        if started:
            ray.shutdown()
