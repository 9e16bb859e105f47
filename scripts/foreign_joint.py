#!/usr/bin/env python3
"""A bonded joint assembled independently of rfmlab (scikit-fem), written in the matrix formats
of other FE programs, with its own lowest modes.

The joint: a steel beam 200 x 12 x 25 mm (x, y, z) on a 2 mm adhesive bond line 40 mm long,
from x = 30 mm to x = 70 mm (a patch away from the beam's end), whose lower face is held by a
rigid base. 27-node triquadratic hexahedra (scikit-fem ElementHex2), graded: 5 mm along x,
two elements through the beam and two through the bond line, two across the width.

Written into OUT_DIR:
  abaqus/joint_MASS1.mtx   M over the whole joint          FORMAT=MATRIX INPUT (node, DOF, node,
  abaqus/joint_STIF1.mtx   K_b over the adherend elements   DOF, value), lower triangle; a DOF
  abaqus/joint_STIF2.mtx   S over the adhesive elements     held by the base carries 1e36 on its
                           at E = 1 Pa, nu fixed             stiffness diagonal, as Abaqus writes
  abaqus/points.csv        node form of the DOF map (id,direction,node,weight)
  hb/M.hb                  M, RSA (lower triangle, written by this script's own writer)
  hb/K_b.hb, hb/S.hb       K_b, S, RUA (scipy.io.hb_write)
  hb/joint.mapping         ANSYS-style equation mapping: equation, node, DOF label
  hb/points.csv            node form of the DOF map (with the mapping file)
  hb/dofmap_eq.csv         equation form of the same map (id,direction,dof,weight)
  modes.json               the lowest modes of the free DOFs at a real adhesive modulus (eigsh)

Units: SI (m, kg, N, Pa). Node labels: 1..N over scikit-fem's DOF sites (vertices, edge, face
and cell midpoints); DOF 1, 2, 3 = x, y, z. The Harwell-Boeing files hold the free DOFs only
(the base's DOFs removed), in node-label order.

Usage: foreign_joint.py OUT_DIR [--modulus 7e6] [--modes 8]
"""
import argparse
import json
import os
import sys

import numpy as np
import scipy
import scipy.io
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import skfem
from skfem import Basis, BilinearForm, ElementHex2, ElementVector, MeshHex, asm
from skfem.helpers import ddot, dot, sym_grad, trace, eye

GEOMETRY = {
    "beam_length_m": 0.200,
    "beam_thickness_m": 0.012,
    "beam_width_m": 0.025,
    "adhesive_x_start_m": 0.030,
    "adhesive_length_m": 0.040,
    "adhesive_thickness_m": 0.002,
}
BEAM = {"E": 205e9, "nu": 0.29, "rho": 7850.0}
ADHESIVE = {"nu": 0.45, "rho": 1250.0}
POINTS_X = [0.100, 0.130, 0.160, 0.190]  # ids 1..4 on the upper face centreline, +y


def grid(breaks, h):
    """Coordinates through every break point with spacing <= h."""
    out = [breaks[0]]
    for a, b in zip(breaks[:-1], breaks[1:]):
        n = max(1, int(np.ceil((b - a) / h - 1e-9)))
        out.extend(list(np.linspace(a, b, n + 1)[1:]))
    return np.array(out)


def mesh():
    g = GEOMETRY
    x0, x1 = g["adhesive_x_start_m"], g["adhesive_x_start_m"] + g["adhesive_length_m"]
    x = grid([0.0, x0, x1, g["beam_length_m"]], 0.005)
    ta, tb = g["adhesive_thickness_m"], g["beam_thickness_m"]
    y = np.array([-ta, -ta / 2, 0.0, tb / 2, tb])
    z = np.linspace(0.0, g["beam_width_m"], 3)
    m = MeshHex.init_tensor(x, y, z)
    c = m.p[:, m.t].mean(axis=1)  # element centroids
    below = c[1] < 0.0
    outside = (c[0] < x0) | (c[0] > x1)
    m = m.remove_elements(np.nonzero(below & outside)[0])
    c = m.p[:, m.t].mean(axis=1)
    adhesive = np.nonzero(c[1] < 0.0)[0]
    beam = np.nonzero(c[1] > 0.0)[0]
    return m, beam, adhesive


def elasticity(E, nu):
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))

    @BilinearForm
    def form(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return 2.0 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev)

    return form


def density(rho):
    @BilinearForm
    def form(u, v, w):
        return rho * dot(u, v)

    return form


