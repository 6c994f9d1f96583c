"""Pinned suites, leaderboard entries, verify (passes as committed, fails on an altered number or a stale
LEADERBOARD.md) and the generated page."""

import json
import shutil
from pathlib import Path

import pytest
import yaml

from agri_training import leaderboard as lb

SUITE = {
    "name": "tiny-rover",
    "version": 1,
    "env_id": "agri_envs/GreenhouseNav-v2",
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
    assert {s.env_id for s in suites} >= {"agri_envs/GreenhouseNav-v2", "agri_envs/GrapeHarvest-v1"}
    for s in suites:
        assert s.seed_start >= lb.HELD_OUT_SEED
        # per level, or the suite says why not (docs/leaderboard.md)
        assert s.episodes >= lb.MIN_EPISODES or len(s.fewer_episodes) > 20, s.name
        assert len(s.sha256) == 64 and s.rank_by


def test_suite_loader(tmp_path):
    suite = lb.load_suite(write_suite(tmp_path, SUITE))
    assert suite.seeds == [100000, 100001] and suite.env_version == "v2"
    assert suite.levels() == [("tiny-rover", SUITE["env_kwargs"])]
    swept = lb.parse_suite({**SUITE, "sweep": {"parameter": "growth", "values": [0.0, 1.0]}})
    assert [label for label, _ in swept.levels()] == ["tiny-rover growth=0.0", "tiny-rover growth=1.0"]
    assert swept.levels()[1][1]["growth"] == 1.0
    # several arguments changed together, one row per level (a longer chain needs a bigger office)
    both = lb.parse_suite(
        {**SUITE, "stress": "plants", "sweep": {"parameters": ["growth", "n_trees"], "values": [[0.0, 0], [1.0, 4]]}}
    )
    labels = ["tiny-rover growth=0.0 n_trees=0", "tiny-rover growth=1.0 n_trees=4"]
    assert [label for label, _ in both.levels()] == labels
    assert both.levels()[1][1] == {**SUITE["env_kwargs"], "growth": 1.0, "n_trees": 4}
    assert both.stress == "plants" and both.level_values() == ["growth=0.0 n_trees=0", "growth=1.0 n_trees=4"]


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
        ({"sweep": {"parameters": ["growth", "n_trees"], "values": [[0.5]]}}, "one value for each"),
        ({"sweep": {"parameters": ["growth"], "values": [[0.5], [0.5]]}}, "levels must differ"),
        ({"sweep": {"parameter": "growth", "values": 0.5}}, "sweep must be"),
        ({"stress": "crowd"}, "needs a sweep of at least 2 levels"),
        ({"stress": "Crowd", "sweep": {"parameter": "growth", "values": [0.0, 1.0]}}, "stress must name an axis"),
        ({"rank_by": [{"metric": "success rate"}]}, "rank_by metric"),
        ({"campaign": {"runs": 3}}, "campaign.runs must be >= 1 and divide"),
        ({"campaign": 2}, "campaign must be a mapping"),
        ({"policies": "luo-apf"}, "policies must be a list"),
        ({"policies": []}, "policies must name"),
    ],
)
def test_bad_suites_are_rejected(change, message):
    with pytest.raises(ValueError, match=message):
        lb.parse_suite({**SUITE, **change})


