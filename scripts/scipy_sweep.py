#!/usr/bin/env python3
"""Time the full-model FRF sweep with scipy (per-line sparse LU) for comparison with rfmlab.

Reads a folder written by rfmlab's Matrix Market export (M.mtx, K_b.mtx, S.mtx, optional
C_b.mtx / D_b.mtx, dofmap.csv), forms Z(w) = -w^2 M + K_b + j w C_b + j D_b + E*(w) S on
each line and solves Z x = b_in with scipy.sparse.linalg.splu; reads H at the observation
DOFs. Prints JSON with the median wall time of a full sweep (and per line).

dofmap.csv: the observation DOFs as written by `rfmlab export-mm` (src/fe/matrix_market.rs):
columns id,direction,dof,weight with a 1-based free-DOF index `dof` (one row per DOF of a
point; rows with the same id and direction belong to one point). A column `dof0` (0-based)
is also accepted.
Without such a file, --obs gives 0-based DOF indices directly.

Usage: scipy_sweep.py FOLDER [--lines 500] [--repeats 3] [--input 1] [--obs 12,40,...]
"""
import argparse
import csv
import json
import os
import statistics
import sys
import time

import numpy as np
import scipy.io
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def load(folder, name, required=True):
    path = os.path.join(folder, name)
    if not os.path.exists(path):
        if required:
            sys.exit(f"missing {path}: export the model with rfmlab's Matrix Market writer")
        return None
    return sp.csc_matrix(scipy.io.mmread(path))


def observation(folder, n, obs_arg):
    if obs_arg:
        dofs = [int(x) for x in obs_arg.split(",")]
        return [[(d, 1.0)] for d in dofs]
    path = os.path.join(folder, "dofmap.csv")
    if not os.path.exists(path):
        sys.exit("no dofmap.csv and no --obs given")
    pts = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            if "dof" in row:
                d = int(row["dof"]) - 1
            elif "dof0" in row:
                d = int(row["dof0"])
            else:
                sys.exit("dofmap.csv needs a 'dof' (1-based) or 'dof0' (0-based) column")
            if not 0 <= d < n:
                sys.exit(f"dofmap.csv: DOF {d + 1} outside 1..{n}")
            w = float(row.get("weight", 1.0) or 1.0)
            key = (row.get("id", str(len(pts))), row.get("direction", ""))
            pts.setdefault(key, []).append((d, w))
    if not pts:
        sys.exit("dofmap.csv lists no DOFs")
    return list(pts.values())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("folder")
    ap.add_argument("--lines", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--input", type=int, default=1, help="0-based index of the excitation point")
    ap.add_argument("--obs", default="")
    a = ap.parse_args()
    m = load(a.folder, "M.mtx")
    k = load(a.folder, "K_b.mtx")
    s = load(a.folder, "S.mtx")
    c = load(a.folder, "C_b.mtx", False)
    d = load(a.folder, "D_b.mtx", False)
    n = m.shape[0]
    pts = observation(a.folder, n, a.obs)
    bmat = np.zeros((n, len(pts)))
    for i, p in enumerate(pts):
        for dof, w in p:
            bmat[dof, i] += w
    f = np.linspace(1.0, 500.0, a.lines)
    omega = 2 * np.pi * f
    # the same smooth E*(w) curve as the Rust bench (Model 4 at Level 1, method.md)
    e0, e1, eta1, h = 6.67e6, 3.1487e6, 4.181e3, 0.944e6
    modulus = e0 + 1j * h + 1j * omega * eta1 * e1 / (e1 + 1j * omega * eta1)
    b_in = bmat[:, a.input].astype(complex)
    times = []
    out = None
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        hh = np.empty((a.lines, len(pts)), dtype=complex)
        for l, w in enumerate(omega):
            z = (-w * w) * m + k + modulus[l] * s
            if c is not None:
                z = z + (1j * w) * c
            if d is not None:
                z = z + 1j * d
            x = spla.splu(sp.csc_matrix(z, dtype=complex)).solve(b_in)
            hh[l] = bmat.T @ x
        times.append(time.perf_counter() - t0)
        out = hh
    med = statistics.median(times)
    print(json.dumps({
        "n_dof": n, "n_lines": a.lines, "n_frf": len(pts), "repeats": a.repeats,
        "median_sweep_s": med, "median_per_line_s": med / a.lines,
        "h_abs_max": float(np.abs(out).max()),
    }))


if __name__ == "__main__":
    main()
