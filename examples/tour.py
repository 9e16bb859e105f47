# %% [markdown]
# # rfmlab from Python: a tour
#
# The bundled data are a virtual replica of the paper's bonded-beam test (a Model 4 adhesive,
# two excitation levels, simulated with `rfmlab simulate studies/data/paper_experiment.toml`;
# the truth is known). This tour
#
# 1. reads the measured FRFs,
# 2. runs the Bayesian study `examples/tour.toml` (Models 3-5 at both levels, NUTS),
# 3. plots the posterior bands of E'(f) and E''(f) of Model 4 at both levels, with ArviZ,
# 4. compares the models by PSIS-LOO,
# 5. runs the closed loop on data with an undeclared 12 g sensor mass and shows the fit
#    before and after.
#
# Run it from the repository root: `python examples/tour.py` (or open it as a notebook: the
# `# %%` markers are cells in Jupyter, VS Code and Spyder). Figures go to `results/tour-py/`.

# %%
import logging
import os
import sys
import time
from pathlib import Path

import arviz as az
import matplotlib

if "ipykernel" not in sys.modules:
    matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import polars as pl

import rfmlab

ROOT = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
OUT = Path(os.environ.get("RFMLAB_TOUR_OUT", ROOT / "results" / "tour-py"))
OUT.mkdir(parents=True, exist_ok=True)
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
t_start = time.perf_counter()

# %% [markdown]
# ## 1. The data
# `read_uff` gives a long frame: one row per level, channel and frequency line.

# %%
frf = rfmlab.read_uff(ROOT / "studies" / "data" / "paper_virtual_L1.uff")
print(frf.head())
fig, ax = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
for rid, ch in frf.group_by("response_id", maintain_order=True):
    h = ch["re"].to_numpy() + 1j * ch["im"].to_numpy()
    ax[0].semilogy(ch["freq_hz"], np.abs(h), label=f"point {rid[0]}")
    ax[1].plot(ch["freq_hz"], ch["coherence"])
ax[0].set_ylabel("|H| ((m/s²)/N)")
ax[0].legend()
ax[1].set_ylabel("coherence")
ax[1].set_xlabel("frequency (Hz)")
fig.savefig(OUT / "data_L1.png", dpi=120)

# %% [markdown]
# ## 2. The Bayesian study
# `run()` works in memory (nothing is written unless `output=` is given); each step is logged
# on the `rfmlab` logger with `quiet=False`. Ctrl-C stops it.

# %%
study = rfmlab.load(ROOT / "examples" / "tour.toml")
print(study)
t0 = time.perf_counter()
results = study.run(quiet=False)
print(f"run: {time.perf_counter() - t0:.1f} s; tables: {sorted(results.tables)}")
print(results.parameters.filter(pl.col("model") == "model4"))
print(
    results.summary.filter(pl.col("model") == "model4").select(
        "level", "parameter", "mean", "sd", "r_hat", "ess_bulk", "truth"
    )
)

# %% [markdown]
# ## 3. E'(f) and E''(f) of Model 4 at both levels
# Each posterior draw's law evaluated over the band gives the modulus bands (median and 95 %);
# the truth of the simulated data is drawn dashed.

# %%
f = np.linspace(1.0, 500.0, 200)
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
for level, colour in (("L1", "C0"), ("L2", "C3")):
    draws = results.posterior_draws("model4", level)
    names = [n for n, _ in rfmlab.law_parameters("model4")]
    p = np.stack([draws[n].ravel() for n in names], axis=1)[::8]
    e = np.array([rfmlab.modulus("model4", row, f) for row in p])
    truth = results.summary.filter((pl.col("model") == "model4") & (pl.col("level") == level))
    e_true = rfmlab.modulus("model4", dict(zip(truth["parameter"], truth["truth"])), f)
    for k, (part, label) in enumerate(((np.real, "E' (Pa)"), (np.imag, "E'' (Pa)"))):
        lo, med, hi = np.percentile(part(e), [2.5, 50, 97.5], axis=0)
        ax[k].fill_between(f, lo, hi, color=colour, alpha=0.3, label=f"{level} 95 %")
        ax[k].plot(f, med, color=colour, label=f"{level} median")
        ax[k].plot(f, part(e_true), "k--", lw=0.8)
        ax[k].set_xlabel("frequency (Hz)")
        ax[k].set_ylabel(label)
