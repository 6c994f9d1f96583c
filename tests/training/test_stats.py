"""Statistics against known values: Wilson/Clopper-Pearson (scipy's binomtest as oracle), IQM, bootstrap,
paired comparisons."""

import math

import numpy as np
import pytest
from scipy.stats import binomtest, trim_mean

from agri_training.core.stats import (
    clopper_pearson_interval,
    format_interval,
    iqm,
    lower_tail_mean,
    newcombe_interval,
    newcombe_paired_interval,
    paired_comparison,
    probability_of_improvement,
    rate_interval,
    stratified_bootstrap_ci,
    wilson_interval,
)


@pytest.mark.parametrize("k,n", [(20, 20), (0, 20), (19, 20), (10, 20), (1, 7), (93, 100), (0, 1), (1, 1)])
@pytest.mark.parametrize("level", [0.95, 0.9])
def test_rate_intervals_match_scipy(k, n, level):
    ref = binomtest(k, n).proportion_ci(confidence_level=level, method="wilson")
    assert wilson_interval(k, n, level) == pytest.approx((ref.low, ref.high), abs=1e-12)
    ref = binomtest(k, n).proportion_ci(confidence_level=level, method="exact")
    assert clopper_pearson_interval(k, n, level) == pytest.approx((ref.low, ref.high), abs=1e-10)


