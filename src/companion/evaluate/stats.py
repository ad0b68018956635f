"""The statistics of an evaluation: medians with bootstrap intervals, exact binomial intervals
for the share of safe episodes, and paired comparisons against a reference controller.

All intervals are 95 % and deterministic (the bootstrap draws from a fixed seed), so the same
episodes give the same summary whatever ran them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import stats

#: Metrics summarised, and whether lower is better for each.
METRICS = {"rms_slot_error_m": True, "rmse_rho_m": True, "rmse_alpha_rad": True,
           "min_person_distance_m": False}
LEVEL = 0.95
RESAMPLES = 2000
SEED = 0


def median_ci(values: Sequence[float]) -> tuple[float, float, float]:
    """``(median, low, high)``: the median and its percentile-bootstrap 95 % interval
    (NaN bounds with fewer than two finite values)."""
    x = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    if len(x) < 2 or np.all(x == x[0]):
        m = float(np.median(x))
        return (m, math.nan, math.nan) if len(x) < 2 else (m, m, m)
    res = stats.bootstrap((x,), np.median, confidence_level=LEVEL, n_resamples=RESAMPLES,
                          method="percentile", random_state=np.random.default_rng(SEED),
                          vectorized=True)
    return (float(np.median(x)), float(res.confidence_interval.low),
            float(res.confidence_interval.high))


def median_sign_ci(values: Sequence[float]) -> tuple[float, float, float]:
    """``(median, low, high)``: the median and its distribution-free 95 % interval from the
    order statistics (the sign test's: at least 95 % coverage for any continuous
    distribution). NaN bounds where no such interval exists (fewer than 6 values): too few
    pairs to tell."""
    x = np.sort([v for v in values if math.isfinite(v)])
    n = len(x)
    if n == 0:
        return math.nan, math.nan, math.nan
    # the largest k with P(B < k) <= 2.5 %, B ~ Binomial(n, 1/2): [x_(k), x_(n-k+1)]
    k = int(stats.binom.ppf((1.0 - LEVEL) / 2.0, n, 0.5))
    while k > 0 and stats.binom.cdf(k - 1, n, 0.5) > (1.0 - LEVEL) / 2.0:
        k -= 1
    median = float(np.median(x))
    if k < 1:
        return median, math.nan, math.nan
    return median, float(x[k - 1]), float(x[n - k])


def binomial_ci(k: int, n: int) -> tuple[float, float]:
    """The exact (Clopper-Pearson) 95 % interval of a share of ``k`` in ``n``."""
    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=LEVEL, method="exact")
    return float(ci.low), float(ci.high)


def describe(rows: Sequence[dict], metric: str) -> dict:
    """Median with its interval, the 90th percentile towards the worse side (``p90``: the
    10th percentile where higher is better) and the worst value of ``metric`` over ``rows``
    (the largest where lower is better, else the smallest), with the key of the episode that
    produced it."""
    finite = [r for r in rows if math.isfinite(r[metric])]
    median, low, high = median_ci([r[metric] for r in finite])
    out = {"median": median, "low": low, "high": high, "p90": math.nan, "worst": math.nan,
           "worst_episode": None, "n": len(finite)}
    if finite:
        lower_better = METRICS[metric]
        worst = (max if lower_better else min)(finite, key=lambda r: r[metric])
        out.update(p90=float(np.percentile([r[metric] for r in finite],
                                           90 if lower_better else 10)),
                   worst=worst[metric], worst_episode=worst["episode"])
    return out


def safe_share(rows: Sequence[dict]) -> dict:
    """The share of safe episodes (:func:`companion.evaluate.rows.summary_row`'s ``safe``)
    with its exact interval."""
    k, n = sum(bool(r["safe"]) for r in rows), len(rows)
    low, high = binomial_ci(k, n)
    return {"safe": k, "n": n, "share": k / n if n else math.nan, "low": low, "high": high}


def paired(rows: Sequence[dict], reference: Sequence[dict], metric: str) -> dict:
    """``rows`` against ``reference`` on the same episodes (matched by ``pair``): the median
    difference (``rows`` minus ``reference``) with its distribution-free interval
    (:func:`median_sign_ci`), the share of pairs where ``rows`` is better, and a verdict only
    where the interval excludes zero."""
    ref = {r["pair"]: r[metric] for r in reference}
    diffs = [r[metric] - ref[r["pair"]] for r in rows
             if r["pair"] in ref and math.isfinite(r[metric]) and math.isfinite(ref[r["pair"]])]
    median, low, high = median_sign_ci(diffs)
    lower_better = METRICS[metric]
    better = [d < 0.0 if lower_better else d > 0.0 for d in diffs]
    verdict = "no difference shown"
    if math.isfinite(low) and (low > 0.0 or high < 0.0):
        verdict = "better" if (high < 0.0) == lower_better else "worse"
    return {"pairs": len(diffs), "median_difference": median, "low": low, "high": high,
            "share_better": float(np.mean(better)) if better else math.nan,
            "verdict": verdict}


def summarize(rows: Sequence[dict], reference: str) -> dict:
    """Per condition (sensing profile and motion group) and controller: every metric of
    :data:`METRICS` described, the safe share, and the paired comparison with the
    ``reference`` controller."""
    out: dict = {}
    conditions = sorted({(r["sensing"], r["group"]) for r in rows})
    for sensing, group in conditions:
        here = [r for r in rows if r["sensing"] == sensing and r["group"] == group]
        ref_rows = [r for r in here if r["controller"] == reference]
        per: dict = {}
        for controller in dict.fromkeys(r["controller"] for r in here):
            mine = [r for r in here if r["controller"] == controller]
            entry = {"episodes": len(mine), "safe": safe_share(mine),
                     "metrics": {m: describe(mine, m) for m in METRICS}}
            if controller != reference and ref_rows:
                entry["paired"] = {m: paired(mine, ref_rows, m) for m in METRICS}
            per[controller] = entry
        out[f"{sensing} / {group}"] = per
    return out