def test_generalization_suites_lie_outside_the_training_distribution():
    committed = {s.env_id: s for s in lb.load_suites() if s.generalization}
    assert set(committed) == {"agri_envs/GreenhouseNav-v2", "agri_envs/GreenhouseCoverage-v2"}
    for suite in committed.values():
        for label, families in lb.outside_training(suite).items():
            assert families and all(families.values()), (label, families)
    # The default scene lies inside (the greenhouse family draws it): as a generalization suite it is refused,
    # and so is a scene that one family excludes while another draws it.
    with pytest.raises(ValueError, match="lie inside the training distribution"):
        lb.parse_suite({**SUITE, "env_kwargs": {}, "generalization": True})
    with pytest.raises(ValueError, match=r"\['corridor'\]"):
        lb.parse_suite({**SUITE, "env_kwargs": {"scene": "corridor", "n_people": 0}, "generalization": True})
    # one sweep level inside is enough to refuse the suite
    swept = {**SUITE, "env_kwargs": {"n_rows": 6}, "sweep": {"parameter": "row_length", "values": [6.0]}}
    assert lb.parse_suite({**swept, "generalization": True}).generalization
    with pytest.raises(ValueError, match="tiny-rover n_rows=3.: \\[.greenhouse.\\]"):
        no_rows = {**swept, "env_kwargs": {}, "sweep": {"parameter": "n_rows", "values": [3, 6]}}
        lb.parse_suite({**no_rows, "generalization": True})
    with pytest.raises(ValueError, match="declares no training distribution"):
        lb.parse_suite({**SUITE, "env_id": "agri_envs/GrapeHarvest-v1", "env_kwargs": {}, "generalization": True})
def test_suite_campaigns_and_policies(tmp_path):
    suite = lb.parse_suite({**SUITE, "campaign": {"runs": 2}, "policies": ["harik-apf-gt"]})
    assert suite.campaign_runs == 2 and suite.policies == ("harik-apf-gt",)
    pairs = lb.all_baseline_pairs([suite])
    assert [ref["name"] for _, ref in pairs] == ["harik-apf-gt"]  # only the named policies run it
    assert len(lb.all_baseline_pairs([lb.parse_suite(SUITE)])) > 1
    block = lb.blocks_of(suite, "harik-apf-gt")
    assert len(block) == 1
    md = lb.render_markdown([], [suite])
    assert "in 1 campaigns of 2 runs" in md


def test_suite_name_must_match_file(tmp_path):
    path = write_suite(tmp_path, SUITE)
    path.rename(tmp_path / "other.yaml")
    with pytest.raises(ValueError, match="match the file name"):
        lb.load_suite(tmp_path / "other.yaml")
    with pytest.raises(ValueError, match="unknown suite"):
        lb.find_suite("nope", tmp_path)


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    """A tiny leaderboard in a temp folder: one suite, one baseline entry, its LEADERBOARD.md."""
    root = tmp_path_factory.mktemp("board")
    suites, entries, md = root / "suites", root / "entries", root / "LEADERBOARD.md"
    suite = lb.load_suite(write_suite(suites, SUITE))
    (entry,) = lb.evaluate_entries([(suite, lb.policy_reference("harik-apf-gt"))], workers=1, progress=False)
    lb.write_entry(entry, entries)
    lb.write_markdown(md, entries, suites)
    return root


def copy_board(board: Path, tmp_path: Path) -> tuple[Path, Path, Path]:
    shutil.copytree(board, tmp_path / "b")
    return tmp_path / "b" / "suites", tmp_path / "b" / "entries", tmp_path / "b" / "LEADERBOARD.md"


def cli(suites: Path, entries: Path, md: Path, *args: str) -> int:
    from agri_training.cli import main

    return main(["leaderboard", "--suites", str(suites), "--entries", str(entries), "--markdown", str(md), *args])


def test_entry_records_what_it_needs(board):
    (entry,) = lb.load_entries(board / "entries")
    assert entry["suite"]["name"] == "tiny-rover" and len(entry["suite"]["sha256"]) == 64
    assert entry["policy"] == {"kind": "baseline", "name": "harik-apf-gt", "privileged": True}
    assert entry["env_version"] == "v2" and entry["package_version"] and entry["git_commit"]
    assert [e["seed"] for e in entry["levels"][0]["episodes"]] == [100000, 100001]
    lo, hi = entry["summary"]["success_rate_ci"]
    assert 0.0 < lo < hi <= 1.0  # Wilson: never a point interval at 2/2 or 0/2
    md = (board / "LEADERBOARD.md").read_text()
    assert "`harik-apf-gt` **P**" in md and "tiny-rover (v1)" in md


