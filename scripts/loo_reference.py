"""ArviZ's PSIS-LOO and WAIC, and scipy's chi-square tail, on the pointwise log likelihood and
PPC residuals that `rfmlab run` wrote (the independent reference of src/bayes/compare/criteria.rs).

Usage: loo_reference.py RESULTS_DIR  -> prints JSON {"LEVEL/MODEL": {...}} on stdout.

For each level and model of pointwise_loglik.parquet: the posterior is the draws.parquet rows of
the same sampler, chains and draws (ArviZ's relative efficiency comes from them), the
log likelihood is [chain, draw, line]; az.loo and az.waic with pointwise=True. The PPC
p-values are scipy.stats.chi2.sf(chi2, dof) of ppc.parquet's per-channel chi2.
"""

import json
import math
import sys
import warnings

warnings.filterwarnings("ignore")

import arviz as az  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy import stats  # noqa: E402

META = {"level", "model", "sampler", "chain", "draw", "lp", "log_lik", "log_prior",
        "step_size", "tree_depth", "n_steps", "diverging", "energy"}


def num(v):
    v = float(v)
    return None if math.isnan(v) else v


def main():
    d = sys.argv[1]
    pw = pd.read_parquet(f"{d}/pointwise_loglik.parquet")
    draws = pd.read_parquet(f"{d}/draws.parquet")
    ppc = pd.read_parquet(f"{d}/ppc.parquet")
    out = {}
    for (level, model), g in pw.groupby(["level", "model"], sort=False):
        sampler = g["sampler"].iloc[0]
        chains = sorted(g["chain"].unique())
        ll = []
        post = {}
        dr = draws[(draws.level == level) & (draws.model == model) & (draws.sampler == sampler)]
        cols = [c for c in dr.columns if c not in META and dr[c].notna().all()]
        for c in chains:
            gc = g[g.chain == c]
            kept = sorted(gc["draw"].unique())
            piv = gc.pivot(index="draw", columns="line", values="log_lik").loc[kept]
            ll.append(piv.to_numpy())
            dc = dr[(dr.chain == c)].set_index("draw").loc[kept]
            for col in cols:
                post.setdefault(col, []).append(dc[col].to_numpy())
        ll = np.asarray(ll)
        idata = az.from_dict(
            posterior={k: np.asarray(v) for k, v in post.items()},
            log_likelihood={"y": ll},
        )
        loo = az.loo(idata, pointwise=True)
        waic = az.waic(idata, pointwise=True)
        pc = ppc[(ppc.level == level) & (ppc.model == model)].groupby("channel").first()
        out[f"{level}/{model}"] = {
            "elpd_loo": num(loo["elpd_loo"]),
            "loo_se": num(loo["se"]),
            "p_loo": num(loo["p_loo"]),
            "pareto_k": [num(v) for v in loo["pareto_k"].values],
            "loo_i": [num(v) for v in loo["loo_i"].values],
            "elpd_waic": num(waic["elpd_waic"]),
            "waic_se": num(waic["se"]),
            "p_waic": num(waic["p_waic"]),
            "waic_i": [num(v) for v in waic["waic_i"].values],
            "ppc_p": {str(ch): num(stats.chi2.sf(r.chi2, r.dof)) for ch, r in pc.iterrows()},
        }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
