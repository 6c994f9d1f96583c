"""`agri report`: one page from committed entries plus fresh runs, with intervals, claims only where the
interval supports them, learning curves with baseline bands, trajectory and failure plots."""

import csv
import json

import yaml

from agri_training import leaderboard as lb
from agri_training.cli import main
from agri_training.core.stats import newcombe_paired_interval
from agri_training.report.page import Row, comparison_table, find_runs, markdown_to_html, zoo_runs

SUITE = {
    "name": "tiny-rover",
    "version": 1,
    "env_id": "agri_envs/GreenhouseNav-v2",
    "scenario": "sim-loop",
    "env_kwargs": {"n_rows": 1, "row_length": 3, "n_people": 0},
    "seeds": {"start": 100000, "episodes": 2},
    "rank_by": [
        {"metric": "success_rate", "higher_is_better": True},
        {"metric": "mean_episode_time", "higher_is_better": False},
    ],
}


def fake_run(root, env_id="agri_envs/GreenhouseNav-v2"):
    run = root / "ppo_nav_1"
    run.mkdir(parents=True)
    (run / "config.yaml").write_text(yaml.safe_dump({"env_id": env_id, "algo": "ppo"}))
    with open(run / "progress.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time/total_timesteps", "eval/success_rate", "rollout/ep_rew_mean"])
        for k in range(1, 11):
            w.writerow([k * 1000, k / 10, k * 3.0])
    return run


def test_report_from_entries_and_fresh_runs(tmp_path, capsys):
    suites, entries, runs, out = tmp_path / "suites", tmp_path / "entries", tmp_path / "runs", tmp_path / "out"
    suites.mkdir()
    (suites / "tiny-rover.yaml").write_text(yaml.safe_dump(SUITE))
    suite = lb.load_suite(suites / "tiny-rover.yaml")
    # one committed entry; the other baselines are missing and get evaluated afresh
    (entry,) = lb.evaluate_entries([(suite, lb.policy_reference("harik-apf-gt"))], progress=False)
    lb.write_entry(entry, entries)
    fake_run(runs)
    rc = main(
        [
            "report",
            "--out",
            str(out),
            "--suites",
            str(suites),
            "--entries",
            str(entries),
            "--runs",
            str(runs),
            "--workers",
            "1",
            "--quiet",
        ]
    )
    assert rc == 0
    md = (out / "report.md").read_text()
    assert "## Who wins where" in md and "`harik-apf-gt` **P**" in md
    assert "1.00 [0.34, 1.00]" in md  # 2 of 2 successes: a Wilson interval, not a point
    fresh = (
        "Evaluated for this report (no current leaderboard entry): `dagger-greenhouse-nav`, "
        "`dagger-greenhouse-nav-robust`, `dagger-greenhouse-nav-robust-shielded`, `dagger-greenhouse-nav-slam`, "
        "`dagger-greenhouse-nav-slam-every-scan-shielded`, `dagger-greenhouse-nav-slam-odometry-shielded`, "
        "`dagger-greenhouse-nav-slam-shielded`, `harik-apf`, `harik-apf-hector-plain`"
    )
    assert fresh in md
    assert sorted(p.name for p in (out / "results" / "tiny-rover").glob("*.json")) == [
        "dagger-greenhouse-nav-robust-shielded.json",
        "dagger-greenhouse-nav-robust.json",
        "dagger-greenhouse-nav-slam-every-scan-shielded.json",
        "dagger-greenhouse-nav-slam-odometry-shielded.json",
        "dagger-greenhouse-nav-slam-shielded.json",
        "dagger-greenhouse-nav-slam.json",
        "dagger-greenhouse-nav.json",
        "harik-apf-hector-plain.json",
        "harik-apf.json",
        "ppo-greenhouse-nav-general-shielded.json",
        "ppo-greenhouse-nav-general.json",
        "ppo-greenhouse-nav.json",
    ]
    assert "GreenhouseNav-v2_greenhouse-default_learning_success.png" not in md  # the fake run has no scene: no bands
    assert "_d_alpha.png" in md and "_trajectory.png" in md
    from PIL import Image

    # a clip of every baseline's success (none fails this suite), MP4 with its poster, loaded only when played
    for policy in ("harik-apf-gt", "harik-apf", "harik-apf-hector-plain"):
        clip = f"clip_tiny-rover_{policy}_success"
        assert f'<video controls preload="none" poster="{clip}.png" src="{clip}.mp4"></video>' in md
        assert (out / f"{clip}.mp4").stat().st_size > 5_000 and Image.open(out / f"{clip}.png").width == 320
    # the learned policy fails this tiny scene (it never saw one): its failure, and no success to show
    assert "clip_tiny-rover_ppo-greenhouse-nav_failure.mp4" in md and "ppo-greenhouse-nav_success" not in md
    for line in md.splitlines():
        if line.startswith("!["):
            assert (out / line.split("(")[1].rstrip(")")).stat().st_size > 10_000
    assert scan_report_tables(md, lb.load_entries(entries) + lb.load_entries(out / "results")) == []
    html = (out / "report.html").read_text()
    assert "<table>" in html and "<img" in html and "<h2 id='who-wins-where'>" in html
    assert '<video controls preload="none"' in html and 'loading="lazy"' in html
    assert json.loads((out / "summary.json").read_text())[0]["suite"] == "tiny-rover"