def test_entries_keep_each_episodes_scalars_and_report_traces_its_whole_record():
    # gonzalez-pseudo-reactive records its sensory map and odometry path per episode (episode_metrics): the
    # entry keeps the numbers, a traced episode (which the report plots) keeps the whole record.
    coverage = {**SUITE, "env_id": "agri_envs/GreenhouseCoverage-v2", "env_kwargs": {"n_rows": 1, "row_length": 3.0}}
    suite = lb.parse_suite({**coverage, "seeds": {"start": 100000, "episodes": 1}})
    traces: list = []
    (entry,) = lb.evaluate_entries(
        [(suite, lb.policy_reference("gonzalez-pseudo-reactive"))], progress=False, traces=traces
    )
    (record,) = entry["levels"][0]["episodes"]
    assert not any(isinstance(v, (list, dict)) for v in record.values())
    assert record["turns"] >= 1 and record["seed"] == 100000
    ((trace,),) = traces[0]
    whole = trace["record"]
    assert whole["sensory_map"] and whole["odometry_path"]
    assert lb.entry_record(whole) == record


def test_verify_passes_as_committed(board, tmp_path, capsys):
    suites, entries, md = copy_board(board, tmp_path)
    assert cli(suites, entries, md, "verify", "--workers", "1", "--quiet") == 0
    assert "verified 1 entries exactly" in capsys.readouterr().out


def test_verify_fails_on_an_altered_number(board, tmp_path, capsys):
    suites, entries, md = copy_board(board, tmp_path)
    path = next(entries.glob("*/*.json"))
    doc = json.loads(path.read_text())
    doc["levels"][0]["episodes"][1]["path_length"] += 1e-9
    path.write_text(json.dumps(doc, indent=1))
    assert cli(suites, entries, md, "verify", "--workers", "1", "--quiet", "--no-markdown") == 1
    err = capsys.readouterr().err
    assert "levels[0].episodes[1].path_length" in err and "tiny-rover/harik-apf-gt" in err
    # the summary too
    doc = json.loads((board / "entries" / "tiny-rover" / "harik-apf-gt.json").read_text())
    doc["summary"]["mean_episode_time"] = 1.0
    path.write_text(json.dumps(doc, indent=1))
    assert lb.verify_entries(lb.load_entries(entries), suites, progress=False) == [
        f"tiny-rover/harik-apf-gt: summary.mean_episode_time: committed 1.0 != reproduced "
        f"{doc['levels'][0]['summary']['mean_episode_time']!r}"
    ]


def test_sampled_verify_reruns_picked_episodes_and_recomputes_every_summary(board, tmp_path, capsys):
    assert lb.sample_indices(20, 1, 1) == [0] and lb.sample_indices(20, 1, 3) == [0, 6, 13]
    assert lb.sample_indices(20, 4, 2) == [0, 1, 2, 3, 8, 9, 10, 11]  # whole campaigns
    assert lb.sample_indices(2, 1, 5) == [0, 1]
    suites, entries, md = copy_board(board, tmp_path)
    assert cli(suites, entries, md, "verify", "--sample", "1", "--workers", "1", "--quiet") == 0
    assert "a sample: 1 episode(s) per level re-run" in capsys.readouterr().out
    path = next(entries.glob("*/*.json"))
    committed = path.read_text()
    # a record that is re-run (episode 0) is caught by the re-run and by the summaries it feeds
    doc = json.loads(committed)
    doc["levels"][0]["episodes"][0]["path_length"] += 1e-9
    path.write_text(json.dumps(doc, indent=1))
    problems = lb.verify_sample(lb.load_entries(entries), 1, suites, progress=False)
    assert any("[tiny-rover]: episodes[0].path_length" in p for p in problems)
    assert any("summary.mean_path_length" in p for p in problems)
    # a record that is not re-run (episode 1) is caught through the summaries
    doc = json.loads(committed)
    doc["levels"][0]["episodes"][1]["episode_time"] += 1.0
    path.write_text(json.dumps(doc, indent=1))
    problems = lb.verify_sample(lb.load_entries(entries), 1, suites, progress=False)
    assert problems and all("summary" in p for p in problems)
    # and a summary edited alone
    doc = json.loads(committed)
    doc["summary"]["success_rate"] = 0.5
    path.write_text(json.dumps(doc, indent=1))
    assert lb.verify_sample(lb.load_entries(entries), 1, suites, progress=False) == [
        "tiny-rover/harik-apf-gt: summary.success_rate: committed 0.5 != reproduced 1.0"
    ]
    with pytest.raises(ValueError, match="at least one episode"):
        lb.sample_indices(20, 1, 0)


