"""`Study.posterior`: the density rfmlab's samplers see, for external samplers."""

from __future__ import annotations

import numpy as np
import polars as pl
import pytest


@pytest.fixture(scope="module")
def posterior(bayes_run):
    study, results = bayes_run
    return study.posterior("model4", "L1", at=results.map_point("model4", "L1")), results


def test_logp_is_the_samplers_density(posterior):
    """At NUTS's draws, the log likelihood equals the one the run recorded and logp differs
    from the recorded lp by one constant (NUTS samples coordinates whitened by the Laplace
    approximation, whose log-Jacobian is that constant): the binding's density is the one
    sampled. logp = log prior + log likelihood, and the gradient matches differences."""
    post, results = posterior
    assert post.names == ["E0", "h", "E1", "eta1"] and post.linearised
    d = results.draws.filter(pl.col("sampler") == "nuts").sort("chain", "draw")
    lower = {c.lower(): c for c in d.columns}
    rows = d.select([lower[n.lower()] for n in post.names]).to_numpy()[::97]
    lp = d["lp"].to_numpy()[::97]
    ll = d["log_lik"].to_numpy()[::97]
    shifts = []
    for p, lp_run, ll_run in zip(rows, lp, ll):
        x = post.to_unconstrained(p)
        np.testing.assert_allclose(post.to_constrained(x), p, rtol=1e-12)
        v = post.logp(x)
        shifts.append(lp_run - v)
        assert abs(post.log_likelihood(x) - ll_run) <= 1e-9 * abs(ll_run), (post.log_likelihood(x), ll_run)
        assert abs(v - post.log_prior(x) - post.log_likelihood(x)) <= 1e-9 * abs(v)
    assert len(shifts) >= 20 and np.ptp(shifts) < 1e-6, shifts
    x = post.to_unconstrained(rows[0])
    v, g = post.logp_and_grad(x)
    assert g.dtype == np.float64 and g.shape == (4,)
    for i in range(4):
        h = 1e-6
        e = np.zeros(4)
        e[i] = h
        fd = (post.logp(x + e) - post.logp(x - e)) / (2 * h)
        assert abs(fd - g[i]) <= 1e-4 * (1 + abs(g[i])), (i, fd, g[i])
    # Every real x maps inside the priors' support: far out the density is finite and far
    # below the mode's; where the density cannot be evaluated it is -inf, not an exception.
    far = post.logp(np.full(4, 30.0))
    assert far == -np.inf or far < post.logp(x) - 1e3, far
    assert post.logp(np.full(4, np.nan)) == -np.inf
    v, g = post.logp_and_grad(np.full(4, np.nan))
    assert v == -np.inf and np.isnan(g).all()


def test_emcee_agrees_with_nuts_on_model4(posterior):
    """emcee (affine-invariant ensemble, no gradients) on `logp` reproduces rfmlab's NUTS
    posterior of Model 4: every mean within 0.2 posterior sd, every sd within 25 %."""
    emcee = pytest.importorskip("emcee")
    post, results = posterior
    lap = results.laplace.filter((pl.col("level") == "L1") & (pl.col("model") == "model4"))
    m = lap["map"].to_numpy()
    sd = lap["sd"].to_numpy()
    rng = np.random.default_rng(7)
    n_walkers = 16
    # Walkers start in a ball of the Laplace approximation around the MAP (not from NUTS).
    start = post.to_unconstrained(m + 0.5 * sd * rng.standard_normal((n_walkers, 4)))
    sampler = emcee.EnsembleSampler(n_walkers, 4, post.logp)
    sampler.random_state = np.random.RandomState(11)
    sampler.run_mcmc(start, 1600)
    chain = sampler.get_chain(discard=400, flat=True)
    phys = post.to_constrained(chain)
    s = results.summary.filter((pl.col("model") == "model4") & (pl.col("sampler") == "nuts"))
    for k, row in enumerate(s.iter_rows(named=True)):
        assert row["parameter"] == post.names[k]
        mean, sd_e = phys[:, k].mean(), phys[:, k].std()
        assert abs(mean - row["mean"]) < 0.2 * row["sd"], (row["parameter"], mean, row["mean"], row["sd"])
        assert abs(sd_e / row["sd"] - 1) < 0.25, (row["parameter"], sd_e, row["sd"])


def test_prior_draws_are_in_the_declared_support(posterior):
    post, _ = posterior
    x = post.sample_prior(500, seed=3)
    assert x.shape == (500, 4)
    p = post.to_constrained(x)
    assert np.all(np.isfinite([post.log_prior(r) for r in x]))
    # Default priors: log-uniform over a decade either side of the initial values.
    init = np.array([6e6, 1e6, 3e6, 3e3])
    assert np.all(p >= init / 10 * (1 - 1e-9)) and np.all(p <= init * 10 * (1 + 1e-9))
