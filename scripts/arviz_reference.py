"""ArviZ's diagnostics of draws written by rfmlab's tests (the independent reference of
src/inference/diagnostics.rs and src/inference/loo.rs).

Usage: arviz_reference.py INPUT.json  -> prints a JSON report on stdout.

INPUT.json: {"params": {name: [[draws of chain 0], ...]},
             "energy": [[...], ...]        (optional, NUTS energy per chain),
             "log_lik": [[[obs...] per draw] per chain]  (optional),
             "hdi_prob": 0.94}
NaN is written as null and +-inf as the strings "inf" / "-inf".
"""

import json
import math
import sys
import warnings

warnings.filterwarnings("ignore")

import arviz as az  # noqa: E402
import numpy as np  # noqa: E402


def num(v):
    v = float(v)
    if math.isnan(v):
        return None
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return v


def nums(a):
    return [num(v) for v in np.asarray(a, dtype=float).ravel()]


def main():
    with open(sys.argv[1]) as f:
        inp = json.load(f)
    hdi_prob = inp.get("hdi_prob", 0.94)
    out = {"arviz": az.__version__, "params": {}}
    posterior = {}
    for name, chains in inp["params"].items():
        x = np.asarray(chains, dtype=float)
        posterior[name] = x
        flat = x.ravel()
        hdi = az.hdi(flat, hdi_prob=hdi_prob)
        out["params"][name] = {
            "rhat": num(az.rhat(x, method="rank")),
            "ess_bulk": num(az.ess(x, method="bulk")),
            "ess_tail": num(az.ess(x, method="tail")),
            "ess_mean": num(az.ess(x, method="mean")),
            "ess_q05": num(az.ess(x, method="quantile", prob=0.05)),
            "mcse_mean": num(az.mcse(x, method="mean")),
            "mcse_sd": num(az.mcse(x, method="sd")),
            "mcse_q05": num(az.mcse(x, method="quantile", prob=0.05)),
            "mcse_q95": num(az.mcse(x, method="quantile", prob=0.95)),
            "hdi": nums(hdi),
            "mean": num(flat.mean()),
            "sd": num(flat.std(ddof=1)),
            "quantiles": nums(np.quantile(flat, [0.5, 0.025, 0.975, 0.05, 0.95])),
        }
    if "energy" in inp:
        out["bfmi"] = nums(az.bfmi(np.asarray(inp["energy"], dtype=float)))
    if "log_lik" in inp:
        ll = np.asarray(inp["log_lik"], dtype=float)
        idata = az.from_dict(posterior=posterior, log_likelihood={"y": ll})
        loo = az.loo(idata, pointwise=True)
        waic = az.waic(idata, pointwise=True)
        out["loo"] = {
            "elpd": num(loo["elpd_loo"]),
            "se": num(loo["se"]),
            "p_loo": num(loo["p_loo"]),
            "warning": bool(loo["warning"]),
            "good_k": num(loo["good_k"]),
            "pareto_k": nums(loo["pareto_k"].values),
            "pointwise": nums(loo["loo_i"].values),
            "scale": loo["scale"],
        }
        out["waic"] = {
            "elpd": num(waic["elpd_waic"]),
            "se": num(waic["se"]),
            "p_waic": num(waic["p_waic"]),
            "warning": bool(waic["warning"]),
            "pointwise": nums(waic["waic_i"].values),
        }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