def test_verify_fails_on_a_stale_leaderboard_page(board, tmp_path, capsys):
    suites, entries, md = copy_board(board, tmp_path)
    md.write_text(md.read_text().replace("1.00 [", "0.99 ["))
    assert not lb.leaderboard_is_current(md, entries, suites)
    assert cli(suites, entries, md, "verify", "--workers", "1", "--quiet") == 1
    assert "is stale" in capsys.readouterr().err
    assert cli(suites, entries, md, "render") == 0 and lb.leaderboard_is_current(md, entries, suites)


def test_verify_fails_when_the_suite_changed(board, tmp_path):
    suites, entries, md = copy_board(board, tmp_path)
    write_suite(suites, {**SUITE, "env_kwargs": {**SUITE["env_kwargs"], "n_people": 1}})
    problems = lb.verify_entries(lb.load_entries(entries), suites, progress=False)
    assert len(problems) == 1 and "stale" in problems[0]


def test_compare_documents_tolerance():
    committed = {"a": 1.0, "b": [1, 2.5], "wall_time_s": 3.0, "mean_planning_time_ms": 1.0, "s": "x"}
    assert lb.compare_documents(committed, {**committed, "wall_time_s": 9.0, "mean_planning_time_ms": 7.0}) == []
    near = {**committed, "a": 1.0 + 1e-12}
    assert lb.compare_documents(committed, near) == ["a: committed 1.0 != reproduced 1.000000000001"]
    assert lb.compare_documents(committed, near, rtol=1e-9) == []
    assert lb.compare_documents(committed, {**committed, "a": 1.1}, rtol=1e-9) != []
    assert lb.compare_documents(committed, {**committed, "b": [1, 2.5, 3]}) == ["b: 2 items committed, 3 reproduced"]
    assert lb.compare_documents(committed, {**committed, "b": [2, 2.5]}, rtol=0.9) == [
        "b[0]: committed 1 != reproduced 2"
    ]
    assert lb.compare_documents({"x": True}, {"x": 1}) != []
    with pytest.raises(ValueError, match="rtol"):
        lb.compare_documents(1.0, 1.0, rtol=-1)


def test_committed_leaderboard_covers_every_baseline_and_is_current():
    from agri_baselines import list_policies

    entries = lb.load_entries()
    have = {(e["suite"]["name"], e["policy"]["name"]) for e in entries}
    pairs = {(suite.name, ref["name"]) for suite, ref in lb.all_baseline_pairs(lb.load_suites())}
    assert pairs <= have, f"no entries for {sorted(pairs - have)}"
    for env_id in {s.env_id for s in lb.load_suites()}:  # every policy of an env runs on some suite of it
        for spec in list_policies(env_id):
            assert any(name == spec.name for _, name in pairs), f"{spec.name} runs on no suite"
    assert lb.leaderboard_is_current()


@pytest.mark.slow
def test_committed_entries_reproduce():
    assert lb.verify_entries(lb.load_entries(), workers=2, progress=False) == []


