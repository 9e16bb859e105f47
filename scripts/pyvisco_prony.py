"""Generalized Maxwell (Prony series) fit of a storage/loss master curve by pyvisco.

The independent reference for `rfmlab material`: pyvisco's own pipeline on
the same curve (load.user_master, master.smooth, prony.discretize with one term per decade,
prony.fit, then opt.nprony, which refits with N = n-1 ... 3 terms whose relaxation times are
optimised). For every N it prints the Prony parameters and the RMS log10 errors of E' and E''
at the data's frequencies, computed here from pyvisco's parameters.

usage: pyvisco_prony.py CSV FREQ_COL STOR_COL LOSS_COL MODULUS_TO_MPA [N ...]
  CSV has one header row; FREQ_COL in Hz; the moduli times MODULUS_TO_MPA are MPa.
  With N given, only those term counts are reported (all are fitted by nprony anyway).
Prints JSON: {"fits": [{"n_terms", "n_params", "e_0_pa", "e_inf_pa", "tau_s", "e_i_pa",
"rms_log10_storage", "rms_log10_loss"}], "n_opt": pyvisco's suggested N}.
"""

import contextlib
import io
import json
import sys
import warnings

import numpy as np
import pandas as pd
from pyvisco import master, opt, prony


def rms_log10(model, data):
    return float(np.sqrt(np.mean((np.log10(model) - np.log10(data)) ** 2)))


def main():
    path, fcol, scol, lcol, to_mpa = sys.argv[1:6]
    wanted = {int(n) for n in sys.argv[6:]}
    to_mpa = float(to_mpa)
    raw = pd.read_csv(path)
    f = raw[fcol].to_numpy(float)
    es = raw[scol].to_numpy(float) * to_mpa
    el = raw[lcol].to_numpy(float) * to_mpa
    order = np.argsort(f)
    f, es, el = f[order], es[order], el[order]
    # The frame pyvisco's load.user_master builds (its CSV parser returns text columns under
    # pandas 3, so the frame is built here with the same columns and attributes).
    df_master = pd.DataFrame({"f": f, "E_stor": es, "E_loss": el})
    df_master["omega"] = 2 * np.pi * df_master["f"]
    df_master["t"] = 1 / df_master["f"]
    df_master.RefT = 25
    df_master.domain = "freq"
    df_master.modul = "E"
    quiet = io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stdout(quiet):
        warnings.simplefilter("ignore")
        df_master = master.smooth(df_master, 1)
        df_dis = prony.discretize(df_master, "round")
        first, _ = prony.fit(df_dis, df_master, opt=False)
        dict_prony, n_opt, _err = opt.nprony(df_master, first, window="min")
    dict_prony[first["df_terms"].shape[0]] = first
    omega = 2 * np.pi * f
    fits = []
    for n in sorted(dict_prony):
        if wanted and n not in wanted:
            continue
        p = dict_prony[n]
        terms = p["df_terms"]
        tau = terms["tau_i"].to_numpy(float)
        alpha = terms["alpha_i"].to_numpy(float)
        e0 = float(p["E_0"])
        a = omega[None, :] * tau[:, None]
        stor = e0 * (1 - alpha.sum() + (alpha[:, None] * a**2 / (1 + a**2)).sum(0))
        loss = e0 * (alpha[:, None] * a / (1 + a**2)).sum(0)
        fits.append(
            {
                "n_terms": int(n),
                "n_params": int(2 * n + 1),
                "e_0_pa": e0 * 1e6,
                "e_inf_pa": e0 * (1 - alpha.sum()) * 1e6,
                "tau_s": tau.tolist(),
                "e_i_pa": (e0 * alpha * 1e6).tolist(),
                "rms_log10_storage": rms_log10(np.maximum(stor, 1e-300), es),
                "rms_log10_loss": rms_log10(np.maximum(loss, 1e-300), el),
            }
        )
    json.dump({"fits": fits, "n_opt": int(n_opt)}, sys.stdout)


if __name__ == "__main__":
    main()
