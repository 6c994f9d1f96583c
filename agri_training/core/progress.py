"""Progress of long jobs: a tqdm bar on a terminal, plain lines at a steady pace in a log."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any


class Progress:
    """One progress display over a whole job of evaluation blocks (a policy on one scenario level each).

    On a terminal it is a tqdm bar counting episodes over all blocks (so its remaining time is the ETA of
    the whole job), labelled with the running block (``[k/N] policy on env [level]``) and its success rate
    so far. Elsewhere (CI logs, ``make test`` piped to a file) a bar would print nothing useful, so a plain
    line goes to stdout at least every ``heartbeat_s`` seconds instead: block k of N, episodes done,
    elapsed time and ETA. Nothing is printed per episode.

    Args:
        total_episodes: Episodes of the whole job.
        total_blocks: Blocks of the whole job (1 for a single evaluation).
        enabled: False for no output at all.
        heartbeat_s: Seconds between plain progress lines when stderr is not a terminal.
    """

    def __init__(
        self, total_episodes: int, total_blocks: int = 1, enabled: bool = True, heartbeat_s: float = 20.0
    ) -> None:
        self.total_episodes = total_episodes
        self.total_blocks = total_blocks
        self.block = 0
        self.desc = ""
        self._successes = 0
        self._done = 0
        self._episodes_done = 0
        self._bar: Any = None
        self._heartbeat: Heartbeat | None = None
        if not enabled:
            return
        if sys.stderr.isatty():
            try:
                from tqdm import tqdm

                self._bar = tqdm(total=total_episodes, unit="ep", file=sys.stderr, dynamic_ncols=True)
                return
            except ImportError:
                pass
        self._heartbeat = Heartbeat(self.status_line, heartbeat_s)

    def status_line(self, elapsed: float) -> str:
        """``block k/N (what runs), e/E episodes, elapsed, ETA``: the plain progress line."""
        done, total = self._episodes_done, self.total_episodes
        eta = format_duration(elapsed / done * (total - done)) if done else "?"
        what = f" ({self.desc})" if self.desc else ""
        return (
            f"progress: block {max(self.block, 1)}/{self.total_blocks}{what}, {done}/{total} episodes, "
            f"{format_duration(elapsed)} elapsed, ETA {eta}"
        )

    def start_block(self, desc: str) -> None:
        """Announce the next block."""
        self.block += 1
        self.desc = desc
        self._successes = self._done = 0
        if self._bar is not None:
            self._bar.set_description(f"[{self.block}/{self.total_blocks}] {desc}")

    def episode_done(self, record: Mapping[str, Any]) -> None:
        """Count one finished episode of the current block."""
        self._done += 1
        self._episodes_done += 1
        self._successes += bool(record.get("is_success"))
        if self._bar is not None:
            self._bar.set_postfix_str(f"success {self._successes}/{self._done}", refresh=False)
            self._bar.update(1)

    def advance(self, block: int, desc: str, postfix: str) -> None:
        """Count one finished episode of block ``block`` (1-based), whichever block runs now."""
        self.block, self.desc = block, desc
        self._episodes_done += 1
        if self._bar is not None:
            self._bar.set_description(f"[{block}/{self.total_blocks}] {desc}", refresh=False)
            self._bar.set_postfix_str(postfix, refresh=False)
            self._bar.update(1)

    def skip(self, episodes: int, desc: str) -> None:
        """Count a block that needs no run (e.g. a leaderboard entry that is up to date)."""
        self.start_block(desc)
        self._episodes_done += episodes
        if self._bar is not None:
            self._bar.update(episodes)

    def close(self) -> None:
        """Close the bar, or print the last plain line."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self._heartbeat is not None:
            self._heartbeat.stop()
            self._heartbeat = None


def format_duration(seconds: float) -> str:
    """``1h02m``, ``3m07s`` or ``42s``."""
    s = int(round(seconds))
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class Heartbeat:
    """Prints ``line(elapsed_s)`` to stdout every ``interval_s`` seconds from a daemon thread, and at stop.

    For long jobs whose output is not a terminal: a reader of a log sees that the job lives and when it
    will end, even while one long episode runs.
    """

    def __init__(self, line: Callable[[float], str], interval_s: float) -> None:
        self._line = line
        self._interval = float(interval_s)
        self._t0 = time.perf_counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="progress-heartbeat", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._interval):
            self._print()

    def _print(self) -> None:
        print(self._line(time.perf_counter() - self._t0), flush=True)

    def stop(self) -> None:
        """Stop the thread and print the final line."""
        self._stop.set()
        self._thread.join()
        self._print()

