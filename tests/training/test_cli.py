"""The ``agri`` command line: evaluate writes the documented JSON, errors are clear, report is complete."""

import json

from agri_training.cli import main, parse_env_kwargs


def test_parse_env_kwargs_types():
    assert parse_env_kwargs(["n_rows=4", "growth=0.5", "full_scan=true", "localization=odometry"]) == {
        "n_rows": 4,
        "growth": 0.5,
        "full_scan": True,
        "localization": "odometry",
    }


def test_evaluate_writes_json(tmp_path, capsys):
    out = tmp_path / "ev.json"
    rc = main(
        [
            "evaluate",
            "--env",
            "agri_envs/GreenhouseNav-v2",
            "--policy",
            "harik-apf-gt",
            "--episodes",
            "2",
            "--seed",
            "5",
            "--env-kwargs",
            "n_rows=1",
            "row_length=3",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert rc == 0
    doc = json.loads(out.read_text())
    s = doc["summary"]
    for key in ("success_rate", "collision_rate", "mean_time", "mean_path_length", "min_clearance", "success_rate_ci"):
        assert key in s
    assert [e["seed"] for e in doc["episodes"]] == [5, 6]
    assert doc["privileged"] is True and doc["env_kwargs"]["n_rows"] == 1
    assert len(doc["traces"]) == 1 and len(doc["traces"][0]["data"]["x"]) == doc["episodes"][0]["steps"] + 1
    assert "success_rate" in capsys.readouterr().out


def test_evaluate_errors_are_clear(tmp_path, capsys):
    def evaluate_with(env_kwargs: str) -> int:
        out = str(tmp_path / "x.json")
        env = "agri_envs/GreenhouseNav-v2"
        args = ["--policy", "harik-apf-gt", "--episodes", "1", "--env-kwargs", env_kwargs, "--out", out, "--quiet"]
        return main(["evaluate", "--env", env, *args])

    assert evaluate_with("n_row=2") == 2 and "n_row" in capsys.readouterr().err
    assert evaluate_with("full_scan=false") == 2 and "needs full_scan=True" in capsys.readouterr().err
    rc = main(["evaluate", "--env", "agri_envs/GreenhouseNav-v2", "--policy", "nope", "--out", "x.json"])
    assert rc == 2 and "unknown policy" in capsys.readouterr().err
    # a misspelled env id is named as such first, not reported as the policy driving another env
    rc = main(["evaluate", "--env", "agri_envs/GreenhouseNav-v9", "--policy", "harik-apf-gt", "--out", "x.json"])
    err = capsys.readouterr().err
    assert rc == 2 and "unknown env id 'agri_envs/GreenhouseNav-v9'; known: agri_envs/GrapeHarvest-v1" in err
    assert "drives" not in err


def test_failures_are_counted_by_cause():
    from agri_training.report.rover import failure_cause, failure_lines

    base = {"is_success": False, "collision": False, "episode_time": 150.0, "waypoints_reached": 3, "n_waypoints": 8}
    episodes = [
        {**base, "seed": 0, "collision": True},
        {**base, "seed": 1, "final_position_error": 1.2, "blocked_at_end": 1.0},
        {**base, "seed": 2, "final_position_error": 0.02, "blocked_at_end": 1.0},
        {**base, "seed": 3, "final_position_error": 0.02, "blocked_at_end": 0.0},
        {**base, "seed": 4, "is_success": True},
    ]
    causes = [failure_cause(e) for e in episodes[:4]]
    assert causes[0] == "collision" and causes[1] == "localization lost"
    assert causes[2].startswith("waiting at the safety stop") and "local minimum" in causes[3]
    lines = failure_lines({"episodes": episodes})
    assert lines[0].startswith("Failures: 4 of 5") and sum(ln.startswith("- seed") for ln in lines) == 4
    assert failure_lines({"episodes": episodes[4:]}) == ["No failures."]


def test_evaluate_help_explains_every_option(capsys):
    import pytest

    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "run directory" in text and "ONNX" in text and "without unpickling" in text
    assert "episodes to run (default 20)" in text and "episode i runs seed S+i" in text
    assert "--quiet no progress bar" in text


def test_list_names_every_env_family(capsys):
    assert main(["list"]) == 0
    envs = capsys.readouterr().out.split("scenarios:")[0]
    for env_id in ("GreenhouseNav-v2", "GreenhouseCoverage-v2", "robot_chain_v1", "GrapeHarvest-v1"):
        assert env_id in envs


def test_list_says_how_each_learned_policy_was_trained(capsys):
    assert main(["list"]) == 0
    policies = capsys.readouterr().out.split("policies:")[1]
    assert (
        "dagger-greenhouse-nav [agri_envs/GreenhouseNav-v2] (privileged) (learned: imitation of harik-apf-gt, 8 "
        "DAgger rounds)" in policies
    )
    assert "ppo-chain [robot_chain_v1] (learned: imitation of apoorva-chain, 4 DAgger rounds, then PPO)" in policies
    assert "sac-her-grape-reach [agri_envs/GrapeHarvest-v1] (learned: SAC + HER)" in policies
    assert "(learned, ppo)" not in policies


def test_train_refuses_bad_input_before_writing_the_run_folder(tmp_path, capsys):
    # A misspelled env id used to leave an --out folder holding only config.yaml, after a traceback.
    out = tmp_path / "run"
    rc = main(["train", "--env", "agri_envs/GreenhouseNav-v3", "--algo", "ppo", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "unknown env id 'agri_envs/GreenhouseNav-v3'" in err and "GreenhouseNav-v2" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    # A bad env argument and a bad algorithm argument are refused the same way.
    for hp in (["env_kwargs={n_row: 2}"], ["algo_kwargs={n_stepz: 8}"]):
        rc = main(["train", "--env", "agri_envs/GreenhouseNav-v2", "--algo", "ppo", "--out", str(out), "--quiet",
                   "--hp", *hp])
        assert rc == 2, capsys.readouterr().err
        assert not out.exists()


def test_list_shows_training_teachers_apart_from_the_baselines(capsys):
    assert main(["list"]) == 0
    policies, teachers = capsys.readouterr().out.split("policies:")[1].split("training teachers")
    assert "\n  coverage-half-circle [" not in policies and "\n  gonzalez-deliberative [" in policies
    assert "\n  coverage-half-circle [agri_envs/GreenhouseCoverage-v2] (privileged)" in teachers
    assert "gonzalez-deliberative" not in teachers


def test_a_training_teacher_cannot_enter_the_leaderboard(capsys, tmp_path):
    board = ["--entries", str(tmp_path / "entries"), "--markdown", str(tmp_path / "LEADERBOARD.md")]
    rc = main(["leaderboard", *board, "submit", "--policy", "coverage-half-circle", "--suite", "coverage-almeria"])
    assert rc != 0 and "coverage-half-circle is a training teacher, not a baseline" in capsys.readouterr().err
