"""Honest statistics for evaluation summaries, leaderboards and reports.

- Rates (success, collision) get score intervals that stay honest at the boundary: Wilson (default) or
  Clopper-Pearson. 20 successes out of 20 read as about [0.84, 1.00], not [1.00, 1.00].
- Continuous metrics get the mean and the interquartile mean (IQM, the mean of the middle 50 %), each with
  a stratified percentile-bootstrap interval, as rliable does (Agarwal et al. 2021, "Deep RL at the Edge of
  the Statistical Precipice"): episodes are resampled with replacement within each stratum (a scenario
  level, say) so every stratum keeps its size.
- The worst episodes get their own number: the mean of the worst 10 % (:func:`lower_tail_mean`, the
  conditional value at risk), with a bootstrap interval like any other statistic.
- Two policies evaluated on the same seeds get a paired comparison: the difference with its interval (a
  paired bootstrap over seeds for continuous metrics, Newcombe's hybrid score interval for paired rates)
  and the probability of improvement ``P(X > Y) + P(X = Y) / 2`` over episode pairs (rliable's definition).

Only numpy and the standard library are needed. All resampling uses a seeded ``numpy.random.Generator``,
so a report computes the same intervals every time.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from statistics import NormalDist
from typing import Any

import numpy as np

#: Confidence level used everywhere unless told otherwise.
LEVEL = 0.95
#: Bootstrap resamples used everywhere unless told otherwise.
N_RESAMPLES = 2000


def _check_level(level: float) -> None:
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")


def _check_counts(successes: int, n: int, level: float) -> None:
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be in [0, n={n}], got {successes}")
    _check_level(level)


def _z(level: float) -> float:
    return NormalDist().inv_cdf(0.5 + level / 2.0)


def wilson_interval(successes: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion.

    Args:
        successes: Number of successes, in [0, n].
        n: Number of trials, >= 1.
        level: Confidence level in (0, 1).

    Returns:
        ``(low, high)`` within [0, 1].

    Raises:
        ValueError: For ``n < 1``, ``successes`` outside [0, n] or ``level`` outside (0, 1).
    """
    _check_counts(successes, n, level)
    z = _z(level)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    lo, hi = centre - half, centre + half
    # Exact at the boundary (the formula gives 0 and 1 up to rounding there).
    return (0.0 if successes == 0 else max(0.0, lo)), (1.0 if successes == n else min(1.0, hi))