def assemble():
    m, beam, adhesive = mesh()
    e = ElementVector(ElementHex2())
    b_all = Basis(m, e, intorder=6)
    b_beam = Basis(m, e, elements=beam, intorder=6)
    b_adh = Basis(m, e, elements=adhesive, intorder=6)
    K_b = asm(elasticity(BEAM["E"], BEAM["nu"]), b_beam).tocsr()
    S = asm(elasticity(1.0, ADHESIVE["nu"]), b_adh).tocsr()
    M = (asm(density(BEAM["rho"]), b_beam) + asm(density(ADHESIVE["rho"]), b_adh)).tocsr()
    # DOF sites ("nodes"): columns of the nodal, edge, facet and interior DOF arrays
    blocks = [b_all.nodal_dofs, b_all.edge_dofs, b_all.facet_dofs, b_all.interior_dofs]
    sites = np.hstack([blk for blk in blocks if blk.size])  # 3 x n_sites: x, y, z DOF numbers
    label_of_dof = np.empty(b_all.N, dtype=np.int64)
    comp_of_dof = np.empty(b_all.N, dtype=np.int64)
    for s in range(sites.shape[1]):
        for c in range(3):
            label_of_dof[sites[c, s]] = s + 1
            comp_of_dof[sites[c, s]] = c + 1
    loc = b_all.doflocs
    fixed = np.nonzero(np.isclose(loc[1], -GEOMETRY["adhesive_thickness_m"]))[0]
    return {
        "mesh": m,
        "M": M,
        "K_b": K_b,
        "S": S,
        "sites": sites,
        "label": label_of_dof,
        "comp": comp_of_dof,
        "loc": loc,
        "fixed": fixed,
        "n_beam": len(beam),
        "n_adhesive": len(adhesive),
    }


def point_site(a, x):
    """Node label of the DOF site at (x, beam top, mid-width)."""
    loc, sites = a["loc"], a["sites"]
    target = np.array([x, GEOMETRY["beam_thickness_m"], GEOMETRY["beam_width_m"] / 2])
    d = np.linalg.norm(loc[:, sites[1]].T - target, axis=1)
    s = int(np.argmin(d))
    if d[s] > 1e-9:
        raise SystemExit(f"no node at {target}: nearest {d[s]:.3e} m away")
    return s + 1


def order_by_label(a):
    """Global DOF numbers sorted by (node label, DOF): the equation order of both formats."""
    return np.lexsort((a["comp"], a["label"]))


def write_abaqus(path, A, a, stiffness_like):
    """One matrix in FORMAT=MATRIX INPUT, lower triangle in (label, DOF) order; DOFs held by
    the base get 1e36 on a stiffness diagonal."""
    rank = np.empty(A.shape[0], dtype=np.int64)
    rank[order_by_label(a)] = np.arange(A.shape[0])
    C = sp.coo_matrix(A)
    keep = (rank[C.row] >= rank[C.col]) & (C.data != 0.0)
    r, c, v = C.row[keep], C.col[keep], C.data[keep].copy()
    if stiffness_like:
        fixed = np.zeros(A.shape[0], dtype=bool)
        fixed[a["fixed"]] = True
        v[(r == c) & fixed[r]] = 1e36
    order = np.lexsort((rank[r], rank[c]))  # column by column, as Abaqus lists them
    lab, comp = a["label"], a["comp"]
    with open(path, "w") as f:
        for k in order:
            f.write(f"{lab[r[k]]},{comp[r[k]]}, {lab[c[k]]},{comp[c[k]]}, {v[k]:.17e}\n")


