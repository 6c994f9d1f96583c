"""Progress of long jobs when the output is a log, not a terminal (CI, ``make test`` piped to a file)."""

import re
import time

from agri_training.core.progress import Progress, format_duration


def test_plain_lines_keep_coming_while_nothing_finishes(capsys):
    bar = Progress(total_episodes=10, total_blocks=2, heartbeat_s=0.05)  # stderr is captured: not a terminal
    bar.start_block("harik-apf on GreenhouseNav-v2 [default]")
    heard: list[str] = []
    deadline = time.monotonic() + 10.0  # one long episode: no episode ends, yet the log hears from the job
    while len(heard) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
        heard += capsys.readouterr().out.splitlines()
    bar.episode_done({"is_success": True})
    bar.skip(4, "luo-apf on GrapeHarvest-v1 [default]")
    bar.close()
    lines = heard + capsys.readouterr().out.splitlines()
    assert len(heard) >= 3, "no heartbeat while the block ran"
    assert lines[0].startswith("progress: block 1/2 (harik-apf on GreenhouseNav-v2 [default]), 0/10 episodes")
    assert lines[0].endswith("ETA ?")
    assert re.fullmatch(r"progress: block 2/2 \(luo-apf .*\), 5/10 episodes, \d+s elapsed, ETA \d+s", lines[-1])


def test_quiet_prints_nothing(capsys):
    bar = Progress(total_episodes=3, enabled=False, heartbeat_s=0.01)
    time.sleep(0.05)
    bar.close()
    assert capsys.readouterr() == ("", "")


def test_durations_read_like_a_clock():
    assert [format_duration(s) for s in (0.4, 42, 187, 3725)] == ["0s", "42s", "3m07s", "1h02m"]
