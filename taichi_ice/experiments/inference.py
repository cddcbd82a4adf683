"""Statistical inference for the studies: proportions, paired runs, many claims, censored
times. NumPy and the standard library only; the tests hold every function against SciPy and
statsmodels (independent implementations) on seeded data and on cases with known answers.

    from taichi_ice.experiments import inference
    inference.clopper_pearson(8, 8)            # (0.631, 1.0): 8 of 8 layouts jammed
    inference.mcnemar(released_a, released_b)  # paired 0/1 outcomes on the same layouts
    inference.wilcoxon(x, y)                   # paired continuous outcomes
    inference.holm(p_values)                   # a family of claims
    inference.kaplan_meier(times, observed)    # time to release, censored at the run's end

Why these (issue 31): a percentile bootstrap of 8 binary outcomes gives the zero-width
interval [1, 1]; an exact (Clopper-Pearson) or Wilson interval does not. Runs of two models
on the same layouts are paired: the exact McNemar test (a binomial test of the discordant
pairs) for binary outcomes, the exact sign test or the Wilcoxon signed-rank test for
continuous ones. Holm's step-down adjustment keeps the family-wise error of many claims at
alpha. A run that ends with a jam held is censored, not "not released": Kaplan-Meier.

References: Clopper & Pearson (1934), Biometrika 26, 404; Wilson (1927), JASA 22, 209;
McNemar (1947), Psychometrika 12, 153; Wilcoxon (1945), Biometrics Bulletin 1, 80; Holm
(1979), Scand. J. Statist. 6, 65; Kaplan & Meier (1958), JASA 53, 457; Greenwood (1926).
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

__all__ = [
    "binomial_n",
    "binomial_pmf",
    "binomial_power",
    "binomial_test",
    "clopper_pearson",
    "holm",
    "kaplan_meier",
    "ks_2samp",
    "mcnemar",
    "mcnemar_pairs",
    "mcnemar_power",
    "paired_pairs",
    "quantile_shift",
    "sign_test",
    "wilcoxon",
    "wilson",
]

# Outcomes whose probability is within this factor of the observed one's count as "as
# likely" in the two-sided binomial test (round-off of equal probabilities; SciPy's choice).
_AS_LIKELY = 1.0 + 1e-7
# Largest sample the signed-rank test takes exactly (its distribution by counting subsets);
# beyond it, and with tied or zero differences, the normal approximation.
WILCOXON_EXACT_MAX = 50


def binomial_pmf(n: int, p: float) -> np.ndarray:
    """``(n + 1,)`` probabilities of 0..n successes in ``n`` trials of probability ``p``
    (through log-factorials: relative round-off about eps ln(n!), 3e-12 at n = 2,000)."""
    k = np.arange(n + 1)
    if p <= 0.0 or p >= 1.0:
        return (k == (0 if p <= 0.0 else n)).astype(float)
    log_factorial = np.array([math.lgamma(i + 1.0) for i in range(n + 1)])
    log_choose = log_factorial[n] - log_factorial - log_factorial[::-1]
    return np.exp(log_choose + k * math.log(p) + (n - k) * math.log1p(-p))


def binomial_test(k: int, n: int, p: float = 0.5) -> float:
    """Two-sided exact binomial test of ``k`` successes in ``n`` trials against ``p``: the
    probability of every outcome no more likely than ``k`` (1.0 when ``n`` is 0)."""
    if not 0 <= k <= n:
        raise ValueError(f"binomial_test: k = {k} must be within 0..n = {n}")
    if n == 0:
        return 1.0
    pmf = binomial_pmf(n, p)
    return float(min(1.0, pmf[pmf <= pmf[k] * _AS_LIKELY].sum()))


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) interval of a proportion ``k / n``: the ``p`` at which ``k``
    or more (the low end), or ``k`` or fewer (the high end), successes have probability
    ``(1 - confidence) / 2``. Never narrower than its confidence; ``(0, 1)`` for ``n`` 0."""
    if not 0 <= k <= n:
        raise ValueError(f"clopper_pearson: k = {k} must be within 0..n = {n}")
    tail = (1.0 - confidence) / 2.0

    def at_most_k(p: float) -> float:
        return float(binomial_pmf(n, p)[: k + 1].sum())

    def solve(f, target: float) -> float:  # f decreasing in p on [0, 1]
        lo, hi = 0.0, 1.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if f(mid) > target:
                lo = mid
            else:
                hi = mid
            if hi - lo < 1e-15:
                break
        return 0.5 * (lo + hi)

    # P(X <= k - 1) = 1 - tail, i.e. P(X >= k) = tail.
    low = 0.0 if k == 0 else solve(lambda p: float(binomial_pmf(n, p)[:k].sum()), 1.0 - tail)
    high = 1.0 if k == n else solve(at_most_k, tail)
    return low, high