def test_quick_look_runs_each_episode_once_and_says_it_is_a_smoke_test(tmp_path, monkeypatch):
    from agri_training.report import page

    suites, out = tmp_path / "suites", tmp_path / "out"
    suites.mkdir()
    (suites / "tiny-rover.yaml").write_text(yaml.safe_dump(SUITE))
    replays = []
    real = page._Replay.run

    def counted(self, record, film):
        replays.append((self.policy.name, record["seed"], film))
        return real(self, record, film)

    monkeypatch.setattr(page._Replay, "run", counted)
    args = ["report", "--episodes", "1", "--out", str(out), "--suites", str(suites), "--workers", "1", "--quiet"]
    args += ["--entries", str(tmp_path / "none"), "--runs", str(tmp_path / "none")]
    assert main(args) == 0
    md = (out / "report.md").read_text()
    assert "Smoke test, not results" in md
    # the traces came from the evaluation itself: the only re-run is the lead policy's clip
    assert replays == [("harik-apf", 100000, True)]
    assert "_trajectory.png" in md


def _entry(name, successes, times, kind="baseline"):
    eps = [
        {"seed": 100000 + i, "is_success": s, "episode_time": t}
        for i, (s, t) in enumerate(zip(successes, times, strict=True))
    ]
    return {"policy": {"kind": kind, "name": name}, "levels": [{"episodes": eps}], "privileged": False}


def test_claims_only_where_the_interval_supports_them():
    suite = lb.parse_suite(SUITE)
    fast = _entry("fast", [True] * 20, [50.0 + 0.1 * i for i in range(20)])
    slow = _entry("slow", [True] * 20, [80.0 + 0.1 * i for i in range(20)])
    table, claims = comparison_table([Row(suite, fast, True), Row(suite, slow, True)])
    # 20/20 against 20/20: no claim on success; 30 s faster on every seed: a supported claim on time
    assert claims == [
        "tiny-rover: `fast` beats `slow` on time [s] (-30.0 [-30.0, -30.0]; over the 20 episodes both completed)."
    ]
    assert "+0.00 [-0.16, +0.16]" in table[2]
    near = _entry("near", [True] * 19 + [False], [50.0 + 0.1 * i for i in range(20)])
    _, claims = comparison_table([Row(suite, near, True), Row(suite, fast, True)])
    # nothing on success; time over the 19 episodes both completed
    assert claims == [
        "tiny-rover: `fast` matches `near` on time [s] (+0.0 [+0.0, +0.0]; over the 19 episodes both completed)."
    ]


def test_a_policy_that_fails_more_is_not_said_to_be_faster():
    suite = lb.parse_suite(SUITE)
    # crashes end episodes early: 10/20 successes, every episode 30 s shorter than the 20/20 policy's
    crashing = _entry("crashing", [True, False] * 10, [50.0 + 0.1 * i for i in range(20)])
    steady = _entry("steady", [True] * 20, [80.0 + 0.1 * i for i in range(20)])
    table, claims = comparison_table([Row(suite, crashing, True), Row(suite, steady, True)])
    assert len(claims) == 1 and claims[0].startswith("tiny-rover: `crashing` is worse than `steady` on success")
    assert "beats" not in claims[0] and "time" not in claims[0]
    # the table shows the time difference over the 10 episodes both completed, without a verdict
    assert "not claimed: X succeeds less often" in table[2] and "over the 10 episodes both completed" in table[2]
    assert "**X better**" not in table[2]