def write_rsa(path, A, title, key):
    """Harwell-Boeing RSA (real symmetric assembled, lower triangle by columns)."""
    L = sp.tril(sp.csc_matrix(A)).tocsc()
    L.eliminate_zeros()
    L.sort_indices()
    n, nnz = A.shape[0], L.nnz
    ptr, ind, val = L.indptr + 1, L.indices + 1, L.data
    iw = len(str(nnz + 1)) + 1
    per = 80 // iw

    def ints(v):
        return ["".join(f"{x:>{iw}d}" for x in v[i:i + per]) for i in range(0, len(v), per)]

    vals = ["".join(f"{x:>25.16E}" for x in val[i:i + 3]) for i in range(0, len(val), 3)]
    p, r = ints(ptr), ints(ind)
    with open(path, "w") as f:
        f.write(f"{title:<72.72}{key:<8.8}\n")
        f.write(f"{len(p) + len(r) + len(vals):>14d}{len(p):>14d}{len(r):>14d}{len(vals):>14d}{0:>14d}\n")
        f.write(f"{'RSA':<14}{n:>14d}{n:>14d}{nnz:>14d}{0:>14d}\n")
        f.write(f"{f'({per}I{iw})':<16}{f'({per}I{iw})':<16}{'(3E25.16)':<20}{'':<20}\n")
        for block in (p, r, vals):
            for line in block:
                f.write(line + "\n")


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--modulus", type=float, default=7.0e6, help="adhesive E (Pa) for modes.json")
    ap.add_argument("--modes", type=int, default=8)
    args = ap.parse_args(argv[1:])
    a = assemble()
    out = args.out
    os.makedirs(os.path.join(out, "abaqus"), exist_ok=True)
    os.makedirs(os.path.join(out, "hb"), exist_ok=True)
    ids = [point_site(a, x) for x in POINTS_X]

    # Abaqus: the whole joint's mass, the adherends' and the adhesive's stiffness
    ab = os.path.join(out, "abaqus")
    write_abaqus(os.path.join(ab, "joint_MASS1.mtx"), a["M"], a, False)
    write_abaqus(os.path.join(ab, "joint_STIF1.mtx"), a["K_b"], a, True)
    write_abaqus(os.path.join(ab, "joint_STIF2.mtx"), a["S"], a, True)
    with open(os.path.join(ab, "points.csv"), "w") as f:
        f.write("id,direction,node,weight\n")
        for i, node in enumerate(ids):
            f.write(f"{i + 1},+y,{node},1.0\n")

    # Harwell-Boeing over the free DOFs, in (label, DOF) order
    order = order_by_label(a)
    fixed = np.zeros(a["M"].shape[0], dtype=bool)
    fixed[a["fixed"]] = True
    free = order[~fixed[order]]
    sub = {k: a[k][free][:, free].tocsc() for k in ("M", "K_b", "S")}
    hb = os.path.join(out, "hb")
    write_rsa(os.path.join(hb, "M.hb"), sub["M"], "foreign joint: mass (kg)", "M")
    scipy.io.hb_write(os.path.join(hb, "K_b.hb"), sub["K_b"])
    scipy.io.hb_write(os.path.join(hb, "S.hb"), sub["S"])
    names = {1: "UX", 2: "UY", 3: "UZ"}
    eq_of = {}
    with open(os.path.join(hb, "joint.mapping"), "w") as f:
        f.write(" Matrix Eqn   Node  DOF\n")
        for e, g in enumerate(free):
            f.write(f"{e + 1:>10d} {a['label'][g]:>8d}  {names[a['comp'][g]]}\n")
            eq_of[(a["label"][g], a["comp"][g])] = e + 1
    with open(os.path.join(hb, "points.csv"), "w") as f:
        f.write("id,direction,node,weight\n")
        for i, node in enumerate(ids):
            f.write(f"{i + 1},+y,{node},1.0\n")
    with open(os.path.join(hb, "dofmap_eq.csv"), "w") as f:
        f.write("id,direction,dof,weight\n")
        for i, node in enumerate(ids):
            f.write(f"{i + 1},+y,{eq_of[(node, 2)]},1.0\n")

    # the script's own modes at a real modulus
    K = (sub["K_b"] + args.modulus * sub["S"]).tocsc()
    w2, _ = sla.eigsh(K, k=args.modes, M=sub["M"].tocsc(), sigma=0.0, which="LM", tol=0.0)
    w2 = np.sort(w2)
    freqs = np.sqrt(w2) / (2 * np.pi)
    summary = {
        "generator": f"scripts/foreign_joint.py (scikit-fem {skfem.__version__}, "
                     f"scipy {scipy.__version__}, numpy {np.__version__})",
        "geometry": GEOMETRY,
        "beam": BEAM,
        "adhesive": ADHESIVE,
        "elements": {"beam": a["n_beam"], "adhesive": a["n_adhesive"], "type": "Hex27"},
        "n_dof_total": int(a["M"].shape[0]),
        "n_dof_free": int(len(free)),
        "n_dof_fixed": int(fixed.sum()),
        "points": [{"id": i + 1, "x_m": x, "node": n} for i, (x, n) in enumerate(zip(POINTS_X, ids))],
        "modulus_pa": args.modulus,
        "freq_hz": [float(f) for f in freqs],
    }
    with open(os.path.join(out, "modes.json"), "w") as f:
        json.dump(summary, f, indent=2)
    print(json.dumps({k: summary[k] for k in ("n_dof_free", "freq_hz")}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
