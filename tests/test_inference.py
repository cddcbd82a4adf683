"""experiments.inference against SciPy and statsmodels (independent implementations, test-only
dependencies) on seeded data, and against answers known in closed form. No Taichi."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from taichi_ice.experiments import inference

SEED = 20261126


def test_exact_intervals_of_the_study_s_proportions_are_the_closed_forms():
    """k = 0 and k = n have closed forms: (alpha/2)^(1/n) and 1 - (alpha/2)^(1/n). 8 of 8
    layouts jammed is [0.631, 1] and 0 of 16 is [0, 0.206] (issue 31's numbers), where a
    percentile bootstrap gave [1, 1] and [0, 0]."""
    low, high = inference.clopper_pearson(8, 8)
    assert high == 1.0 and low == pytest.approx(0.025 ** (1 / 8), rel=1e-12)
    assert round(low, 3) == 0.631
    low, high = inference.clopper_pearson(0, 16)
    assert low == 0.0 and high == pytest.approx(1 - 0.025 ** (1 / 16), rel=1e-12)
    assert round(high, 3) == 0.206
    assert inference.clopper_pearson(0, 0) == (0.0, 1.0)


@pytest.mark.parametrize("confidence", [0.9, 0.95, 0.99])
def test_clopper_pearson_and_wilson_equal_scipy_s(confidence):
    rng = np.random.default_rng(SEED)
    for n in (1, 2, 7, 16, 64, 300, 2000):
        for k in sorted({0, n, *rng.integers(0, n + 1, 4).tolist()}):
            ref = stats.binomtest(k, n).proportion_ci(confidence, method="exact")
            got = inference.clopper_pearson(k, n, confidence)
            assert got == pytest.approx((ref.low, ref.high), abs=1e-10), (k, n)
            ref = stats.binomtest(k, n).proportion_ci(confidence, method="wilson")
            got = inference.wilson(k, n, confidence)
            assert got == pytest.approx((ref.low, ref.high), abs=1e-12), (k, n)


def test_intervals_agree_with_statsmodels():
    from statsmodels.stats.proportion import proportion_confint

    for k, n in ((0, 16), (3, 16), (8, 8), (31, 64), (64, 64)):
        for method, ours in (("beta", inference.clopper_pearson), ("wilson", inference.wilson)):
            ref = proportion_confint(k, n, alpha=0.05, method=method)
            assert ours(k, n) == pytest.approx(ref, abs=1e-10), (method, k, n)


def test_the_exact_interval_covers_at_least_its_confidence():
    """Clopper-Pearson's defining property, computed from the binomial law itself: for any
    true p the probability that the interval holds p is at least 95 %."""
    n = 24
    intervals = [inference.clopper_pearson(k, n) for k in range(n + 1)]
    for p in np.linspace(0.01, 0.99, 41):
        pmf = inference.binomial_pmf(n, p)
        covered = sum(pmf[k] for k, (lo, hi) in enumerate(intervals) if lo <= p <= hi)
        assert covered >= 0.95 - 1e-12, p


def test_binomial_test_equals_scipy_s():
    rng = np.random.default_rng(SEED)
    for n in (1, 5, 20, 101, 1000):
        for p in (0.5, 0.3, 0.9):
            for k in rng.integers(0, n + 1, 5):
                ref = stats.binomtest(int(k), n, p).pvalue
                assert inference.binomial_test(int(k), n, p) == pytest.approx(ref, rel=1e-9), (
                    k,
                    n,
                    p,
                )
    assert inference.binomial_test(0, 0) == 1.0
    with pytest.raises(ValueError, match="k = 5"):
        inference.binomial_test(5, 4)


def test_mcnemar_is_the_binomial_test_of_the_discordant_pairs():
    """10 discordant pairs, all one way: p = 2 / 2^10 exactly; statsmodels' exact McNemar
    on seeded paired outcomes gives the same p."""
    from statsmodels.stats.contingency_tables import mcnemar

    a = np.array([1] * 10 + [1] * 5 + [0] * 7, dtype=bool)
    b = np.array([0] * 10 + [1] * 5 + [0] * 7, dtype=bool)
    got = inference.mcnemar(a, b)
    assert (got["only_a"], got["only_b"], got["a"], got["b"]) == (10, 0, 15, 5)
    assert got["p"] == pytest.approx(2.0 / 2**10, rel=1e-12)
    rng = np.random.default_rng(SEED)
    for _ in range(20):
        n = int(rng.integers(5, 80))
        a = rng.random(n) < 0.5
        b = np.where(rng.random(n) < 0.7, a, rng.random(n) < 0.6)
        table = [[np.sum(a & b), np.sum(a & ~b)], [np.sum(~a & b), np.sum(~a & ~b)]]
        ref = mcnemar(table, exact=True).pvalue
        assert inference.mcnemar(a, b)["p"] == pytest.approx(ref, rel=1e-9)
    assert inference.mcnemar([1, 0], [1, 0])["p"] == 1.0


def test_sign_test_equals_statsmodels():
    from statsmodels.stats.descriptivestats import sign_test

    rng = np.random.default_rng(SEED)
    for n in (6, 17, 40):
        x = rng.normal(size=n)
        y = x + rng.normal(0.3, 1.0, n)
        y[:2] = x[:2]  # zero differences are dropped
        got = inference.sign_test(x, y)
        _, ref = sign_test(y - x, 0.0)
        assert got["n"] == n - 2 and got["p"] == pytest.approx(ref, rel=1e-9)


@pytest.mark.parametrize("n", [1, 4, 9, 20, 50])
def test_exact_wilcoxon_equals_scipy_s(n):
    rng = np.random.default_rng(SEED + n)
    for _ in range(5):
        x = rng.normal(size=n)
        y = x + rng.normal(0.2, 1.0, n)
        got = inference.wilcoxon(x, y)
        ref = stats.wilcoxon(x, y, method="exact")
        assert got["method"] == "exact"
        assert got["statistic"] == ref.statistic
        assert got["p"] == pytest.approx(ref.pvalue, rel=1e-9)


def test_wilcoxon_of_eight_positive_differences_is_2_over_2_to_the_8():
    got = inference.wilcoxon(np.arange(1.0, 9.0))
    assert got["statistic"] == 0.0 and got["p"] == pytest.approx(2.0 / 2**8, rel=1e-12)


def test_normal_wilcoxon_with_ties_equals_scipy_s():
    rng = np.random.default_rng(SEED)
    for n in (30, 80, 300):
        d = np.round(rng.normal(0.3, 1.0, n), 1)  # ties, and some zeros
        got = inference.wilcoxon(d, exact=False)
        ref = stats.wilcoxon(d, method="approx", zero_method="wilcox", correction=False)
        assert got["method"] == "normal" and got["n"] == int(np.sum(d != 0))
        assert got["statistic"] == pytest.approx(ref.statistic, rel=1e-12)
        assert got["p"] == pytest.approx(ref.pvalue, rel=1e-9)
    with pytest.raises(ValueError, match="without ties"):
        inference.wilcoxon([1.0, 1.0, -2.0], exact=True)


def test_holm_equals_statsmodels():
    from statsmodels.stats.multitest import multipletests

    rng = np.random.default_rng(SEED)
    for m in (1, 3, 17, 40):
        p = rng.random(m) ** 3
        p[: m // 4] = p[0]  # ties
        ref = multipletests(p, alpha=0.05, method="holm")[1]
        assert inference.holm(p) == pytest.approx(ref.tolist(), rel=1e-12, abs=1e-15)
    # By hand: sorted 0.01, 0.02, 0.04 of 3 -> 0.03, 0.04, 0.04 (monotone).
    assert inference.holm([0.04, 0.01, 0.02]) == pytest.approx([0.04, 0.03, 0.04])


def test_kaplan_meier_equals_statsmodels():
    from statsmodels.duration.survfunc import SurvfuncRight

    rng = np.random.default_rng(SEED)
    for n in (5, 32, 200):
        t = np.round(rng.exponential(8.0, n), 1)  # tied times
        observed = t < 20.0
        t = np.minimum(t, 20.0)  # censored at the run's end, 20 s
        got = inference.kaplan_meier(t, observed)
        ref = SurvfuncRight(t, observed.astype(int))
        assert got["times"] == pytest.approx(ref.surv_times.tolist())
        assert got["survival"] == pytest.approx(ref.surv_prob.tolist(), rel=1e-12)
        assert got["se"] == pytest.approx(ref.surv_prob_se.tolist(), rel=1e-9, abs=1e-15)
        assert got["at_risk"] == ref.n_risk.astype(int).tolist()
        # The median is the first time at which survival is 0.5 or below (Klein &
        # Moeschberger); statsmodels' quantile takes SAS's strict "below", which differs
        # where survival sits at exactly 0.5: read it from statsmodels' curve.
        below = np.flatnonzero(ref.surv_prob <= 0.5 + 1e-12)
        assert (got["median"] is None) == (below.size == 0)
        if below.size:
            assert got["median"] == pytest.approx(ref.surv_times[below[0]])


def test_kaplan_meier_without_censoring_is_the_empirical_survival():
    t = np.array([3.0, 1.0, 2.0, 2.0, 5.0])
    got = inference.kaplan_meier(t, np.ones(5, dtype=bool))
    assert got["times"] == [1.0, 2.0, 3.0, 5.0]
    assert got["survival"] == pytest.approx([0.8, 0.4, 0.2, 0.0])
    assert got["median"] == 2.0
    all_censored = inference.kaplan_meier([20.0, 20.0], [False, False])
    assert all_censored["times"] == [] and all_censored["median"] is None
    with pytest.raises(ValueError, match="finite"):
        inference.kaplan_meier([1.0, math.inf], [True, False])


def test_mcnemar_power_is_the_sum_over_every_outcome_of_scipy_s_test():
    """The exact power of the exact McNemar test, against a sum over every outcome (the
    discordant count m and its split j) of the probability of the outcomes SciPy's
    binomial test rejects."""
    n, only_a, only_b = 30, 0.3, 0.1
    want = 0.0
    for m in range(1, n + 1):
        p_m = stats.binom.pmf(m, n, only_a + only_b)
        for j in range(m + 1):
            if stats.binomtest(j, m, 0.5).pvalue <= 0.05:
                want += p_m * stats.binom.pmf(j, m, only_a / (only_a + only_b))
    assert inference.mcnemar_power(n, only_a, only_b) == pytest.approx(want, rel=1e-9)
    assert inference.mcnemar_power(n, 0.2, 0.2) <= 0.05  # no effect: at most alpha


@pytest.mark.parametrize(
    "n, p, p0", [(30, 0.75, 0.5), (57, 0.3, 0.5), (200, 0.45, 0.5), (13, 0.9, 0.6)]
)
def test_binomial_power_is_the_mass_of_what_scipy_s_test_rejects(n, p, p0):
    """The exact power of the exact binomial test: the probability under p of every count
    SciPy's binomtest rejects at 0.05."""
    rejected = [k for k in range(n + 1) if stats.binomtest(k, n, p0).pvalue <= 0.05]
    want = float(stats.binom.pmf(rejected, n, p).sum())
    assert inference.binomial_power(n, p, p0) == pytest.approx(want, rel=1e-9)


def test_binomial_n_is_the_first_n_that_reaches_the_power():
    """n for 80 % power: reached at n, not at n - 1 (the power is not monotone in n, so the
    first n is the claim); in the normal approximation's range for p far from p0."""
    for p in (0.75, 0.3, 0.9):
        n = inference.binomial_n(p)
        assert inference.binomial_power(n, p) >= 0.8
        assert all(inference.binomial_power(m, p) < 0.8 for m in range(1, n))
        z = stats.norm.ppf(0.975) * 0.5 + stats.norm.ppf(0.8) * math.sqrt(p * (1 - p))
        assert 0.6 * (z / (p - 0.5)) ** 2 < n < 1.6 * (z / (p - 0.5)) ** 2
    assert inference.binomial_n(0.5) is None  # no effect, no n


def test_mcnemar_pairs_is_the_fewest_that_reach_the_power():
    n = inference.mcnemar_pairs(0.25, 0.05)
    assert (
        inference.mcnemar_power(n, 0.25, 0.05) >= 0.8 > inference.mcnemar_power(n - 1, 0.25, 0.05)
    )
    # Simulated with the test itself: 2,000 sets of n pairs, rejected at the rate found.
    rng = np.random.default_rng(SEED)
    draws = rng.multinomial(n, [0.25, 0.05, 0.7], size=2000)
    rejected = np.mean([inference.binomial_test(int(a), int(a + b)) <= 0.05 for a, b, _ in draws])
    power = inference.mcnemar_power(n, 0.25, 0.05)
    assert abs(rejected - power) < 4 * math.sqrt(power * (1 - power) / 2000)
    assert inference.mcnemar_pairs(0.1, 0.1) is None  # no effect, no n


def test_paired_pairs_of_the_t_test_agree_with_statsmodels():
    from statsmodels.stats.power import TTestPower

    for d in (0.2, 0.35, 0.5, 0.8, 1.2):
        ref = TTestPower().solve_power(effect_size=d, alpha=0.05, power=0.8)
        assert abs(inference.paired_pairs(d, 1.0, test="t") - math.ceil(ref)) <= 1, d


def test_paired_pairs_of_the_wilcoxon_test_reach_the_power_in_simulation():
    """Normal differences of mean 0.5 sd: at the n found, the Wilcoxon test (ours, held to
    SciPy's above) rejects in 80 % of 1,000 simulated studies, within 4 standard errors."""
    n = inference.paired_pairs(0.5, 1.0)
    rng = np.random.default_rng(SEED)
    rejected = np.mean(
        [inference.wilcoxon(rng.normal(0.5, 1.0, n))["p"] <= 0.05 for _ in range(1000)]
    )
    assert abs(rejected - 0.8) < 4 * math.sqrt(0.8 * 0.2 / 1000), (n, rejected)


@pytest.mark.parametrize(("n", "m"), [(1, 1), (5, 7), (10, 10), (20, 45), (64, 64), (120, 80)])
def test_exact_two_sample_ks_equals_scipy_s(n, m):
    rng = np.random.default_rng(SEED + n * m)
    for shift in (0.0, 0.5):
        x, y = rng.normal(size=n), rng.normal(shift, 1.0, m)
        got = inference.ks_2samp(x, y)
        ref = stats.ks_2samp(x, y, method="exact")
        assert got["statistic"] == pytest.approx(ref.statistic, rel=1e-12)
        assert got["p"] == pytest.approx(ref.pvalue, rel=1e-9, abs=1e-14)


def test_ks_of_samples_apart_is_the_chance_of_that_order():
    """Every x below every y: D = 1, and p is 2 / C(n + m, n), the two orders (all x first
    or all y first) among the equally likely ones."""
    got = inference.ks_2samp(np.arange(4.0), np.arange(10.0, 16.0))
    assert got["statistic"] == 1.0 and got["p"] == pytest.approx(2.0 / math.comb(10, 4))


def test_quantile_shift_of_a_constant_shift_is_exact():
    x = np.random.default_rng(SEED).normal(size=32)
    for row in inference.quantile_shift(x, x + 0.25):
        assert row["shift"] == pytest.approx(0.25) and row["low"] == pytest.approx(0.25)
        assert row["high"] == pytest.approx(0.25)


def test_quantile_shift_intervals_agree_with_scipy_s_paired_bootstrap():
    """Percentile intervals of the median's shift, ours and scipy.stats.bootstrap's
    (paired, percentile), each from 20,000 resamples: equal within their Monte Carlo error
    (5 % of the interval's width)."""
    rng = np.random.default_rng(SEED)
    x = rng.lognormal(0.0, 0.5, 32)
    y = x * rng.lognormal(0.1, 0.3, 32)
    (got,) = inference.quantile_shift(x, y, quantiles=(0.5,), resamples=20_000)
    ref = stats.bootstrap(
        (x, y),
        lambda a, b, axis: np.median(b, axis=axis) - np.median(a, axis=axis),
        paired=True,
        vectorized=True,
        n_resamples=20_000,
        method="percentile",
        random_state=1,
    ).confidence_interval
    width = ref.high - ref.low
    assert got["shift"] == pytest.approx(np.median(y) - np.median(x))
    assert abs(got["low"] - ref.low) < 0.05 * width and abs(got["high"] - ref.high) < 0.05 * width