def wilson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson's score interval of a proportion ``k / n`` (without continuity correction);
    ``(0, 1)`` for ``n`` 0."""
    if not 0 <= k <= n:
        raise ValueError(f"wilson: k = {k} must be within 0..n = {n}")
    if n == 0:
        return 0.0, 1.0
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    z2 = z * z
    centre = (k + z2 / 2.0) / (n + z2)
    half = z / (n + z2) * math.sqrt(k * (n - k) / n + z2 / 4.0)
    return max(0.0, centre - half), min(1.0, centre + half)


def mcnemar(a, b) -> dict:
    """Paired 0/1 outcomes (``a[i]``, ``b[i]`` of unit i): the exact McNemar test, a
    two-sided binomial test at 1/2 of the pairs that differ.

    Returns ``{"n", "a", "b", "only_a", "only_b", "p"}``: units, successes of each, the
    discordant counts and the p-value (1.0 when no pair differs).
    """
    a, b = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"mcnemar: paired outcomes of shapes {a.shape} and {b.shape}")
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    return {
        "n": int(a.size),
        "a": int(a.sum()),
        "b": int(b.sum()),
        "only_a": only_a,
        "only_b": only_b,
        "p": binomial_test(only_a, only_a + only_b, 0.5),
    }


def _paired_differences(x, y) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    d = x if y is None else np.asarray(y, dtype=float) - x
    if y is not None and np.shape(y) != x.shape:
        raise ValueError(f"paired values of shapes {x.shape} and {np.shape(y)}")
    return d[np.isfinite(d)]


def sign_test(x, y=None) -> dict:
    """The exact sign test of paired values (``y - x``, or the differences ``x``): how many
    are positive among those not zero, against 1/2. Returns ``{"n", "positive", "p"}``."""
    d = _paired_differences(x, y)
    d = d[d != 0.0]
    positive = int(np.sum(d > 0.0))
    return {"n": int(d.size), "positive": positive, "p": binomial_test(positive, d.size, 0.5)}


def _average_ranks(values: np.ndarray) -> np.ndarray:
    """Ranks 1..n of ``values``, ties sharing their mean rank."""
    order = np.argsort(values, kind="stable")
    ranks = np.empty(values.size)
    ranks[order] = np.arange(1, values.size + 1)
    for v in np.unique(values):
        same = values == v
        if same.sum() > 1:
            ranks[same] = ranks[same].mean()
    return ranks


def wilcoxon(x, y=None, exact: bool | None = None) -> dict:
    """The Wilcoxon signed-rank test of paired values (``y - x``, or the differences
    ``x``), two-sided; zero differences are dropped (Wilcoxon's own rule).

    Exact (the null distribution of the positive rank sum, by counting subsets of ranks)
    when ``exact`` or, by default, for at most ``WILCOXON_EXACT_MAX`` differences without
    ties; else the normal approximation with the tie correction, no continuity correction.

    Returns ``{"n", "statistic", "p", "method"}``: the differences used, the smaller of the
    positive and negative rank sums, the p-value and "exact" or "normal".
    """
    d = _paired_differences(x, y)
    d = d[d != 0.0]
    n = d.size
    if n == 0:
        return {"n": 0, "statistic": 0.0, "p": 1.0, "method": "exact"}
    ranks = _average_ranks(np.abs(d))
    r_plus = float(ranks[d > 0.0].sum())
    total = n * (n + 1) / 2.0
    statistic = min(r_plus, total - r_plus)
    tied = np.unique(np.abs(d)).size < n
    if exact is None:
        exact = n <= WILCOXON_EXACT_MAX and not tied
    if exact:
        if tied:
            raise ValueError("wilcoxon: the exact distribution needs differences without ties")
        # counts[s]: subsets of the ranks 1..n that sum to s (each equally likely under H0).
        counts = np.zeros(int(total) + 1)
        counts[0] = 1.0
        for r in range(1, n + 1):
            counts[r:] = counts[r:] + counts[:-r].copy()
        cdf = np.cumsum(counts) / 2.0**n
        p = min(1.0, 2.0 * float(cdf[round(statistic)]))
        return {"n": int(n), "statistic": statistic, "p": p, "method": "exact"}
    _, tie_counts = np.unique(np.abs(d), return_counts=True)
    var = n * (n + 1) * (2 * n + 1) / 24.0 - float(np.sum(tie_counts**3 - tie_counts)) / 48.0
    z = (statistic - total / 2.0) / math.sqrt(var) if var > 0.0 else 0.0
    p = min(1.0, 2.0 * NormalDist().cdf(-abs(z)))
    return {"n": int(n), "statistic": statistic, "p": p, "method": "normal"}


def holm(p) -> list[float]:
    """Holm's step-down adjusted p-values, in the order given: a claim holds at family-wise
    error alpha where its adjusted p is at most alpha."""
    p = np.asarray(p, dtype=float)
    order = np.argsort(p, kind="stable")
    m = p.size
    adjusted = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adjusted[i] = running
    return adjusted.tolist()


def kaplan_meier(times, observed) -> dict:
    """The Kaplan-Meier estimate of the survival function of ``times`` (s), ``observed``
    False where a time is censored (the run ended first), with Greenwood's standard error.

    Returns ``{"times", "survival", "se", "at_risk", "events", "median"}``: at each distinct
    observed time, the survival just after it, its standard error, the units at risk and
    the events; the median is the first time survival falls to 0.5 or below (Klein &
    Moeschberger; SAS and statsmodels take the first below 0.5), None if it never does
    (the runs ended, censored, before half the events).
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(observed, dtype=bool)
    if t.shape != e.shape:
        raise ValueError(f"kaplan_meier: times {t.shape} and observed {e.shape} differ in shape")
    if np.any(~np.isfinite(t)):
        raise ValueError("kaplan_meier: every time must be finite (censor at the run's end)")
    event_times = np.unique(t[e])
    survival, se, at_risk, events = [], [], [], []
    s, greenwood = 1.0, 0.0
    for u in event_times:
        n_u = int(np.sum(t >= u))
        d_u = int(np.sum((t == u) & e))
        s *= 1.0 - d_u / n_u
        greenwood += d_u / (n_u * (n_u - d_u)) if n_u > d_u else math.inf
        survival.append(s)
        se.append(s * math.sqrt(greenwood) if math.isfinite(greenwood) else 0.0)
        at_risk.append(n_u)
        events.append(d_u)
    below = [u for u, v in zip(event_times, survival) if v <= 0.5]
    return {
        "times": event_times.tolist(),
        "survival": survival,
        "se": se,
        "at_risk": at_risk,
        "events": events,
        "median": float(below[0]) if below else None,
    }


# --------------------------------------------------------------------------------------------
# Power: how many units a claim needs
# --------------------------------------------------------------------------------------------


def mcnemar_power(n: int, only_a: float, only_b: float, alpha: float = 0.05) -> float:
    """The power of the exact McNemar test (``mcnemar``) at ``alpha`` with ``n`` pairs,
    where a pair succeeds for A alone with probability ``only_a`` and for B alone with
    ``only_b``: exact, summed over the number of discordant pairs and their split."""
    if not (0.0 <= only_a and 0.0 <= only_b and only_a + only_b <= 1.0):
        raise ValueError(f"mcnemar_power: discordant probabilities {only_a}, {only_b}")
    discordant = only_a + only_b
    if discordant == 0.0 or n == 0:
        return 0.0
    share = only_a / discordant
    power = 0.0
    for m, p_m in enumerate(binomial_pmf(n, discordant)):
        if m == 0 or p_m < 1e-16:
            continue
        # binomial_test(j, m, 1/2) for every split j at once: the null law is symmetric and
        # unimodal, so the splits no more likely than j are the two tails beyond it.
        below = np.cumsum(binomial_pmf(m, 0.5))
        j = np.arange(m + 1)
        p_value = np.minimum(1.0, 2.0 * below[np.minimum(j, m - j)])
        p_value[2 * j == m] = 1.0
        power += p_m * float(binomial_pmf(m, share)[p_value <= alpha].sum())
    return power


def binomial_power(n: int, p: float, p0: float = 0.5, alpha: float = 0.05) -> float:
    """The power of the two-sided exact binomial test (``binomial_test``) of ``p0`` at
    ``alpha`` with ``n`` trials whose true probability is ``p``: exact, the probability under
    ``p`` of every count the test rejects."""
    if n == 0:
        return 0.0
    # binomial_test(k, n, p0) for every k at once: the mass of the outcomes no more likely.
    null = binomial_pmf(n, p0)
    order = np.sort(null)
    p_value = np.cumsum(order)[np.searchsorted(order, null * _AS_LIKELY, side="right") - 1]
    return float(binomial_pmf(n, p)[np.minimum(1.0, p_value) <= alpha].sum())


def binomial_n(
    p: float, p0: float = 0.5, alpha: float = 0.05, power: float = 0.8, most: int = 20_000
) -> int | None:
    """The fewest trials at which the exact binomial test of ``p0`` reaches ``power`` when
    the true probability is ``p`` (``binomial_power``; its power is not monotone in n, so the
    first n that reaches it); None if ``p == p0`` or beyond ``most``."""
    if p == p0:
        return None
    nd = NormalDist()
    za, zb = nd.inv_cdf(1.0 - alpha / 2.0), nd.inv_cdf(power)
    guess = ((za * math.sqrt(p0 * (1 - p0)) + zb * math.sqrt(p * (1 - p))) / (p - p0)) ** 2
    n = max(1, int(guess / 2))
    while n <= most:
        if binomial_power(n, p, p0, alpha) >= power:
            return n
        n += 1 if n < 400 else max(1, n // 200)
    return None


def mcnemar_pairs(
    only_a: float, only_b: float, alpha: float = 0.05, power: float = 0.8, most: int = 100_000
) -> int | None:
    """The fewest pairs at which the exact McNemar test reaches ``power`` (``mcnemar_power``),
    searched up from Connor's (1987) normal approximation's half; None beyond ``most``."""
    discordant, diff = only_a + only_b, abs(only_a - only_b)
    if diff == 0.0:
        return None
    nd = NormalDist()
    za, zb = nd.inv_cdf(1.0 - alpha / 2.0), nd.inv_cdf(power)
    guess = (za * math.sqrt(discordant) + zb * math.sqrt(discordant - diff**2)) ** 2 / diff**2
    n = max(1, int(guess / 2))
    while n <= most:
        if mcnemar_power(n, only_a, only_b, alpha) >= power:
            return n
        n += max(1, n // 50)
    return None


def paired_pairs(
    effect: float, sd: float, alpha: float = 0.05, power: float = 0.8, test: str = "wilcoxon"
) -> int:
    """Pairs a two-sided paired test needs to find a mean difference ``effect`` between
    pairs whose differences have standard deviation ``sd``: the normal approximation with
    Guenther's (1981) correction for the t test (``test="t"``), divided by the Wilcoxon test's
    asymptotic relative efficiency for normal differences, 3 / pi (``"wilcoxon"``)."""
    if sd <= 0.0 or effect == 0.0:
        raise ValueError(f"paired_pairs: effect {effect} and sd {sd} must be non-zero")
    nd = NormalDist()
    za, zb = nd.inv_cdf(1.0 - alpha / 2.0), nd.inv_cdf(power)
    n = ((za + zb) * sd / effect) ** 2 + za**2 / 2.0
    if test == "wilcoxon":
        n /= 3.0 / math.pi
    elif test != "t":
        raise ValueError(f'paired_pairs: test must be "t" or "wilcoxon", not {test!r}')
    return math.ceil(n)


# --------------------------------------------------------------------------------------------
# Two distributions: the same layouts at two steps (issue 31's step bias)
# --------------------------------------------------------------------------------------------


def ks_2samp(x, y) -> dict:
    """The two-sample Kolmogorov-Smirnov test, two-sided, exact: ``D``, the largest gap
    between the two empirical distribution functions, and the probability that two samples
    of these sizes from one continuous law differ by ``D`` or more (a walk over the merged
    order that stays inside the band ``|i/n - j/m| < D``; Hodges 1957). NaNs are dropped.

    Returns ``{"n", "m", "statistic", "p"}``.
    """
    x = np.sort(np.asarray(x, dtype=float)[np.isfinite(np.asarray(x, dtype=float))])
    y = np.sort(np.asarray(y, dtype=float)[np.isfinite(np.asarray(y, dtype=float))])
    n, m = x.size, y.size
    if n == 0 or m == 0:
        raise ValueError(f"ks_2samp: samples of {n} and {m} values")
    grid = np.concatenate([x, y])
    gap = np.abs(
        np.searchsorted(x, grid, side="right") * m - np.searchsorted(y, grid, side="right") * n
    )
    h = int(gap.max())  # D n m, an integer
    # inside[j]: probability that a uniform walk over the merged order reached (i, j) without
    # leaving the band |i m - j n| < h; a step takes an x with probability (n - i) / rest.
    inside = np.zeros(m + 1)
    inside[0] = 1.0
    for j in range(1, m + 1):  # the first row: j values of y, none of x
        inside[j] = inside[j - 1] * (m - j + 1) / (n + m - j + 1) if j * n < h else 0.0
    for i in range(1, n + 1):
        new = np.zeros(m + 1)
        for j in range(m + 1):
            if abs(i * m - j * n) >= h:
                continue
            rest = n + m - i - j
            from_x = inside[j] * (n - i + 1) / (rest + 1)
            from_y = new[j - 1] * (m - j + 1) / (rest + 1) if j > 0 else 0.0
            new[j] = from_x + from_y
        inside = new
    return {
        "n": n,
        "m": m,
        "statistic": h / (n * m),
        "p": float(min(1.0, max(0.0, 1.0 - inside[m]))),
    }


def quantile_shift(
    base,
    other,
    quantiles=(0.1, 0.5, 0.9),
    confidence: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> list[dict]:
    """The shift of ``other``'s quantiles from ``base``'s, for paired values (the same
    layouts in two runs: unit i is ``base[i]``, ``other[i]``), with percentile bootstrap
    intervals that resample the units (pairs with a NaN dropped).

    Returns ``[{"q", "shift", "low", "high"}]``, one per quantile.
    """
    a, b = np.asarray(base, dtype=float), np.asarray(other, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"quantile_shift: paired values of shapes {a.shape} and {b.shape}")
    keep = np.isfinite(a) & np.isfinite(b)
    a, b = a[keep], b[keep]
    if a.size == 0:
        raise ValueError("quantile_shift: no pair with both values")
    qs = np.asarray(quantiles, dtype=float)
    rows = np.random.default_rng(seed).integers(0, a.size, size=(resamples, a.size))
    shifts = np.quantile(b[rows], qs, axis=1) - np.quantile(a[rows], qs, axis=1)
    tail = (1.0 - confidence) / 2.0
    low, high = np.quantile(shifts, [tail, 1.0 - tail], axis=1)
    point = np.quantile(b, qs) - np.quantile(a, qs)
    return [
        {"q": float(q), "shift": float(s), "low": float(lo), "high": float(hi)}
        for q, s, lo, hi in zip(qs, point, low, high)
    ]