def test_worker_pool_gives_the_serial_result(board):
    suite = lb.load_suite(board / "suites" / "tiny-rover.yaml")
    suite = lb.Suite(**{**suite.__dict__, "episodes": 3})
    serial = lb.run_blocks(lb.blocks_of(suite, "harik-apf-gt"), workers=1, progress=False)
    pooled = lb.run_blocks(lb.blocks_of(suite, "harik-apf-gt"), workers=2, progress=False)
    assert [e["seed"] for e in pooled[0]["episodes"]] == list(range(100000, 100003))
    assert lb.compare_documents(serial[0]["episodes"], pooled[0]["episodes"]) == []
    assert lb.compare_documents(serial[0]["summary"], pooled[0]["summary"]) == []
    assert pooled[0]["label"] == "tiny-rover" and pooled[0]["env_kwargs"]["full_scan"] is True


def test_learned_policy_reference_pins_the_weights(tmp_path):
    run = tmp_path / "ppo_nav"
    run.mkdir()
    (run / "config.yaml").write_text(yaml.safe_dump({"env_id": "agri_envs/GreenhouseNav-v2", "algo": "ppo"}))
    (run / "policy.pt").write_bytes(b"weights v1")
    ref = lb.policy_reference(str(run))
    assert ref["kind"] == "learned" and ref["name"] == "ppo_nav" and ref["privileged"] is False
    assert ref["sha256"] == lb.sha256_file(run / "policy.pt")
    assert lb.policy_argument(ref) == str(run)
    (run / "policy.pt").write_bytes(b"weights v2")
    with pytest.raises(ValueError, match="changed"):
        lb.policy_argument(ref)
    (run / "policy.pt").unlink()
    with pytest.raises(ValueError, match="not found"):
        lb.policy_argument(ref)
    assert lb.policy_reference("luo-apf") == {"kind": "baseline", "name": "luo-apf", "privileged": False}


def test_leaderboard_columns_have_display_names_and_readable_precision():
    md = lb.render_markdown(lb.load_entries(lb.ENTRIES_DIR), lb.load_suites(lb.SUITES_DIR))
    assert "mean_mean" not in md and "success_rate ↑" not in md
    assert "| mean strip distance [m] ↓ |" in md and "| max cross-track to centre line [cm] ↓ |" in md
    coverage = md.split("### coverage-almeria")[1].split("###")[0]
    assert "1.000 [1.000, 1.000]" in coverage  # coverage to 3 decimals, not "1.0 [1.0, 1.0]"
    assert lb.metric_format("success_rate") == "{:.2f}" and lb.metric_format("mean_min_clearance") == "{:.3f}"
    assert lb.metric_label("iqm_episode_time") == "IQM time [s]"


def test_cross_track_reads_in_centimetres_and_campaign_parts_are_named():
    # stored in metres, shown in cm to the millimetre: 0.0577 m -> "5.8", not "0.1" (one decimal of a metre)
    assert lb.format_metric("mean_max_cross_track", 0.0577, [0.0549, 0.0605]) == "5.8 [5.5, 6.0]"
    assert lb.format_metric("later_runs_mean_cross_track_turns_max", 0.1234) == "12.3"
    assert lb.format_metric("mean_episode_time", 137.84) == "137.8"
    assert lb.format_metric("later_runs_mean_episode_time", 141.667) == "141.7"  # "later" holds no "ate"
    assert lb.metric_format("ate_rmse") == lb.metric_format("mean_ate_rmse") == "{:.3f}"
    assert lb.metric_label("later_runs_mean_cross_track_corridors_max") == (
        "later runs: max cross-track to plan, corridors [cm]"
    )
    assert lb.metric_label("first_run_mean_episode_time") == "first run: time [s]"
    entry = {
        "levels": [
            {
                "episodes": [
                    {"campaign_run": k % 2, "is_success": k != 2, "episode_time": 100.0 + k} for k in range(4)
                ]
            }
        ]
    }
    # a campaign part's metric takes that part's episodes only: later runs are k = 1 and 3
    assert lb.episode_values(entry, "later_runs_mean_episode_time") == ([101.0, 103.0], False)
    assert lb.episode_values(entry, "first_run_success_rate") == ([True, False], True)
    assert lb.episode_values(entry, "success_rate") == ([True, True, False, True], True)
