"""Stress suites in the report and on LEADERBOARD.md: the robustness matrix, where each policy first drops below
0.90 and why, and the one-screen opening before the detail. Synthetic entries only: nothing is evaluated."""

import yaml

from agri_training import leaderboard as lb
from agri_training.core.stats import wilson_interval
from agri_training.report import page
from agri_training.report.page import Row
from agri_training.report.robustness import robustness_section

NAV = "agri_envs/GreenhouseNav-v2"
RANK = [{"metric": "success_rate", "higher_is_better": True}]
CROWD = {
    "name": "nav-stress-crowd",
    "version": 1,
    "env_id": NAV,
    "env_kwargs": {"n_rows": 1},
    "sweep": {"parameter": "n_people", "values": [0, 4, 8]},
    "stress": "crowd",
    "seeds": {"start": 100000, "episodes": 20},
    "rank_by": RANK,
}
PAPER = {**{k: v for k, v in CROWD.items() if k not in ("sweep", "stress")}, "name": "nav-paper"}
CHAIN_LENGTH = {
    **CROWD,
    "name": "chain-stress-length",
    "env_id": "robot_chain_v1",
    "env_kwargs": {},
    "sweep": {"parameters": ["n_robots", "office_width"], "values": [[4, 14.0], [32, 28.0]]},
    "stress": "chain-length",
}


def _record(i, failure=None):
    """An episode's record; ``failure``: None (a success), crash, time-out, stall (Harik's safety stop holds)."""
    return {
        "seed": 100000 + i,
        "is_success": failure is None,
        "collision": failure == "crash",
        "truncated": failure in ("time-out", "stall"),
        "blocked_at_end": float(failure == "stall"),
        "episode_time": 10.0,
        "return": 1.0,
    }


def _entry(suite, name, failures, kind="baseline"):
    """An entry with, per level, the failure kinds of its first episodes (the rest succeed)."""
    levels = []
    for (label, kwargs), kinds in zip(suite.levels(), failures, strict=True):
        eps = [_record(i, kinds[i] if i < len(kinds) else None) for i in range(suite.episodes)]
        k = sum(e["is_success"] for e in eps)
        summary = {"episodes": len(eps), "success_rate": k / len(eps), "success_rate_ci": wilson_interval(k, len(eps))}
        levels.append({"label": label, "env_kwargs": kwargs, "summary": summary, "episodes": eps})
    k = sum(lv["summary"]["success_rate"] * 20 for lv in levels)
    n = 20 * len(levels)
    policy = {"kind": kind, "name": name, "privileged": False, **({"sha256": "0" * 64} if kind == "learned" else {})}
    return {
        "suite": {"name": suite.name, "version": suite.version, "sha256": suite.sha256},
        "policy": policy,
        "privileged": False,
        "env_id": suite.env_id,
        "git_commit": "0" * 40,
        "summary": {"episodes": n, "success_rate": k / n, "success_rate_ci": wilson_interval(round(k), n)},
        "levels": levels,
    }


def _crowd_entries(suite):
    return [
        _entry(suite, "steady", [[], ["time-out"], ["crash", "crash"]]),  # 0.90 at worst: holds
        _entry(suite, "crashy", [[], ["crash"] * 3 + ["time-out"], ["crash"] * 8], kind="learned"),
        _entry(suite, "slow", [[], [], ["time-out"] * 5 + ["stall"] * 2]),
    ]


def test_first_drop_says_where_and_why():
    suite = lb.parse_suite(CROWD)
    lines = lb.robustness_lines(NAV, [suite], _crowd_entries(suite))
    assert lines == [
        "- `slow`: crowd: first below 0.90 at `n_people=8` (level 3 of 3): 0.65 [0.43, 0.82], time-out "
        "(5 of 7 failures; 2 stall).",
        "- `steady`: holds on every level.",
        "- `crashy` (learned): crowd: first below 0.90 at `n_people=4` (level 2 of 3): 0.80 [0.58, 0.92], crash "
        "(3 of 4 failures; 1 time-out).",
    ]
    # stalls where the record tells them; a chain break on the chain; time-out where nothing tells a stall
    assert lb.failure_kind(NAV, _record(0, "stall")) == "stall"
    assert lb.failure_kind("agri_envs/GreenhouseCoverage-v9", _record(0, "stall")) == "time-out"
    assert lb.failure_kind("robot_chain_v1", {"chain_intact": False}) == "chain break"
    assert lb.failure_kind("agri_envs/GrapeHarvest-v1", {"truncated": True, "plan_success": False}) == "stall"


def test_leaderboard_lists_stress_levels_and_its_robustness_section():
    crowd, chain = lb.parse_suite(CROWD), lb.parse_suite(CHAIN_LENGTH)
    entries = [*_crowd_entries(crowd), _entry(chain, "apoorva", [[], ["time-out"] * 3])]
    md = lb.render_markdown(entries, [chain, crowd])
    assert "Stress suite, axis **chain-length**" in md and "(`n_robots=4 office_width=14.0`, " in md
    assert "levels of `n_people` (`0`, `4`, `8`)" in md and "| 1.00 / 0.95 / 0.90 |" in md
    assert "| 1.00 / **0.80** / **0.60** |" in md  # success by level, below the floor in bold
    robust = md.split("### Robustness: where each policy first drops below 0.90 success")
    assert len(robust) == 3 and "`apoorva`: chain-length: first below 0.90 at `n_robots=32 office_width=28.0`" in md
    assert md == lb.render_markdown(entries, [chain, crowd])  # deterministic: verify compares it byte for byte


