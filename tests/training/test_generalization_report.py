"""The report's generalization section: training distribution beside the suites, gap, worst episodes, seeds."""

import hashlib
import json

import pytest

from agri_training import leaderboard as lb
from agri_training.core.stats import newcombe_interval
from agri_training.report.generalization import (
    episode_progress,
    generalization_section,
    scenes_verdict,
    seed_spread_section,
)

NAV = "agri_envs/GreenhouseNav-v2"


def _records(n, successes, n_waypoints=8, seed=0):
    out = []
    for i in range(n):
        ok = i < successes
        out.append(
            {
                "seed": seed + i,
                "return": 100.0 + i if ok else -20.0 - i,
                "is_success": ok,
                "collision": not ok,
                "waypoints_reached": n_waypoints if ok else i % n_waypoints,
                "n_waypoints": n_waypoints,
            }
        )
    return out


@pytest.fixture()
def zoo(tmp_path):
    folder = tmp_path / "ppo-x"
    folder.mkdir()
    (folder / "policy.pt").write_bytes(b"chosen weights")
    sha = hashlib.sha256(b"chosen weights").hexdigest()

    def candidate(run, seed, path, success, sha256):
        return {"path": path, "run": run, "seed": seed, "timesteps": 1000, "weights_sha256": sha256,
                "summary": {"episodes": 10, "success_rate": success, "collision_rate": 1 - success,
                            "mean_return": 50.0, "mean_return_ci": [40.0, 60.0]}}  # fmt: skip

    doc = {
        "seeds": {"start": 20000, "episodes": 10},
        "candidates": [
            candidate("runs/a", 0, "runs/a", 0.8, sha),
            candidate("runs/b", 1, "runs/b/checkpoints/step_1000", 0.6, "other"),
            candidate("runs/b", 1, "runs/b", 0.5, "other2"),
        ],
        "best_per_run": {"runs/a": "runs/a", "runs/b": "runs/b/checkpoints/step_1000"},
        "chosen": "runs/a",
        "episodes": {"runs/a": _records(10, 8, seed=20000), "runs/b/checkpoints/step_1000": _records(10, 6)},
    }
    (folder / "validation.json").write_text(json.dumps(doc))
    config = {"env_id": NAV, "env_kwargs": {}, "train_env_kwargs": {"scene_distribution": "training"}}
    (folder / "config.yaml").write_text(json.dumps(config))
    return tmp_path


def _entry(name, records):
    return {"policy": {"kind": "learned", "name": name}, "levels": [{"episodes": records}]}


def test_section_puts_training_and_suites_side_by_side(zoo):
    loop, general = lb.find_suite("greenhouse-sim-loop"), lb.find_suite("greenhouse-generalization")
    entries = [(loop, _entry("ppo-x", _records(20, 15))), (general, _entry("ppo-x", _records(20, 10)))]
    text = "\n".join(generalization_section(NAV, entries, zoo_dir=zoo))
    lines = {line.split(" | ")[0]: line for line in text.splitlines() if line.startswith("| ")}
    train = lines["| training distribution (seeds 20000-20009)"]
    assert "| inside | 10 | 0.80 [" in train and "| — |" in train
    lo, hi = newcombe_interval(15, 20, 8, 10)
    assert f"| -0.05 [{lo:+.2f}, {hi:+.2f}] |" in lines[f"| greenhouse-sim-loop (v{loop.version})"]
    gen = lines[f"| greenhouse-generalization (v{general.version})"]
    assert "outside: n_rows=5 outside 2..4; row_length=9.0 outside [4, 8]; corridor_width=1.6" in gen
    # worst 10 % of 20 episodes = the 2 worst: progress (i % 8) / 8 of the failures 10..19 -> 0/8 and 1/8 ...
    worst = sorted((i % 8) / 8 for i in range(10, 20))[:2]
    assert f"| {sum(worst) / 2:.2f} [" in gen
    assert "ranges from 0.60 to 0.80" in text and "| 0 (shipped) | `a` |" in text and "| 1 | `b` | 1000 (2) |" in text
    assert "chose other weights" not in text


def test_section_warns_when_the_shipped_weights_are_not_the_chosen_ones(zoo):
    (zoo / "ppo-x" / "policy.pt").write_bytes(b"retrained")
    loop = lb.find_suite("greenhouse-sim-loop")
    text = "\n".join(generalization_section(NAV, [(loop, _entry("ppo-x", _records(20, 20)))], zoo_dir=zoo))
    assert "chose other weights than the ones shipped" in text


def test_without_validation_the_suites_still_show(tmp_path):
    loop = lb.find_suite("greenhouse-sim-loop")
    text = "\n".join(generalization_section(NAV, [(loop, _entry("ppo-y", _records(20, 20)))], zoo_dir=tmp_path))
    assert "No validation on its training distribution recorded" in text and "| — | 20 | 1.00 [" in text
    # a policy that did not train on the distribution (no config naming it): no inside / outside verdicts
    assert "trained on fixed scenes" in text and "| inside |" not in text and "| outside" not in text
    none = generalization_section(NAV, [], zoo_dir=tmp_path)
    assert none == ["No learned policy of this env has leaderboard entries."]



def test_an_env_without_a_training_distribution_still_shows_each_recipes_seeds(zoo):
    table2, loop = lb.find_suite("grape-table2"), lb.find_suite("greenhouse-sim-loop")
    entries = [(table2, _entry("ppo-x", _records(20, 20))), (table2, _entry("ppo-y", _records(20, 20)))]
    entries.append((loop, _entry("ppo-z", _records(20, 20))))  # another env's: left out
    (zoo / "ppo-z").mkdir()
    (zoo / "ppo-z" / "validation.json").write_text((zoo / "ppo-x" / "validation.json").read_text())
    text = "\n".join(seed_spread_section(table2.env_id, entries, zoo_dir=zoo))
    assert "#### `ppo-x`" in text and "10 validation episodes per candidate (seeds 20000-20009; the defaults)" in text
    assert "| 0 (shipped) | `a` |" in text and "| 1 | `b` | 1000 (2) |" in text and "ranges from 0.60 to 0.80" in text
    assert "ppo-y" not in text and "ppo-z" not in text and "chose other weights" not in text  # no document; other env
    (zoo / "ppo-x" / "policy.pt").write_bytes(b"retrained")
    assert "chose other weights than the ones shipped" in "\n".join(seed_spread_section(table2.env_id, entries, zoo))
    alone = seed_spread_section(table2.env_id, entries[1:], zoo_dir=zoo)
    assert alone == ["No learned policy of this env has a validation document."]

def test_progress_and_scene_verdicts():
    assert episode_progress({"coverage": 0.4, "is_success": False}) == 0.4
    assert episode_progress({"waypoints_reached": 3, "n_waypoints": 4, "is_success": False}) == 0.75
    assert episode_progress({"is_success": True}) == 1.0
    assert scenes_verdict(lb.find_suite("greenhouse-plant-development")) == "inside"
    assert scenes_verdict(lb.find_suite("greenhouse-repeatability")) == "outside: mission_cycles=10 outside 1..3"
    assert scenes_verdict(lb.find_suite("grape-table2")) == "(no training distribution)"
