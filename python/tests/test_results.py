"""`Study.run` against the CLI, and the ArviZ view of a Bayesian run against rfmlab's tables."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import polars as pl
import polars.testing
import pytest

import rfmlab
from conftest import STUDIES, cli_binary, study_copy

# Columns that measure time, which no two runs share.
TIMED = {"seconds"}


def test_default_study_equals_the_cli_parquet(tmp_path):
    """Every table of `rfmlab.load('studies/default.toml').run()` equals the parquet file the
    CLI writes for the same study (run here into a temporary folder), value for value."""
    path = study_copy(tmp_path, "default.toml", "py_default")
    out = tmp_path / "results" / "py_default"
    cli = subprocess.run(
        [str(cli_binary()), "--quiet", "run", str(path), "--no-cache", "--no-figures"],
        capture_output=True, text=True, cwd=tmp_path,
    )
    assert cli.returncode == 0, cli.stderr
    written = {p.stem: p for p in out.glob("*.parquet")}
    assert {"parameters", "frf", "modulus", "modal"} <= set(written), sorted(written)

    results = rfmlab.load(path).run(rom_cache=False)
    assert set(results.tables) == set(written), (sorted(results.tables), sorted(written))
    for name, file in written.items():
        a = results.tables[name]
        b = pl.read_parquet(file)
        keep = [c for c in b.columns if c not in TIMED]
        polars.testing.assert_frame_equal(a.select(keep), b.select(keep), check_exact=True)
    # Independent of the equality above (a fault shared with the CLI would fail here): the
    # identified Model 4 at L1 is within 3 % of the parameters the bundled data were made with
    # (studies/data/paper_virtual.truth.json) and fits every FRF (FRAC > 0.99).
    truth = json.loads((STUDIES / "data" / "paper_virtual.truth.json").read_text())
    want = next(lv["params"] for lv in truth["levels"] if lv["level"] == "L1")
    p = results.parameters.filter((pl.col("level") == "L1") & (pl.col("model") == "model4"))
    assert p.height == 4
    for name in ("E0", "h", "E1", "eta1"):
        got = p.filter(pl.col("parameter") == name)["identified"][0]
        assert abs(got / want[name] - 1) < 0.03, (name, got, want[name])
    fr = [c for c in p.columns if c.startswith("frac_updated_")]
    assert fr and all(p[c][0] > 0.99 for c in fr), {c: p[c][0] for c in fr}


def test_inference_data_reproduces_the_summary_diagnostics(bayes_run):
    """az.rhat / az.ess on `to_inference_data` equal the summary table's R-hat and ESS."""
    az = pytest.importorskip("arviz")
    study, results = bayes_run
    idata = results.to_inference_data(model="model4", level="L1", prior_draws=200)
    for g in ("posterior", "sample_stats", "log_likelihood", "observed_data", "prior", "constant_data"):
        assert g in idata.groups(), idata.groups()
    assert idata.log_likelihood["frf"].dims == ("chain", "draw", "freq_hz")
    assert idata.observed_data["accelerance_re"].dims == ("channel", "freq_hz")
    assert list(idata.constant_data["parameter"].values) == ["E0", "h", "E1", "eta1"]
    s = results.summary.filter((pl.col("model") == "model4") & (pl.col("sampler") == "nuts"))
    rhat = az.rhat(idata)
    bulk = az.ess(idata, method="bulk")
    tail = az.ess(idata, method="tail")
    assert s.height == 4
    for row in s.iter_rows(named=True):
        p = row["parameter"]
        assert idata.posterior[p].shape == (4, 500)
        assert abs(float(rhat[p]) - row["r_hat"]) <= 1e-8 * row["r_hat"], (p, float(rhat[p]), row["r_hat"])
        assert abs(float(bulk[p]) - row["ess_bulk"]) <= 1e-6 * row["ess_bulk"], p
        assert abs(float(tail[p]) - row["ess_tail"]) <= 1e-6 * row["ess_tail"], p
        # The posterior mean is the table's.
        assert abs(float(idata.posterior[p].mean()) - row["mean"]) <= 1e-9 * abs(row["mean"])
    # The prior group holds draws of the declared priors (log-uniform over a decade either
    # side of the initial values unless declared): inside those bounds, spread over them.
    e0 = idata.prior["E0"].values.ravel()
    assert e0.min() >= 6e5 * (1 - 1e-9) and e0.max() <= 6e7 * (1 + 1e-9)
    assert np.std(np.log10(e0)) > 0.4


def test_az_loo_equals_the_model_comparison_table(bayes_run):
    az = pytest.importorskip("arviz")
    _, results = bayes_run
    idata = results.to_inference_data(model="model4", level="L1", loo_draws=True, prior_draws=0)
    loo = az.loo(idata, pointwise=True)
    mc = results.model_comparison.filter((pl.col("level") == "L1") & (pl.col("model") == "model4"))
    row = mc.row(0, named=True)
    assert abs(float(loo["elpd_loo"]) - row["elpd_loo"]) <= 1e-6 * abs(row["elpd_loo"])
    assert abs(float(loo["se"]) - row["elpd_loo_se"]) <= 1e-6 * row["elpd_loo_se"]
    assert abs(float(loo["p_loo"]) - row["p_loo"]) <= 1e-6 * max(abs(row["p_loo"]), 1.0)
    assert abs(float(loo["pareto_k"].max()) - row["max_pareto_k"]) <= 1e-6
    # Over 51 lines (10-60 Hz), each line's elpd is the table's.
    pw = results.pointwise_loglik.filter(
        (pl.col("level") == "L1") & (pl.col("model") == "model4")
    ).group_by("line").agg(pl.col("elpd_loo_i").first()).sort("line")
    assert pw.height == 51
    np.testing.assert_allclose(loo["loo_i"].values, pw["elpd_loo_i"].to_numpy(), rtol=1e-6)


def test_results_tables_and_errors(bayes_run):
    _, results = bayes_run
    assert results.summary.height > 0 and results.draws.height == 4 * 500
    with pytest.raises(KeyError, match="closed_loop"):
        results.table("closed_loop")
    m = results.map_point("model4", "L1")
    assert list(m) == ["E0", "h", "E1", "eta1"]


def test_progress_interrupt_and_the_gil(tmp_path):
    """A run reports its steps to the callback; while it computes, another Python thread runs
    (the GIL is released); an exception in the callback and Ctrl-C (a SIGINT to the main
    thread) each stop the run at the next stage and are raised, leaving nothing written."""
    import _thread
    import threading

    path = study_copy(tmp_path, "default.toml", "py_progress")
    study = rfmlab.load(path)

    steps = []
    ticks = []
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            ticks.append(1)
            stop.wait(0.05)

    t = threading.Thread(target=ticker)
    t.start()
    try:
        study.run(figures=False, rom_cache=False, progress=lambda s, d, n: steps.append((s, d, n)))
    finally:
        stop.set()
        t.join()
    assert len({s for s, _, _ in steps}) >= 3, steps
    assert len(ticks) >= 10, "another Python thread should run while the study computes"

    class Stop(Exception):
        pass

    def fail(step, done, total):
        raise Stop(step)

    with pytest.raises(Stop):
        study.run(figures=False, rom_cache=False, progress=fail, output=tmp_path / "never")
    assert not (tmp_path / "never").exists()

    timer = threading.Timer(1.0, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            study.run(figures=False, rom_cache=False, output=tmp_path / "never")
    finally:
        timer.cancel()
    assert not (tmp_path / "never").exists()