def clopper_pearson_interval(successes: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Clopper-Pearson ("exact") interval of a binomial proportion; needs scipy.

    Args:
        successes: Number of successes, in [0, n].
        n: Number of trials, >= 1.
        level: Confidence level in (0, 1).

    Returns:
        ``(low, high)`` within [0, 1].

    Raises:
        ValueError: For ``n < 1``, ``successes`` outside [0, n] or ``level`` outside (0, 1).
    """
    _check_counts(successes, n, level)
    from scipy.stats import beta

    a = (1.0 - level) / 2.0
    lo = 0.0 if successes == 0 else float(beta.ppf(a, successes, n - successes + 1))
    hi = 1.0 if successes == n else float(beta.ppf(1.0 - a, successes + 1, n - successes))
    return lo, hi


def rate_interval(
    values: Sequence[Any] | np.ndarray, level: float = LEVEL, method: str = "wilson"
) -> tuple[float, float]:
    """Interval of the rate of true values (bools or 0/1; None and NaN are dropped).

    Args:
        values: Per-episode outcomes.
        level: Confidence level in (0, 1).
        method: ``"wilson"`` or ``"clopper-pearson"``.

    Returns:
        ``(low, high)``, or ``(nan, nan)`` when no value is left.

    Raises:
        ValueError: For an unknown method.
    """
    x = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan")
    k = int(np.count_nonzero(x))
    if method == "wilson":
        return wilson_interval(k, int(x.size), level)
    if method == "clopper-pearson":
        return clopper_pearson_interval(k, int(x.size), level)
    raise ValueError(f"method must be 'wilson' or 'clopper-pearson', got {method!r}")


def iqm(values: Sequence[float] | np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 % (25 % trimmed from each end, as ``scipy.stats.trim_mean``).

    Returns:
        The IQM, NaN for no finite value.
    """
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan")
    cut = int(0.25 * x.size)
    return float(x[cut : x.size - cut].mean())


def lower_tail_mean(values: Sequence[float] | np.ndarray, fraction: float = 0.1) -> float:
    """Mean of the worst ``fraction`` of the values (the lower tail; CVaR at level ``fraction``).

    The tail holds ``ceil(fraction * n)`` values (at least one), so over 20 episodes the worst 10 % are the
    2 lowest. Used for "how bad are a policy's worst episodes" next to the mean.

    Returns:
        The tail mean, NaN for no finite value.

    Raises:
        ValueError: For ``fraction`` outside (0, 1].
    """
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must be in (0, 1], got {fraction}")
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan")
    return float(x[: max(1, math.ceil(fraction * x.size - 1e-9))].mean())


def _strata_index(n: int, strata: Sequence[Any] | None) -> list[np.ndarray]:
    if strata is None:
        return [np.arange(n)]
    if len(strata) != n:
        raise ValueError(f"strata must have one label per value ({n}), got {len(strata)}")
    labels = list(dict.fromkeys(strata))
    arr = np.array([labels.index(s) for s in strata])
    return [np.flatnonzero(arr == k) for k in range(len(labels))]


def stratified_bootstrap_ci(
    values: Sequence[float] | np.ndarray,
    statistic: Callable[[np.ndarray], float] = np.mean,
    strata: Sequence[Any] | None = None,
    n_resamples: int = N_RESAMPLES,
    level: float = LEVEL,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile interval of ``statistic`` from a bootstrap that resamples within each stratum.

    Args:
        values: Per-episode values (None and NaN are dropped together with their stratum label).
        statistic: Function of a 1-D array, e.g. ``np.mean`` or :func:`iqm`.
        strata: Optional label per value (e.g. the scenario level); resampling keeps each stratum's size.
        n_resamples: Bootstrap resamples, >= 100.
        level: Confidence level in (0, 1).
        seed: Seed of the resampling.

    Returns:
        ``(low, high)``; ``(v, v)`` for a single value, ``(nan, nan)`` for none.

    Raises:
        ValueError: For ``n_resamples < 100``, a bad level or strata of the wrong length.
    """
    if n_resamples < 100:
        raise ValueError(f"n_resamples must be >= 100, got {n_resamples}")
    _check_level(level)
    x = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
    if strata is not None and len(strata) != x.size:
        raise ValueError(f"strata must have one label per value ({x.size}), got {len(strata)}")
    keep = np.isfinite(x)
    labels = None if strata is None else [s for s, k in zip(strata, keep, strict=True) if k]
    x = x[keep]
    if x.size == 0:
        return float("nan"), float("nan")
    if x.size == 1:
        return float(x[0]), float(x[0])
    groups = _strata_index(x.size, labels)
    rng = np.random.default_rng(seed)
    picks = [g[rng.integers(0, g.size, size=(n_resamples, g.size))] for g in groups]
    resampled = x[np.concatenate(picks, axis=1)]
    if statistic is np.mean:
        stats = resampled.mean(axis=1)
    elif statistic is iqm:  # vectorised: sort each resample, trim a quarter at each end
        cut = int(0.25 * x.size)
        stats = np.sort(resampled, axis=1)[:, cut : x.size - cut].mean(axis=1)
    else:
        stats = np.array([statistic(row) for row in resampled])
    a = (1.0 - level) / 2.0
    return float(np.quantile(stats, a)), float(np.quantile(stats, 1.0 - a))


def bootstrap_ci(
    values: Sequence[float] | np.ndarray, n_resamples: int = N_RESAMPLES, level: float = LEVEL, seed: int = 0
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean (one stratum); see :func:`stratified_bootstrap_ci`."""
    return stratified_bootstrap_ci(values, np.mean, None, n_resamples, level, seed)


def newcombe_paired_interval(
    x: Sequence[Any] | np.ndarray, y: Sequence[Any] | np.ndarray, level: float = LEVEL
) -> tuple[float, float]:
    """Interval of the difference of two paired rates ``p_x - p_y`` (Newcombe 1998, method 10).

    Built from the Wilson intervals of both rates and the phi correlation of the pairs, so it stays honest
    when both rates are 0 or 1 (20/20 against 20/20 gives about [-0.16, 0.16]).

    Args:
        x: Outcomes (bool / 0-1) of policy X, one per seed.
        y: Outcomes of policy Y on the same seeds.
        level: Confidence level in (0, 1).

    Raises:
        ValueError: For sequences of different or zero length.
    """
    a_x = np.asarray(x, dtype=bool)
    a_y = np.asarray(y, dtype=bool)
    if a_x.size != a_y.size or a_x.size == 0:
        raise ValueError(f"x and y must be non-empty and paired, got lengths {a_x.size} and {a_y.size}")
    n = a_x.size
    both = int(np.sum(a_x & a_y))
    only_x = int(np.sum(a_x & ~a_y))
    only_y = int(np.sum(~a_x & a_y))
    neither = n - both - only_x - only_y
    p1, p2 = (both + only_x) / n, (both + only_y) / n
    l1, u1 = wilson_interval(both + only_x, n, level)
    l2, u2 = wilson_interval(both + only_y, n, level)
    denom = (both + only_x) * (only_y + neither) * (both + only_y) * (only_x + neither)
    phi = (both * neither - only_x * only_y) / math.sqrt(denom) if denom > 0 else 0.0
    theta = p1 - p2
    delta = math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    eps = math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    return max(-1.0, theta - delta), min(1.0, theta + eps)


def newcombe_interval(k1: int, n1: int, k2: int, n2: int, level: float = LEVEL) -> tuple[float, float]:
    """Interval of ``k1/n1 - k2/n2`` for two independent rates (Newcombe 1998, hybrid score method 10).

    Used where the samples share no seeds, e.g. our success rate against a paper's reported trials.

    Raises:
        ValueError: For counts outside [0, n] or n < 1 (see :func:`wilson_interval`).
    """
    l1, u1 = wilson_interval(k1, n1, level)
    l2, u2 = wilson_interval(k2, n2, level)
    p1, p2 = k1 / n1, k2 / n2
    d = p1 - p2
    return d - math.sqrt((p1 - l1) ** 2 + (u2 - p2) ** 2), d + math.sqrt((u1 - p1) ** 2 + (p2 - l2) ** 2)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """``P(X > Y) + P(X = Y) / 2`` over all pairs of an X value and a Y value (Mann-Whitney, as rliable)."""
    gt = (x[:, None] > y[None, :]).mean()
    eq = (x[:, None] == y[None, :]).mean()
    return float(gt + 0.5 * eq)


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A paired comparison of policy X against policy Y on one metric, oriented so that positive is better.

    Attributes:
        metric: Metric name.
        n: Number of shared seeds used.
        x: X's estimate (mean or rate).
        y: Y's estimate.
        difference: ``x - y`` (raw units; see ``higher_is_better`` for which sign is better).
        ci: Interval of the difference.
        prob_improvement: Probability that X is better than Y on a random pair of episodes.
        prob_improvement_ci: Paired-bootstrap interval of ``prob_improvement``.
        higher_is_better: Orientation of the metric.
        margin: Equivalence margin on the difference used by :attr:`verdict`.
    """

    metric: str
    n: int
    x: float
    y: float
    difference: float
    ci: tuple[float, float]
    prob_improvement: float
    prob_improvement_ci: tuple[float, float]
    higher_is_better: bool
    margin: float

    @property
    def verdict(self) -> str:
        """What the interval supports: ``"better"``, ``"worse"``, ``"matches"`` or ``"inconclusive"``.

        ``better`` / ``worse`` when the interval excludes 0; ``matches`` when it lies inside
        ``[-margin, margin]``; else ``inconclusive`` (no claim is supported).
        """
        lo, hi = self.ci
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return "inconclusive"
        if lo > 0 or hi < 0:
            return "better" if (lo > 0) == self.higher_is_better else "worse"
        if -self.margin <= lo and hi <= self.margin:
            return "matches"
        return "inconclusive"


def paired_comparison(
    x: Sequence[Any],
    y: Sequence[Any],
    metric: str = "metric",
    higher_is_better: bool = True,
    binary: bool = False,
    margin: float = 0.0,
    n_resamples: int = N_RESAMPLES,
    level: float = LEVEL,
    seed: int = 0,
) -> Comparison:
    """Compare X with Y on paired values (same seeds, same order); pairs with a missing side are dropped.

    Args:
        x: Values of policy X, one per seed.
        y: Values of policy Y on the same seeds.
        metric: Name kept in the result.
        higher_is_better: Orientation (success: True; time, path length: False).
        binary: True for rates: the difference gets Newcombe's paired score interval.
        margin: Equivalence margin for the ``"matches"`` verdict (in the metric's units), >= 0.
        n_resamples: Bootstrap resamples, >= 100.
        level: Confidence level in (0, 1).
        seed: Seed of the resampling.

    Raises:
        ValueError: For sequences of different lengths, no complete pair, or a negative margin.
    """
    if len(x) != len(y):
        raise ValueError(f"x and y must be paired (same length), got {len(x)} and {len(y)}")
    if margin < 0:
        raise ValueError(f"margin must be >= 0, got {margin}")
    if n_resamples < 100:
        raise ValueError(f"n_resamples must be >= 100, got {n_resamples}")
    _check_level(level)
    ax = np.array([np.nan if v is None else float(v) for v in x], dtype=np.float64)
    ay = np.array([np.nan if v is None else float(v) for v in y], dtype=np.float64)
    keep = np.isfinite(ax) & np.isfinite(ay)
    ax, ay = ax[keep], ay[keep]
    if ax.size == 0:
        raise ValueError(f"no seed has a value of {metric!r} for both policies")
    sign = 1.0 if higher_is_better else -1.0
    diff = ax - ay
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, ax.size, size=(n_resamples, ax.size))
    a = (1.0 - level) / 2.0
    if binary:
        ci = newcombe_paired_interval(ax > 0.5, ay > 0.5, level)
    else:
        boot = diff[idx].mean(axis=1)
        ci = (float(np.quantile(boot, a)), float(np.quantile(boot, 1.0 - a)))
    pi = probability_of_improvement(sign * ax, sign * ay)
    gt = (sign * ax[:, None] > sign * ay[None, :]).astype(np.float64)
    eq = (ax[:, None] == ay[None, :]).astype(np.float64)
    score = gt + 0.5 * eq
    boot_pi = np.array([score[np.ix_(row, row)].mean() for row in idx])
    return Comparison(
        metric=metric,
        n=int(ax.size),
        x=float(ax.mean()),
        y=float(ay.mean()),
        difference=float(diff.mean()),
        ci=ci,
        prob_improvement=pi,
        prob_improvement_ci=(float(np.quantile(boot_pi, a)), float(np.quantile(boot_pi, 1.0 - a))),
        higher_is_better=higher_is_better,
        margin=margin,
    )


def format_interval(value: float | None, ci: Sequence[float | None] | None, fmt: str = "{:.2f}") -> str:
    """``"0.95 [0.76, 0.99]"``; ``"-"`` for a missing value; the value alone without an interval."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if not ci or ci[0] is None or ci[1] is None or not all(math.isfinite(float(c)) for c in ci):  # type: ignore[arg-type]
        return fmt.format(value)
    return f"{fmt.format(value)} [{fmt.format(ci[0])}, {fmt.format(ci[1])}]"