ax[0].legend()
fig.tight_layout()
fig.savefig(OUT / "modulus_bands.png", dpi=120)

idata = {level: results.to_inference_data(model="model4", level=level) for level in ("L1", "L2")}
print(az.summary(idata["L1"], kind="diagnostics"))
axes = az.plot_posterior(idata["L1"], var_names=["E0", "h", "E1", "eta1"])
plt.gcf().savefig(OUT / "posterior_model4_L1.png", dpi=100)

# %% [markdown]
# ## 4. Model comparison by PSIS-LOO
# ArviZ's `compare` on the same draws as the run's own `model_comparison` table.

# %%
for level in ("L1", "L2"):
    loo_data = {
        m: results.to_inference_data(model=m, level=level, loo_draws=True, prior_draws=0)
        for m in ("model3", "model4", "model5")
    }
    cmp = az.compare(loo_data, ic="loo")
    print(f"level {level}:\n{cmp[['rank', 'elpd_loo', 'p_loo', 'elpd_diff', 'weight']]}")
    assert cmp.index[0] == "model4", "the truth's law should win"
print(results.model_comparison.select("level", "model", "elpd_loo", "elpd_loo_se", "max_pareto_k"))

# %% [markdown]
# ## 5. The closed loop on data with an undeclared sensor mass
# `studies/closed_loop_mass.toml` fits Model 4 to data simulated with a 12 g sensor mass at
# point 4 that the study does not declare. `run(closed_loop=True)` adds the closed loop after
# the inference: it tests candidate effects (point masses, gains, a beam factor, extra
# Maxwell branches, another law), accepts those the evidence supports, and refits, all in
# memory. (`study.diagnose()` runs the loop alone, as `rfmlab diagnose`.)

# %%
loop_study = rfmlab.load(ROOT / "studies" / "closed_loop_mass.toml")
t0 = time.perf_counter()
loop_results = loop_study.run(quiet=False, closed_loop=True)
print(f"run with the closed loop: {time.perf_counter() - t0:.1f} s")
summary = loop_results.closed_loop
for lv in summary["levels"]:
    print(f"level {lv['level']}: {lv['conclusion']}")
    print(f"  chi2/dof before {lv['chi2_normalised_before']:.4g}, after {lv['chi2_normalised_after']:.4g}")
    print(f"  FRAC before {np.round(lv['frac_before'], 5)}, after {np.round(lv['frac_after'], 5)}")
    for name, kind, size, sd in lv["accepted"]:
        print(f"  accepted {name} ({kind}): {size:.6g} +- {sd:.2g}")
print(loop_results.tables["closed_loop/closed_loop"])
before_after = pl.DataFrame(summary["levels"][0]["parameters"])
print(before_after.select("name", "before", "before_sd", "after", "after_sd", "truth"))

fig, ax = plt.subplots(figsize=(6, 4))
pa = before_after.filter(pl.col("truth").is_not_null() & pl.col("before").is_not_null())
x = np.arange(pa.height)
ax.bar(x - 0.2, (pa["before"] / pa["truth"] - 1) * 100, 0.4, label="before the loop")
ax.bar(x + 0.2, (pa["after"] / pa["truth"] - 1) * 100, 0.4, label="after the loop")
ax.set_xticks(x, pa["name"].to_list())
ax.set_ylabel("error against the truth (%)")
ax.axhline(0, color="k", lw=0.8)
ax.legend()
fig.tight_layout()
fig.savefig(OUT / "closed_loop_before_after.png", dpi=120)

# %%
print(f"tour: {time.perf_counter() - t_start:.1f} s")
