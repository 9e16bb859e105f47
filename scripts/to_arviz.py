#!/usr/bin/env python3
"""Turn rfmlab's posterior draws into ArviZ InferenceData.

    python scripts/to_arviz.py RESULTS_DIR [--level L1] [--model model4] [--sampler nuts] [--json]

Reads RESULTS_DIR/draws.parquet (columns: level, model, sampler, chain, draw, one column per
parameter in SI units, lp, log_lik, log_prior and the NUTS statistics) and prints ArviZ's
summary of every (level, model, sampler) group, or, with --json, the R-hat, bulk and tail ESS
and MCSE of the mean per parameter (the test suite compares them with rfmlab's own summary).
The core of it is the few lines of `inference_data`.
"""
import argparse
import json
import sys

import arviz as az
import numpy as np
import pandas as pd

STATS = ["lp", "log_lik", "log_prior", "step_size", "tree_depth", "n_steps", "diverging", "energy"]
KEYS = ["level", "model", "sampler", "chain", "draw"]


def inference_data(group: pd.DataFrame) -> az.InferenceData:
    """One (level, model, sampler) group of draws.parquet as InferenceData (chain x draw)."""
    params = [c for c in group.columns if c not in KEYS + STATS and group[c].notna().all()]
    g = group.sort_values(["chain", "draw"])
    n_chain = g["chain"].nunique()
    shape = (n_chain, len(g) // n_chain)
    post = {p: g[p].to_numpy().reshape(shape) for p in params}
    stats = {s: g[s].to_numpy().reshape(shape) for s in STATS if s in g and g[s].notna().all()}
    if "diverging" in stats:
        stats["diverging"] = stats["diverging"].astype(bool)
    return az.from_dict(posterior=post, sample_stats=stats)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("--level")
    ap.add_argument("--model")
    ap.add_argument("--sampler")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    draws = pd.read_parquet(f"{a.results}/draws.parquet")
    for k in ("level", "model", "sampler"):
        v = getattr(a, k)
        if v is not None:
            draws = draws[draws[k] == v]
    out = {}
    for (level, model, sampler), group in draws.groupby(["level", "model", "sampler"]):
        idata = inference_data(group)
        if a.json:
            s = az.summary(idata, kind="diagnostics", round_to="none")
            out[f"{level}/{model}/{sampler}"] = {
                p: {c: float(s.loc[p, c]) for c in ["r_hat", "ess_bulk", "ess_tail", "mcse_mean"]}
                for p in s.index
            }
        else:
            print(f"== level {level}, {model}, {sampler}")
            print(az.summary(idata))
    if a.json:
        json.dump(out, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
