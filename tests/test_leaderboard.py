"""Pinned suites, leaderboard entries, verify (passes as committed, fails on an altered number or a stale
LEADERBOARD.md) and the generated page."""

from pathlib import Path

import pytest
import yaml

from agri_training import leaderboard as lb

SUITE = {
    "name": "tiny-rover",
    "version": 1,
    "env_id": "agri_envs/GreenhouseNav-v1",
    "description": "two short rows",
    "env_kwargs": {"n_rows": 1, "row_length": 3, "n_people": 0},
    "seeds": {"start": 100000, "episodes": 2},
    "rank_by": [
        {"metric": "success_rate", "higher_is_better": True},
        {"metric": "mean_episode_time", "higher_is_better": False},
    ],
}


def write_suite(folder: Path, doc: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{doc['name']}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_committed_suites_are_valid_and_held_out():
    suites = lb.load_suites()
    assert {s.env_id for s in suites} >= {"agri_envs/GreenhouseNav-v1", "agri_envs/GrapeHarvest-v1"}
    for s in suites:
        assert s.seed_start >= lb.HELD_OUT_SEED and s.episodes >= lb.MIN_EPISODES
        assert len(s.sha256) == 64 and s.rank_by


def test_suite_loader(tmp_path):
    suite = lb.load_suite(write_suite(tmp_path, SUITE))
    assert suite.seeds == [100000, 100001] and suite.env_version == "v1"
    assert suite.levels() == [("tiny-rover", SUITE["env_kwargs"])]
    swept = lb.parse_suite({**SUITE, "sweep": {"parameter": "growth", "values": [0.0, 1.0]}})
    assert [label for label, _ in swept.levels()] == ["tiny-rover growth=0.0", "tiny-rover growth=1.0"]
    assert swept.levels()[1][1]["growth"] == 1.0


@pytest.mark.parametrize(
    "change,message",
    [
        ({"seeds": {"start": 99999, "episodes": 2}}, "held out"),
        ({"seeds": {"start": 100000}}, "seeds must"),
        ({"version": 0}, "version"),
        ({"rank_by": []}, "rank_by"),
        ({"episodes": 3}, "unknown suite keys"),
        ({"name": "Bad Name"}, "name"),
        ({"sweep": {"parameter": "n_rows", "values": [1]}}, "sweep"),
        ({"rank_by": [{"metric": "success rate"}]}, "rank_by metric"),
    ],
)
def test_bad_suites_are_rejected(change, message):
    with pytest.raises(ValueError, match=message):
        lb.parse_suite({**SUITE, **change})


def test_suite_name_must_match_file(tmp_path):
    path = write_suite(tmp_path, SUITE)
    path.rename(tmp_path / "other.yaml")
    with pytest.raises(ValueError, match="match the file name"):
        lb.load_suite(tmp_path / "other.yaml")
    with pytest.raises(ValueError, match="unknown suite"):
        lb.find_suite("nope", tmp_path)