def test_all_successes_are_not_a_point():
    lo, hi = rate_interval([True] * 20)
    assert lo == pytest.approx(0.8389, abs=1e-4) and hi == 1.0
    assert rate_interval([1, 0, None, float("nan")]) == wilson_interval(1, 2)
    assert np.isnan(rate_interval([])[0])


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="successes"):
        wilson_interval(21, 20)
    with pytest.raises(ValueError, match="n must"):
        wilson_interval(0, 0)
    with pytest.raises(ValueError, match="level"):
        wilson_interval(1, 2, level=1.5)
    with pytest.raises(ValueError, match="method"):
        rate_interval([1], method="jeffreys")
    with pytest.raises(ValueError, match="strata"):
        stratified_bootstrap_ci([1.0, 2.0], strata=["a"])
    with pytest.raises(ValueError, match="paired"):
        paired_comparison([1.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="margin"):
        paired_comparison([1.0], [1.0], margin=-1)


def test_iqm_matches_scipy_trim_mean():
    rng = np.random.default_rng(3)
    for n in (1, 3, 4, 7, 20, 101):
        x = rng.normal(size=n)
        assert iqm(x) == pytest.approx(trim_mean(x, 0.25))
    assert iqm([1.0, 2.0, 3.0, 1000.0]) == pytest.approx(2.5)  # robust to the outlier


def test_bootstrap_is_seeded_and_covers_the_mean():
    rng = np.random.default_rng(0)
    x = rng.normal(10.0, 2.0, size=50)
    a = stratified_bootstrap_ci(x, seed=1)
    assert a == stratified_bootstrap_ci(x, seed=1)
    assert a[0] < x.mean() < a[1]
    # the percentile interval of the mean is close to the normal-theory one for 50 normal samples
    half = 1.96 * x.std(ddof=1) / np.sqrt(x.size)
    assert a[1] - a[0] == pytest.approx(2 * half, rel=0.15)
    lo, hi = stratified_bootstrap_ci(x, iqm)
    assert lo < iqm(x) < hi


def test_stratified_bootstrap_keeps_strata_sizes():
    # Two strata with very different values: resampling within strata keeps the pooled mean nearly fixed,
    # while an unstratified bootstrap lets the mix vary.
    x = np.array([0.0] * 10 + [100.0] * 10) + np.linspace(0, 1, 20)
    strata = ["a"] * 10 + ["b"] * 10
    lo_s, hi_s = stratified_bootstrap_ci(x, strata=strata)
    lo_u, hi_u = stratified_bootstrap_ci(x)
    assert hi_s - lo_s < 1.0 < hi_u - lo_u


def test_newcombe_paired_interval():
    # 20/20 against 20/20 on the same seeds: no difference, but not a point either
    lo, hi = newcombe_paired_interval([True] * 20, [True] * 20)
    assert lo == pytest.approx(-0.1611, abs=1e-3) and hi == pytest.approx(0.1611, abs=1e-3)
    # coverage: paired outcomes with known rates and correlation; the 95 % interval should cover the true
    # difference about 95 % of the time (Newcombe's method 10 is slightly conservative)
    rng = np.random.default_rng(11)
    hits = 0
    for _ in range(1000):
        u = rng.random(40)
        x = u < 0.8
        y = np.where(rng.random(40) < 0.5, x, rng.random(40) < 0.6)  # p_y = 0.5*0.8 + 0.5*0.6 = 0.7
        lo, hi = newcombe_paired_interval(x, y)
        hits += lo <= 0.1 <= hi
    assert 0.93 <= hits / 1000 <= 0.99
    with pytest.raises(ValueError, match="paired"):
        newcombe_paired_interval([1, 0], [1])


def test_probability_of_improvement():
    assert probability_of_improvement(np.array([2.0, 3.0]), np.array([0.0, 1.0])) == 1.0
    assert probability_of_improvement(np.array([1.0, 1.0]), np.array([1.0, 1.0])) == 0.5
    assert probability_of_improvement(np.array([0.0, 2.0]), np.array([1.0, 1.0])) == 0.5


def test_paired_comparison_verdicts():
    rng = np.random.default_rng(5)
    base = rng.normal(50.0, 5.0, size=30)
    faster = base - 5.0 + rng.normal(0, 0.5, size=30)  # time: lower is better
    c = paired_comparison(faster, base, "mean_episode_time", higher_is_better=False)
    assert c.verdict == "better" and c.ci[1] < 0 and c.prob_improvement > 0.5
    assert paired_comparison(base, faster, "t", higher_is_better=False).verdict == "worse"
    same = base + rng.normal(0, 0.01, size=30)
    assert paired_comparison(same, base, "t", margin=0.5).verdict == "matches"
    assert paired_comparison(same, base, "t", margin=0.0).verdict == "inconclusive"
    # rates: 20/20 against 18/20 is not enough to claim anything
    c = paired_comparison([1] * 20, [1] * 18 + [0] * 2, "success_rate", binary=True)
    assert c.verdict == "inconclusive" and c.ci[0] < 0 < c.ci[1] and c.difference == pytest.approx(0.1)


def test_format_interval():
    assert format_interval(1.0, (0.8389, 1.0)) == "1.00 [0.84, 1.00]"
    assert format_interval(None, None) == "-"
    assert format_interval(2.0, (float("nan"), float("nan"))) == "2.00"


def test_newcombe_independent_interval():
    # Newcombe (1998) "Interval estimation for the difference between independent proportions", example:
    # 56/70 - 48/80 = 0.2, method 10 interval 0.0524 to 0.3339
    assert newcombe_interval(56, 70, 48, 80) == pytest.approx((0.0524, 0.3339), abs=1e-4)
    # 10/10 here against the paper's 9/10: the data support no difference
    lo, hi = newcombe_interval(10, 10, 9, 10)
    assert lo < 0 < hi


def test_lower_tail_mean_is_the_mean_of_the_worst_episodes():
    rng = np.random.default_rng(3)
    x = rng.normal(size=200)
    # oracle: sort by hand, keep the lowest ceil(0.1 n)
    assert lower_tail_mean(x, 0.1) == pytest.approx(float(np.mean(sorted(x.tolist())[:20])))
    assert lower_tail_mean([1.0, 0.0, 1.0, 1.0], 0.1) == 0.0  # one episode of four is the tail
    assert lower_tail_mean([3.0, 1.0, np.nan, 2.0], 0.5) == 1.5
    assert lower_tail_mean(x, 1.0) == pytest.approx(x.mean())
    assert math.isnan(lower_tail_mean([np.nan]))
    with pytest.raises(ValueError, match="fraction"):
        lower_tail_mean(x, 0.0)