def test_report_opens_with_the_glance_and_draws_a_robustness_matrix(tmp_path, monkeypatch):
    from PIL import Image

    suites_dir, out = tmp_path / "suites", tmp_path / "out"
    suites_dir.mkdir()
    for doc in (CROWD, PAPER):
        (suites_dir / f"{doc['name']}.yaml").write_text(yaml.safe_dump(doc))
    crowd, paper = lb.load_suite(suites_dir / "nav-stress-crowd.yaml"), lb.load_suite(suites_dir / "nav-paper.yaml")
    rows = [Row(crowd, e, True) for e in _crowd_entries(crowd)]
    # two learned policies and no baseline on the paper suite: no pair to compare, so no comparison table
    rows += [Row(paper, _entry(paper, name, [["crash"] * k], kind="learned"), True) for name, k in (("a", 0), ("b", 9))]
    monkeypatch.setattr(page, "collect_rows", lambda *args, **kwargs: rows)
    monkeypatch.setattr(page, "level_results", lambda *args, **kwargs: [])
    monkeypatch.setattr(page, "zoo_runs", lambda: [])
    md = page.build_report(out, suites_dir, tmp_path / "entries", tmp_path / "runs", progress=False).read_text()
    glance, detail, wins = md.index("## At a glance"), md.index(f"## {NAV}"), md.index("## Who wins where")
    assert glance < md.index("## How to read") < detail < wins
    assert "| `b` (learned) | **0.55** | - |" in md and "| `slow` | - | **0.88 ▾0.65** |" in md
    assert "![robustness-greenhouse-nav.png](robustness-greenhouse-nav.png)" in md
    assert "- `steady`: holds on every level." in md
    assert Image.open(out / "robustness-greenhouse-nav.png").width <= 1150  # the page's width
    lines = md.splitlines()
    for i, line in enumerate(lines):  # every table has a row under its header
        if line.startswith("|---"):
            assert i + 1 < len(lines) and lines[i + 1].startswith("| "), lines[i - 1]
    assert "`a` vs `b`" not in md and "X vs Y" not in md.split("#### nav-paper")[1].split("####")[0]
    # one matrix per env family, named after it (no version: it survives a version bump)
    chain = lb.parse_suite(CHAIN_LENGTH)
    section = robustness_section(chain.env_id, [chain], [(chain, _entry(chain, "apoorva", [[], []]))], out)
    assert "![robustness-robot-chain.png](robustness-robot-chain.png)" in section
    assert section[-1] == "- `apoorva`: holds on every level."
    assert (out / "robustness-robot-chain.png").exists()
    html = (out / "report.html").read_text()
    assert "img,video{max-width:100%" in html and "<details><summary>" in html


def test_every_policy_kind_but_a_baseline_is_listed_as_learned():
    from agri_training.leaderboard.robustness import policy_order

    assert not lb.is_learned({"kind": "baseline", "name": "harik-apf"})
    kinds = ("learned", "onnx", "sb3-zip", "callable", "object")
    assert all(lb.is_learned({"kind": k}) for k in kinds)
    entries = [{"policy": {"kind": k, "name": k}, "privileged": False} for k in ("baseline", *kinds)]
    order = policy_order(entries)
    assert order[0] == ("baseline", False, False) and all(learned for _, learned, _ in order[1:])


def test_own_sensors_section_sets_each_unprivileged_learned_policy_against_the_best_unprivileged_script():
    from agri_training.report.robustness import own_sensors_section

    crowd, paper = lb.parse_suite(CROWD), lb.parse_suite(PAPER)
    privileged = _entry(crowd, "oracle", [[], [], []])
    privileged["privileged"] = True  # never the rival: it sees what the robot cannot
    shown = [
        (crowd, _entry(crowd, "steady", [[], ["time-out"], ["crash", "crash"]])),
        (crowd, _entry(crowd, "slow", [[], [], ["time-out"] * 5])),
        (crowd, _entry(crowd, "student", [[], ["crash"] * 3, ["crash"]], kind="learned")),
        (crowd, privileged),
        (paper, _entry(paper, "steady", [[]])),
        (paper, _entry(paper, "student", [["time-out"]], kind="learned")),
    ]
    lines = own_sensors_section(NAV, shown)
    text = "\n".join(lines)
    # the rival: the unprivileged script with the best success pooled over the suites the student ran
    # (steady 77 of 80, slow 55 of 60)
    assert "against `steady`" in text and "oracle" not in text
    rows = [line for line in lines if line.startswith("| ") and "---" not in line and "suite level" not in line]
    assert rows[0].startswith("| `nav-paper` | 0.95 [")  # paper suites first, then the stress levels
    marked = "| **`nav-stress-crowd n_people=4`** | 0.85 [0.64, 0.95] | 0.95 [0.76, 0.99] | -0.10 | 0.15 | 0.00 |"
    assert rows[2] == marked
    assert "| `nav-stress-crowd n_people=8` | 0.95 [" in text  # ahead by 0.05: not marked
    assert "trails `steady` by more than 0.05 on 1 of 4 suite levels" in text
    assert own_sensors_section(NAV, [(crowd, privileged)]) == []