def test_secondary_metrics_are_compared_over_episodes_both_completed():
    suite = lb.parse_suite(SUITE)
    # fails 18 of 20 (early, hence "fast"): only 2 episodes both completed, too few to compare times
    failing = _entry("failing", [True, True] + [False] * 18, [10.0] * 20, kind="learned")
    steady = _entry("steady", [True] * 20, [80.0 + 0.1 * i for i in range(20)])
    table, claims = comparison_table([Row(suite, failing, True), Row(suite, steady, True)])
    assert "n/a: both completed 2 of 20 episodes" in table[2] and "better" not in table[2].replace("P(X better)", "")
    assert "time" not in claims[0]
    # the same time on the shared successes: a match over them, however short the failures were
    mixed = _entry("mixed", [True] * 15 + [False] * 5, [80.0 + 0.1 * i for i in range(15)] + [5.0] * 5)
    table, claims = comparison_table([Row(suite, mixed, True), Row(suite, steady, True)])
    assert "match over the 15 episodes both completed" in table[2]


def _success_contradicts(table_line, success, parts=None):
    """Why a paired-table row's verdicts contradict the success rates (or None).

    ``parts``: per policy, each episode's campaign part (first run or later run) in a campaign suite, whose
    columns of one part compare the episodes of that part.
    """
    cells = [c.strip() for c in table_line.strip().strip("|").split("|")]
    x, y = (n.strip("` ") for n in cells[0].split(" vs "))
    sx, sy = success[x], success[y]
    lo, hi = newcombe_paired_interval(sx, sy)
    completed = [a and b for a, b in zip(sx, sy, strict=True)]
    counts = {sum(completed)}
    if parts:
        counts |= {sum(c for c, p in zip(completed, parts[x], strict=True) if p == part) for part in set(parts[x])}
    for cell in cells[2:]:  # the secondary metrics
        for word, contradicted in (("**X better**", hi < 0), ("**X worse**", lo > 0)):
            if word not in cell:
                continue
            if contradicted:
                return f"{cells[0]}: {word} though the success rates say otherwise ({sum(sx)} vs {sum(sy)})"
            if "episodes both completed" in cell:
                both = int(cell.split("over the ")[1].split(" episodes both completed")[0])
                if both not in counts:
                    return f"{cells[0]}: compared over other episodes than the {sorted(counts)} both completed"
                if both < lb.MIN_COMPLETED_PAIRS:
                    return f"{cells[0]}: compared over {both} episodes"
    return None


def scan_report_tables(md, entries):
    """Every paired-table row of a report page checked against the success rates of its entries."""
    suite = None
    problems = []
    for line in md.splitlines():
        if line.startswith("#### "):
            suite = line[5:].split(" (v")[0]
        elif line.startswith("| `") and " vs `" in line.split("|")[1]:
            mine = [e for e in entries if e["suite"]["name"] == suite]
            success = {e["policy"]["name"]: lb.episode_values(e, "success_rate")[0] for e in mine}
            parts = {
                e["policy"]["name"]: [bool(r.get("campaign_run")) for lv in e["levels"] for r in lv["episodes"]]
                for e in mine
            }
            problem = _success_contradicts(line, success, parts)
            if problem:
                problems.append(f"{suite}: {problem}")
    return problems


def test_committed_entries_make_no_claim_their_success_rates_contradict():
    suites, entries = lb.load_suites(lb.SUITES_DIR), lb.load_entries(lb.ENTRIES_DIR)
    md = []
    for suite in suites:
        group = [Row(suite, e, True) for e in entries if e["suite"]["name"] == suite.name]
        if len(group) > 1:
            md += [f"#### {suite.name} (v{suite.version})", *comparison_table(group)[0]]
    assert sum(line.startswith("| `") for line in md) >= 10
    assert scan_report_tables("\n".join(md), entries) == []
    # e.g. ppo-greenhouse-nav (0.10 on greenhouse-corridor) is not "better" on time or path length there
    corridor = "\n".join(md).split("#### greenhouse-corridor")[1].split("####")[0]
    failing = [line for line in corridor.splitlines() if line.startswith("| `ppo-greenhouse-nav` vs")]
    assert failing and not any("**X better**" in line for line in failing)
    # while ppo-greenhouse-nav-general, as successful as harik-apf-gt there, is faster over the same episodes
    general = [line for line in corridor.splitlines() if line.startswith("| `ppo-greenhouse-nav-general` vs `harik")]
    assert general and all("**X better**" in line for line in general)


