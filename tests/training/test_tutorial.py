"""The commands of docs/bring-your-own-policy.md run as written, with fewer steps and a tiny suite."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import yaml

import agri_training.leaderboard as lb
from agri_training.cli import main

PAGE = Path(__file__).resolve().parents[2] / "docs" / "bring-your-own-policy.md"
TINY = {"n_rows": 1, "row_length": 3.0, "n_people": 0, "max_episode_steps": 30, "localization": "ground_truth"}


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", PAGE.read_text(), flags=re.DOTALL)


def test_the_tutorial_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    suites = tmp_path / "suites"
    suites.mkdir()
    doc = {"name": "tiny-nav", "version": 1, "env_id": "agri_envs/GreenhouseNav-v2", "env_kwargs": TINY,
           "seeds": {"start": 100000, "episodes": 2}, "fewer_episodes": "a test", "traces": 0,
           "rank_by": [{"metric": "success_rate"}]}  # fmt: skip
    (suites / "tiny-nav.yaml").write_text(yaml.safe_dump(doc))
    code = "\n".join(_blocks("python"))
    for old, new in (("TIMESTEPS = 200_000", "TIMESTEPS = 64"), ("n_steps=256", "n_steps=64"),
                     ('"greenhouse-corridor"', "tiny_suite")):  # fmt: skip
        assert old in code
        code = code.replace(old, new)
    exec(compile(code, str(PAGE), "exec"), {"tiny_suite": lb.load_suite(suites / "tiny-nav.yaml")})
    assert (tmp_path / "nav_ppo.zip").is_file() and (tmp_path / "nav_actor.onnx").is_file()
    (commands,) = _blocks("bash")
    places = f"--suites {suites} --entries {tmp_path / 'entries'} --markdown {tmp_path / 'LB.md'}"
    for line in commands.strip().splitlines():
        line = line.replace("--episodes 5", "--episodes 1 --env-kwargs max_episode_steps=30")
        line = line.replace("agri leaderboard", f"agri leaderboard {places}").replace("greenhouse-corridor", "tiny-nav")
        line = line.replace("leaderboard/entries/", f"{tmp_path / 'entries'}/")
        assert main(shlex.split(line)[1:]) == 0, capsys.readouterr().err
    assert "verified 1 entries exactly" in capsys.readouterr().out
    (entry,) = lb.load_entries(tmp_path / "entries")
    assert entry["policy"]["kind"] == "onnx" and entry["policy"]["name"] == "my-ppo-actor"
    assert entry["policy"]["sidecar_sha256"] and entry["levels"][0]["env_kwargs"] == TINY
