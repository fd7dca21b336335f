"""Small statistics over seeds (numpy only): how sure a mean is, and how often one method's seed beats another's.

Every figure here is over seeds: one score per training seed (a seed's score being the mean return of its
last three evaluations). The intervals are percentile bootstraps, deterministic for a given `seed`.
"""
import numpy as np


def _interval(values, confidence: float) -> tuple:
    """The central `confidence` share of `values`: (low, high) percentiles."""
    tail = (1 - confidence) / 2 * 100
    low, high = np.percentile(values, [tail, 100 - tail])
    return float(low), float(high)


def bootstrap_ci(scores, confidence=0.95, resamples=10000, seed=0) -> tuple:
    """Interval of the mean over seeds: draw the seeds again with replacement `resamples` times and keep the
    central `confidence` share of the means. One score gives (score, score)."""
    scores = np.asarray(scores, dtype=float)
    picks = np.random.default_rng(seed).integers(0, len(scores), (resamples, len(scores)))
    return _interval(scores[picks].mean(axis=1), confidence)


def _wins(x, y):
    """P(X > Y) over the last axis of x against the last axis of y, all pairs, ties counting 1/2."""
    x, y = x[..., :, None], y[..., None, :]
    return ((x > y) + 0.5 * (x == y)).mean(axis=(-2, -1))


def probability_of_improvement(x, y) -> float:
    """The probability that a seed of X scores above a seed of Y: the share of all pairs (x_i, y_j) with
    x_i > y_j, ties counting 1/2 (the Mann-Whitney form of rliable's probability of improvement).
    0.5: no difference; 1: every seed of X beats every seed of Y."""
    return float(_wins(np.asarray(x, dtype=float), np.asarray(y, dtype=float)))


def probability_of_improvement_ci(x, y, confidence=0.95, resamples=10000, seed=0) -> tuple:
    """Interval of probability_of_improvement(x, y): a stratified percentile bootstrap that draws the seeds
    of x and of y again, each with replacement and apart from each other."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    rng = np.random.default_rng(seed)
    x_picks, y_picks = rng.integers(0, len(x), (resamples, len(x))), rng.integers(0, len(y), (resamples, len(y)))
    return _interval(_wins(x[x_picks], y[y_picks]), confidence)


def expert_normalised(score, expert):
    """A score as a share of the expert's score on the same env (1: as good as the expert)."""
    return score / expert