def test_learned_policies_are_compared_with_every_baseline():
    suite = lb.parse_suite(SUITE)
    rows = [
        Row(suite, _entry("a", [True] * 20, [1.0] * 20), True),
        Row(suite, _entry("b", [True] * 20, [1.0] * 20), True),
        Row(suite, _entry("ppo", [True] * 20, [1.0] * 20, kind="learned"), True),
    ]
    table, _ = comparison_table(rows)
    assert [r.split("|")[1].strip() for r in table[2:]] == ["`ppo` vs `a`", "`ppo` vs `b`"]


def test_find_runs(tmp_path):
    fake_run(tmp_path)
    (tmp_path / "no_config").mkdir()
    (tmp_path / "no_config" / "progress.csv").write_text("a,b\n1,2\n")
    (run,) = find_runs(tmp_path)
    assert run["env_id"] == "agri_envs/GreenhouseNav-v2" and len(run["rows"]) == 10
    assert find_runs(tmp_path / "missing") == []


def test_markdown_to_html_escapes_and_links():
    html = markdown_to_html("# T\n\nsee [x](#y) and `a<b>`\n\n- one\n  more\n", "t")
    assert '<a href="#y">x</a>' in html and "<code>a&lt;b&gt;</code>" in html and "<li>one more</li>" in html


def test_progress_names_the_block_and_prints_no_rows_per_episode(capsys, monkeypatch):
    import sys

    from agri_training.evaluation.evaluate import evaluate_many
    from agri_training.evaluation.policies import EvalRequest

    kwargs = {"n_rows": 1, "row_length": 3, "n_people": 0}
    requests = [
        EvalRequest("agri_envs/GreenhouseNav-v2", "harik-apf-gt", 2, 100000, env_kwargs=kwargs, label="a"),
        EvalRequest("agri_envs/GreenhouseNav-v2", "harik-apf-gt", 2, 100002, env_kwargs=kwargs, label="b"),
    ]
    evaluate_many(requests[:1], progress=True, workers=1)
    assert capsys.readouterr().err == ""  # not a terminal (a CI log): no bar at all
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    docs = evaluate_many(requests, progress=True, workers=1)
    err = capsys.readouterr().err
    assert "[1/2] harik-apf-gt on GreenhouseNav-v2 [a]" in err and "[2/2] harik-apf-gt on GreenhouseNav-v2 [b]" in err
    assert "4/4" in err and "success 2/2 of 2" in err  # one bar over the whole run (its ETA), per-block counts
    assert "seed" not in err and [d["label"] for d in docs] == ["a", "b"]


def test_learning_curves_only_against_baselines_of_the_same_task_and_scene(tmp_path):
    from agri_training.report.page import curve_suite, learning_curves

    suites = {s.name: s for s in lb.load_suites(lb.SUITES_DIR)}
    zoo = {run["name"]: run for run in zoo_runs()}
    # the reach learner trained on one cluster: not the table2 scenes (2-5 clusters, return home)
    assert curve_suite(zoo["zoo/sac-her-grape-reach"], list(suites.values())).name == "grape-reach"
    # the rover trained on the default scene (people walking): greenhouse-default, not sim-loop
    assert curve_suite(zoo["zoo/ppo-greenhouse-nav"], list(suites.values())).name == "greenhouse-default"
    entries = lb.load_entries(lb.ENTRIES_DIR)
    nav = [Row(s, e, True) for s in suites.values() for e in entries if e["suite"]["name"] == s.name]
    md = "\n".join(learning_curves("agri_envs/GreenhouseNav-v2", [zoo["zoo/ppo-greenhouse-nav"]], nav, tmp_path))
    assert "GreenhouseNav-v2_greenhouse-default_learning_success.png" in md and "sim-loop" not in md
    # a run on a scene no suite has: drawn alone, with a note
    other = {**zoo["zoo/ppo-greenhouse-nav"], "config": {"env_kwargs": {"n_rows": 7}}, "name": "mine"}
    md = "\n".join(learning_curves("agri_envs/GreenhouseNav-v2", [other], nav, tmp_path))
    assert "no suite has this run's env arguments" in md and "_own-scene_learning_success.png" in md


