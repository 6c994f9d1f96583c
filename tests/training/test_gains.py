"""Where learning beats the papers: the pairing against the best scripted entry and the verdicts."""

import numpy as np

from agri_training import leaderboard as lb
from agri_training.leaderboard.gains import best_scripted, efficiency_metric

NAV = "agri_envs/GreenhouseNav-v2"
RANK = (
    lb.RankKey("success_rate", True),
    lb.RankKey("mean_max_cross_track", False),  # a slower policy may rank first on another key
    lb.RankKey("mean_episode_time", False),
)
SUITE = lb.Suite("toy-paper", 1, NAV, {}, 100000, 20, RANK)
STRESS = lb.Suite("toy-stress", 1, NAV, {}, 100000, 20, RANK, sweep=(("n_people",), ((2,), (8,))), stress="crowd")


def _entry(name, kind, times, successes=None, collisions=(), suite="toy-paper", layer=None):
    n = len(times)
    successes = [True] * n if successes is None else successes
    episodes = []
    for i, t in enumerate(times):
        e = {"seed": 100000 + i, "is_success": successes[i], "collision": i in collisions, "episode_time": t}
        if layer is not None:
            e["safety_interventions"] = layer
        episodes.append(e)
    done = [t for t, ok in zip(times, successes, strict=True) if ok]
    summary = {
        "episodes": n,
        "success_rate": sum(successes) / n,
        "mean_episode_time": float(np.mean(done)),
        "mean_max_cross_track": 0.1 if kind == "baseline" and name == "slow-but-tidy" else 0.2,
    }
    return {
        "suite": {"name": suite},
        "policy": {"kind": kind, "name": name},
        "summary": summary,
        "levels": [{"episodes": episodes}],
    }


def _times(mean, n=20, seed=0):
    return list(mean + np.random.default_rng(seed).normal(0, 1.0, n))


def test_the_learned_policy_is_paired_with_the_fastest_of_the_safest_scripted_ones():
    slow = _entry("slow-but-tidy", "baseline", _times(200))  # ranked first (cross-track), but slow
    fast = _entry("fast-scripted", "baseline", _times(110, seed=1))
    unsafe = _entry("reckless-scripted", "baseline", _times(50, seed=2), successes=[False] + [True] * 19)
    assert best_scripted([slow, fast, unsafe], "mean_episode_time", False) is fast
    assert efficiency_metric(SUITE) == "mean_episode_time"


def test_verdicts():
    scripted = _entry("fast-scripted", "baseline", _times(110, seed=1))
    quick = _entry("quick", "learned", _times(85, seed=3), layer=12.0)
    crashy = _entry("crashy", "learned", _times(85, seed=4), successes=[False] + [True] * 19, collisions={0})
    slow = _entry("slowpoke", "learned", _times(112, seed=5))
    rows = {g.policy: g for g in lb.gain_rows(NAV, [SUITE, STRESS], [scripted, quick, crashy, slow])}
    assert rows["quick"].beats and rows["quick"].interventions == 12.0
    assert -0.25 < rows["quick"].relative < -0.20
    assert rows["crashy"].faster and not rows["crashy"].as_safe and not rows["crashy"].beats
    assert not rows["slowpoke"].faster
    assert all(g.scripted == "fast-scripted" for g in rows.values())
    text = "\n".join(lb.gains_lines([NAV], [SUITE], [scripted, quick, crashy, slow]))
    assert "| `quick` | toy-paper | `fast-scripted` |" in text and "**beats it at equal safety**" in text
    assert "faster, less safe" in text and "`slowpoke`" not in text  # only policies faster somewhere
    assert "`quick` beats the best scripted policy at equal safety on 1 of its 1 suites." in text


def test_stress_suites_and_envs_without_a_faster_policy():
    scripted = _entry("fast-scripted", "baseline", _times(110, seed=1), suite="toy-stress")
    quick = _entry("quick", "learned", _times(85, seed=3), suite="toy-stress")
    assert lb.gain_rows(NAV, [STRESS], [scripted, quick]) == []
    slow = _entry("slowpoke", "learned", _times(130, seed=5))
    text = lb.gains_lines([NAV], [SUITE], [_entry("fast-scripted", "baseline", _times(110, seed=1)), slow])
    assert any("No learned policy is faster" in line for line in text)


def test_a_policy_cloned_from_a_training_teacher_says_whose_time_it_gains():
    from agri_training.learned.zoo import training_teacher, zoo_training

    taught = "dagger-greenhouse-coverage-half-circle"
    assert training_teacher(taught) == "coverage-half-circle"
    assert training_teacher("dagger-greenhouse-coverage-route") is None  # cloned from a paper's controller
    assert training_teacher("not-in-the-zoo") is None
    assert zoo_training(taught).startswith("imitation of coverage-half-circle (a training teacher, no paper's)")
    scripted = _entry("fast-scripted", "baseline", _times(110, seed=1))
    text = "\n".join(
        lb.gains_lines(
            [NAV], [SUITE], [scripted, _entry(taught, "learned", _times(85)), _entry("quick", "learned", _times(85))]
        )
    )
    assert (
        f"`{taught}` beats the best scripted policy at equal safety on 1 of its 1 suites. It was cloned from " in text
    )
    assert "`quick` beats the best scripted policy at equal safety on 1 of its 1 suites.\n" in text