def test_failure_labels_of_learned_policies_use_no_controller_words():
    from agri_training.report import arm, rover

    stuck = {"is_success": False, "collision": False, "blocked_at_end": False}
    assert "APF" in rover.failure_cause(stuck) and "APF" not in rover.failure_cause(stuck, learned=True)
    blocked = {**stuck, "blocked_at_end": True}
    assert "safety stop" not in rover.failure_cause(blocked, learned=True)
    assert arm.failure_cause(stuck) == "plan incomplete" and "plan" not in arm.failure_cause(stuck, learned=True)
    lines = rover.failure_lines({"policy_kind": "learned", "episodes": [{**stuck, "seed": 1}]})
    assert not any("APF" in line for line in lines)


def test_every_env_section_has_a_description_line():
    from agri_training.report.page import _env_blurb

    for env_id in ("robot_chain_v1", "agri_envs/GreenhouseNav-v2", "agri_envs/GrapeHarvest-v1"):
        assert len(_env_blurb(env_id)) > 40, env_id


def test_grape_figures_name_their_policy_and_the_scene_is_drawn_once(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.axes import Axes

    from agri_training.report.arm import plot_planned_path

    titles = []
    set_title = Axes.set_title
    monkeypatch.setattr(
        Axes, "set_title", lambda self, text, *a, **k: titles.append(text) or set_title(self, text, *a, **k)
    )
    suite = lb.load_suite(lb.SUITES_DIR / "grape-table2.yaml")
    files = []
    for policy in ("luo-apf", "luo-apf-attract-only"):
        result = {
            "env_id": suite.env_id,
            "env_kwargs": dict(suite.env_kwargs),
            "policy": policy,
            "scenario": "table2",
            "label": "grape-table2",
        }
        files.append(plot_planned_path(result, 100000, tmp_path, f"grape_{policy}"))
    assert titles[0].startswith("luo-apf on grape-table2") and titles[2].startswith("luo-apf-attract-only on")
    assert "the scene at reset" in titles[1] and len(titles) == 3  # one scene picture for both policies
    assert files[0][1] == files[1][1] and files[0][0] != files[1][0]
    ee = {"control": "ee", "max_ee_step": 0.04, "max_ee_rotation": 0.2}
    learned = {**result, "policy": "sac-her-grape-vine", "env_kwargs": {**suite.env_kwargs, **ee}}
    assert plot_planned_path(learned, 100000, tmp_path, "grape_learned") is None  # it acts step by step: no plan


def test_learning_curves_across_seeds_show_the_mean_and_an_interval(tmp_path):
    from agri_training.report.page import across_seeds, learning_curves, seed_groups

    runs = []
    for seed in range(3):
        config = {
            "env_id": "agri_envs/GreenhouseNav-v2",
            "env_kwargs": {"n_rows": 7},
            "seed": seed,
            "eval_episodes": 10,
        }
        rows = [{"timesteps": str(k * 100), "success_rate": str(min(1.0, k * 0.1 + 0.1 * seed))} for k in range(6)]
        runs.append({"env_id": config["env_id"], "name": f"sweep/seed{seed}", "rows": rows, "config": config})
    other = {**runs[0], "name": "other", "config": {**runs[0]["config"], "algo": "sac"}}
    curves = [(r, ("success_rate", "success rate", [float(x["timesteps"]) for x in r["rows"]],
                   [float(x["success_rate"]) for x in r["rows"]])) for r in [*runs, other]]  # fmt: skip
    groups = seed_groups(curves)
    assert [len(g) for g in groups] == [3, 1]
    xs, mean, lo, hi = across_seeds([c for _, c in groups[0]])
    assert xs[:2] == [0.0, 100.0] and abs(mean[1] - 0.2) < 1e-9 and lo[1] < mean[1] < hi[1]
    md = "\n".join(learning_curves("agri_envs/GreenhouseNav-v2", runs, [], tmp_path))
    assert "_own-scene_learning_success.png" in md
