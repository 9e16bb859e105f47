#!/usr/bin/env python3
"""Independent time-domain virtual experiment of a bonded joint that is not the paper's.

Written for testing rfmlab's identification on data made by code that shares nothing with it:
numpy, scipy and scikit-fem only (no rfmlab import, no rfmlab formulas beyond the published
Model 4 law), 27-node triquadratic hexahedra instead of rfmlab's 20-node ones, a graded mesh,
its own reduced basis and its own Welch H1 measurement chain.

The joint (SI; x along the beam, y through the thickness = the excitation direction, z across):
  steel beam 0.400 x 0.008 x 0.025 m (E 205 GPa, nu 0.29, rho 7850), x in [0, 0.4],
  y in [0, 0.008], z in [0, 0.025];
  adhesive bond line under the beam's end: x in [0, 0.030], y in [-0.003, 0], full width,
  nu 0.45, rho 1250, its lower face y = -0.003 fixed (rigid base);
  points 1-4 at x = 0.120, 0.200, 0.280, 0.360 on the upper face centreline (y = 0.008,
  z = 0.0125), accelerations in +y; the force at point 2 in +y.
Adhesive law (rfmlab's Model 4, docs/method.md): E*(w) = E0 + j h + j w eta1 E1 / (E1 + j w eta1);
truth E0 = 7.2e6 Pa, h = 1.1e6 Pa, E1 = 2.8e6 Pa, eta1 = 5.0e3 Pa s. Conventions: exp(+j w t),
E* = E' + j E'' with E'' > 0, accelerance in (m/s^2)/N.

FE model. K(w) = K_b + E*(w) S - w^2 M, with K_b the beam's stiffness, S the adhesive's stiffness
assembled at unit Young's modulus and M the consistent mass; 3x3x3 Gauss points (exact for these
box elements). Two meshes (--mesh):

  matched (default): the discretisation a study with rfmlab's default `element_size = 0.005`
    gets for this joint, built by this script's own code: a uniform grid of 20-node serendipity
    hexahedra (ElementHexS2), 6 x 5 mm along the bond line, 74 x 5 mm along the rest of the
    beam, 2 through the bond line, 2 through the beam, 5 across the whole width (the centreline
    is a mid-edge node). 15 846 free DOFs, 19 s. Its lowest modes at 7.2 MPa (real): 8.1278,
    15.6438, 156.5929, 199.6521, 261.9115, 398.2943 Hz, rfmlab's to the digits printed. Data on
    this mesh test rfmlab's element, assembly, reduced model, estimator model and inference,
    not its mesh convergence.
  graded: 27-node triquadratic hexahedra (ElementHex2) on a tensor grid graded towards the edges
    of the bond line, where the nearly incompressible adhesive (nu 0.45) bonded to a rigid base
    and a stiff beam has singular corner fields: element sizes grow linearly with the distance
    from x = 0 and 0.030, from both faces of the bond line and from the free side z = 0 (sizes
    in MESH). The joint and its load are symmetric about z = 0.0125 and the points lie on that
    plane, so the data come from the half z in [0, 0.0125] with u_z = 0 on the plane (the force
    halved); the antisymmetric modes (u_x = u_y = 0 on the plane) are computed for the mode
    lists. 31 388 free DOFs in the measured half, 80 s. The first y mode at 7.2 MPa (real)
    under --refine-mesh 0.7 / 1 / 1.4: 15.4540 / 15.4130 / 15.3936 Hz (10 660 / 31 388 /
    72 900 DOFs): second-order convergence in the refinement, an extrapolated 15.373 Hz. The
    matched (rfmlab default) mesh's 15.6438 Hz is 1.8 % above it: the measure of what a 5 mm
    mesh with two elements through a 3 mm bond line misses.

Reduced basis (for the FRF at every FFT bin of the record): a block Krylov basis at the real
moduli E_r = 7.2 and 10 MPa (E'(w) runs from 7.2 to 9.9 MPa over 0-500 Hz): K_r^-1 f, then 14
frequency moments K_r^-1 M v and 4 modulus moments K_r^-1 S v each (K_r = K_b + E_r S),
M-orthonormalised; the projected pencil is solved per bin. It is checked against direct sparse
LU solves of the full model (scipy SuperLU) at --verify frequencies 1-500 Hz including the peaks;
the largest error relative to each FRF's peak is 6.6e-7 on the matched mesh and 5.4e-8 on the
graded one (the run stops above 1e-6).

Measurement chain (as the independent virtual experiments of docs/data.md): fs 2048 Hz; a
record of N = 1024 (segments + 1) samples; the force is white Gaussian noise with its FFT bins outside
(0, 500] Hz zeroed, scaled to 3.3 N RMS; the responses are the exact periodic steady state (the
record's FFT times the FRF at every bin up to 500 Hz, zero above, inverse FFT); white sensor
noise 0.002 N RMS on the force and 0.002 m/s^2 RMS on each acceleration; Welch with periodic
Hann 2048-sample (1 s) blocks at 50 % overlap: H1 = G_fa / G_ff, coherence
|G_fa|^2 / (G_ff G_aa), lines 1-500 Hz. Random numbers: numpy default_rng(seed): the force
record, then the force noise, then the noise of channels 1-4.

Written into OUT_DIR:
  level1.uff   UFF58 ASCII: the 4 accelerances H1 (func type 4, response node i +Y, reference
               node 2 +Y, (m/s^2)/N) then the 4 coherences (func type 6)
  truth.json   geometry, materials, law and parameters, E*(f), the modes, the mesh, its
               convergence, the reduced basis check, the chain's settings and statistics,
               versions
  exact.npz    freq_hz (1..500) and H_exact (4 x 500 complex): the noise-free accelerance at
               the lines (no leakage), E_star at the lines; for checks only

Usage: independent_td_joint.py OUT_DIR [--mesh matched|graded] [--segments 200] [--seed 21]
                               [--refine-mesh 1] [--check-mesh] [--verify 10] [--jobs 2]
"""
import argparse
import json
import multiprocessing
import os
import platform
import sys
import time

import numpy as np
import scipy
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import skfem
from skfem import Basis, BilinearForm, ElementHex2, ElementHexS2, ElementVector, MeshHex, asm
from skfem.helpers import ddot, dot, sym_grad, trace

import pyuff

VERSION = "1.0"

BEAM_L, BEAM_T, BEAM_W = 0.400, 0.008, 0.025
BOND_L, BOND_T = 0.030, 0.003
STEEL = {"E": 205e9, "nu": 0.29, "rho": 7850.0}
GLUE = {"nu": 0.45, "rho": 1250.0}
POINTS_X = (0.120, 0.200, 0.280, 0.360)  # ids 1..4, upper face centreline, +y
DRIVE = 2  # the force acts at point 2, +y
TRUTH = {"E0": 7.2e6, "h": 1.1e6, "E1": 2.8e6, "eta1": 5.0e3}
REF_MODULI = (7.2e6, 10.0e6)  # real moduli of the reduced basis's expansions
KRYLOV_DEPTH = 14  # frequency moments per modulus
KRYLOV_S_DEPTH = 4  # modulus moments per modulus
MODAL_DEPTH = 6  # block Krylov depth of the mode lists (rigid-motion inertia loads per half)
MODAL_S_DEPTH = 1  # and their modulus moments
CHAIN = {
    "fs_hz": 2048.0,
    "block": 2048,
    "overlap": 0.5,
    "window": "hann (periodic)",
    "force_band_hz": [0.0, 500.0],
    "force_rms_n": 3.3,
    "force_noise_rms_n": 0.002,
    "accel_noise_rms_ms2": 0.002,
    "lines_hz": [1, 500],
}

# Element sizes (m) of the graded tensor grid: (size at the graded end(s), growth of the size per
# unit distance, cap). x over the bond line graded towards both its ends, x over the free beam
# graded away from x = 0.030 (breaks at the points), y in the bond line graded towards both faces,
# z graded away from the free side z = 0; y_beam elements through the beam. --refine-mesh R
# divides every size and growth rate by R (and multiplies y_beam by R).
MESH = {
    "element": "hex27",
    "x_bond": (5e-4, 0.5, 3e-3),
    "x_beam": (1e-3, 0.8, 0.015),
    "y_bond": (5e-4, 0.6),
    "y_beam": 3,
    "z": (5e-4, 0.6, 4e-3),
}

# The matched mesh (--mesh matched, the default): the discretisation a user's study with
# rfmlab's default `element_size = 0.005` gets for this joint, built here by this script's own
# code: a uniform tensor grid of 20-node serendipity hexahedra (scikit-fem ElementHexS2, 3x3x3
# Gauss) with 6 x 5 mm cells along the bond line, 74 x 5 mm along the rest of the beam, 2 cells
# through the bond line and 2 through the beam, 5 across the whole width (the centreline is the
# mid-edge node of the middle cells, so no symmetry half). Data on this mesh test everything of
# rfmlab's chain but its mesh convergence; the graded mesh measures that.
MESH_MATCHED = {
    "element": "hex20",
    "uniform": {"x_bond": 6, "x_beam": 74, "y_bond": 2, "y_beam": 2, "z": 5},
}

# Recorded by --check-mesh at --refine-mesh 1 (truth.json carries it when not recomputed).
CONVERGENCE_RECORDED = {}


def model4(w, p):
    """Model 4: a spring E0, a structural damper h and one Maxwell branch (E1, eta1)."""
    w = np.asarray(w, dtype=float)
    return p["E0"] + 1j * p["h"] + 1j * w * p["eta1"] * p["E1"] / (p["E1"] + 1j * w * p["eta1"])


# ----------------------------------------------------------------------------------- mesh

def graded_nodes(a, b, h_a, h_b, grow, h_max):
    """Nodes on [a, b] with element size min(h_max, h_end + grow * distance from a graded end)
    (h_a or h_b None: that end not graded): as many elements as the integral of 1/size."""
    span = b - a
    d = np.concatenate([np.linspace(0.0, span, 4001)]
                       + [np.geomspace(1e-4 * h, span, 600) for h in (h_a, h_b) if h]
                       + [span - np.geomspace(1e-4 * h, span, 600) for h in (h_a, h_b) if h])
    d = np.unique(np.clip(d, 0.0, span))
    size = np.full_like(d, h_max)
    if h_a:
        size = np.minimum(size, h_a + grow * d)
    if h_b:
        size = np.minimum(size, h_b + grow * (span - d))
    dens = 1.0 / size
    s = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(d))])
    n = max(1, int(np.ceil(s[-1] - 1e-6)))
    return a + np.interp(np.linspace(0.0, s[-1], n + 1), s, d)


def join(*parts):
    out = [parts[0][:1]]
    for p in parts:
        out.append(p[1:])
    return np.concatenate(out)


def grid_axes(spec, refine=1.0, half=True):
    """Node coordinates along x, y and z; `refine` divides every size and growth rate (or
    multiplies the counts of a uniform spec)."""
    r = float(refine)
    if "uniform" in spec:
        n = {k: int(round(v * r)) for k, v in spec["uniform"].items()}
        x = join(np.linspace(0.0, BOND_L, n["x_bond"] + 1),
                 np.linspace(BOND_L, BEAM_L, n["x_beam"] + 1))
        y = join(np.linspace(-BOND_T, 0.0, n["y_bond"] + 1), np.linspace(0.0, BEAM_T, n["y_beam"] + 1))
        z = np.linspace(0.0, BEAM_W, n["z"] + 1)
        return x, y, z, n["y_bond"]
    he, g, hm = spec["x_bond"]
    x = [graded_nodes(0.0, BOND_L, he / r, he / r, g / r, hm / r)]
    he, g, hm = spec["x_beam"]
    breaks = (BOND_L,) + POINTS_X + (BEAM_L,)
    for i, (a, b) in enumerate(zip(breaks[:-1], breaks[1:])):
        x.append(graded_nodes(a, b, he / r if i == 0 else None, None, g / r, hm / r))
    x = join(*x)
    he, g = spec["y_bond"]
    y_bond = graded_nodes(-BOND_T, 0.0, he / r, he / r, g / r, BOND_T)
    y_beam = np.linspace(0.0, BEAM_T, int(round(spec["y_beam"] * r)) + 1)
    y = join(y_bond, y_beam)
    he, g, hm = spec["z"]
    zc = BEAM_W / 2
    z = graded_nodes(0.0, zc, he / r, None, g / r, hm / r)
    if not half:
        z = join(z, (BEAM_W - z[::-1]))
    return x, y, z, len(y_bond) - 1


def joint_mesh(spec, refine=1.0, half=True):
    x, y, z, ny_bond = grid_axes(spec, refine, half)
    m = MeshHex.init_tensor(x, y, z)
    c = m.p[:, m.t].mean(axis=1)
    m = m.remove_elements(np.nonzero((c[1] < 0.0) & (c[0] > BOND_L))[0])
    c = m.p[:, m.t].mean(axis=1)
    counts = {"x": len(x) - 1, "y_bond": ny_bond, "y_beam": len(y) - 1 - ny_bond, "z": len(z) - 1}
    return m, np.nonzero(c[1] > 0.0)[0], np.nonzero(c[1] < 0.0)[0], counts


# ----------------------------------------------------------------------------------- FE

def isotropic(E, nu):
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))

    def energy(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return lam * trace(eu) * trace(ev) + 2.0 * mu * ddot(eu, ev)

    return BilinearForm(energy)


def inertia(rho):
    return BilinearForm(lambda u, v, w: rho * dot(u, v))


class Joint:
    """The assembled half (or whole) joint: K_b, S, M over all DOFs, the DOFs' components and
    locations, and the y DOFs of the points."""

    def __init__(self, spec, refine=1.0, half=True):
        t0 = time.time()
        self.half = half
        self.mesh, beam, bond, self.counts = joint_mesh(spec, refine, half)
        e = ElementVector(ElementHexS2() if spec["element"] == "hex20" else ElementHex2())
        b_beam = Basis(self.mesh, e, elements=beam, intorder=4)
        b_bond = Basis(self.mesh, e, elements=bond, intorder=4)
        self.K_b = asm(isotropic(STEEL["E"], STEEL["nu"]), b_beam).tocsr()
        self.S = asm(isotropic(1.0, GLUE["nu"]), b_bond).tocsr()
        self.M = (asm(inertia(STEEL["rho"]), b_beam) + asm(inertia(GLUE["rho"]), b_bond)).tocsr()
        self.n = self.K_b.shape[0]
        self.loc = b_beam.doflocs
        self.comp = np.empty(self.n, dtype=np.int64)
        for c, idx in enumerate(b_beam.split_indices()):
            self.comp[idx] = c
        self.n_elements = {"beam": int(len(beam)), "bond": int(len(bond))}
        self.assembly_s = time.time() - t0
        self.point_dofs = []
        for x in POINTS_X:
            target = np.array([x, BEAM_T, BEAM_W / 2])
            cand = np.nonzero(self.comp == 1)[0]
            d = np.linalg.norm(self.loc[:, cand].T - target, axis=1)
            k = int(np.argmin(d))
            if d[k] > 1e-12:
                raise SystemExit(f"no node at point {target}")
            self.point_dofs.append(int(cand[k]))

    def free(self, kind):
        """Free DOFs: the base fixed; on the plane z = 0.0125 u_z = 0 ('sym') or u_x = u_y = 0
        ('anti'); 'full' for a whole-width mesh."""
        held = np.isclose(self.loc[1], -BOND_T)
        if kind != "full":
            plane = np.isclose(self.loc[2], BEAM_W / 2)
            held |= plane & ((self.comp == 2) if kind == "sym" else (self.comp != 2))
        return np.nonzero(~held)[0]

    def restrict(self, kind):
        f = self.free(kind)
        return f, self.K_b[f][:, f].tocsc(), self.S[f][:, f].tocsc(), self.M[f][:, f].tocsc()


def factor(A):
    """Sparse LU (SuperLU, minimum degree on A + A^T, no pivoting: the matrices here are
    symmetric, real or complex)."""
    return sla.splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                    options={"SymmetricMode": True})


def energy_shares(phi, M, comp):
    """Kinetic-energy shares of x, y, z in a mode (the consistent mass does not couple them)."""
    out = []
    for c in range(3):
        v = np.where(comp == c, phi, 0.0)
        out.append(float(np.real(np.vdot(v, M @ v))))
    tot = sum(out)
    return [o / tot for o in out]


class Half:
    """One half of the joint (its free DOFs, matrices, force, outputs) with cached LUs of
    K_b + E S at real reference moduli."""

    def __init__(self, joint, kind):
        self.kind = kind
        self.free, self.Kb, self.S, self.M = joint.restrict(kind)
        self.comp = joint.comp[self.free]
        self.loc = joint.loc[:, self.free]
        n = len(self.free)
        self.f = np.zeros(n)
        if kind == "anti":  # the points lie on the plane, held in y: no force, no outputs
            self.out = np.zeros(0, dtype=np.int64)
        else:
            pos = {g: i for i, g in enumerate(self.free)}
            self.out = np.array([pos[d] for d in joint.point_dofs])
            self.f[self.out[DRIVE - 1]] = 0.5 if kind == "sym" else 1.0  # the half takes half
        self._lu = {}

    def lu(self, E):
        if E not in self._lu:
            self._lu[E] = factor(self.Kb + E * self.S)
        return self._lu[E]

    def mode_residual(self, E, lam, phi):
        """||K_r^-1 (K_b + E S - lambda M) phi||_M / ||phi||_M with K_r = K_b + E_r S at the first
        reference modulus factored: the mode's error measured in displacement (energy-scaled)."""
        r = self.Kb @ phi + E * (self.S @ phi) - lam * (self.M @ phi)
        lu = next(iter(self._lu.values()))  # the first reference LU
        d = lu.solve(np.ascontiguousarray(r.real)) + 1j * lu.solve(np.ascontiguousarray(r.imag))
        return float(np.sqrt(np.real(np.vdot(d, self.M @ d)) / np.real(np.vdot(phi, self.M @ phi))))

    def inertia_loads(self):
        """Inertia loads of the rigid motions this half allows: sym: x, y and rotation about z;
        anti: z, rotation about x and rotation about y."""
        x, y, z = self.loc
        c = self.comp
        xc, yc, zc = BEAM_L / 2, BEAM_T / 2, BEAM_W / 2
        if self.kind == "full":  # all six rigid motions
            return Half.inertia_loads(_Kind(self, "sym")) + Half.inertia_loads(_Kind(self, "anti"))
        if self.kind == "anti":
            motions = [(c == 2) * 1.0,
                       np.where(c == 1, -(z - zc), np.where(c == 2, y - yc, 0.0)),
                       np.where(c == 2, x - xc, np.where(c == 0, -(z - zc), 0.0))]
        else:
            motions = [(c == 0) * 1.0, (c == 1) * 1.0,
                       np.where(c == 0, -(y - yc), np.where(c == 1, x - xc, 0.0))]
        return [self.M @ m for m in motions]


class _Kind:
    """A view of a half under another symmetry label (for its rigid-motion loads)."""

    def __init__(self, half, kind):
        self.loc, self.comp, self.M, self.kind = half.loc, half.comp, half.M, kind


class MBasis:
    """A growing M-orthonormal basis (Gram-Schmidt, two passes; a vector whose remainder falls
    below rtol of its M-norm is dropped)."""

    def __init__(self, M, rtol=1e-10):
        self.M, self.rtol, self.Q, self.MQ = M, rtol, [], []

    def add(self, v):
        v = np.array(v, dtype=float)
        n0 = np.sqrt(v @ (self.M @ v))
        if n0 == 0.0:
            return None
        v /= n0
        for _ in range(2):
            for q, mq in zip(self.Q, self.MQ):
                v -= (mq @ v) * q
        nv = np.sqrt(v @ (self.M @ v))
        if nv < self.rtol:
            return None
        v /= nv
        self.Q.append(v)
        self.MQ.append(self.M @ v)
        return v

    def matrix(self):
        return np.column_stack(self.Q)


def krylov(half, moduli, starts, depth, s_depth=0):
    """Block Krylov basis: for each modulus E_r (LU of K_r = K_b + E_r S) and start load b,
    v_0 = K_r^-1 b, v_k+1 = K_r^-1 M v_k for k < depth (the frequency moments about w = 0, whose
    span converges to the lowest modes the load reaches) and K_r^-1 S v_k for k < s_depth (the
    moments in the modulus)."""
    basis = MBasis(half.M)
    for E in moduli:
        lu = half.lu(E)
        block = [basis.add(lu.solve(b)) for b in starts]
        chains = [[v] for v in block]
        for _ in range(depth):
            block = [basis.add(lu.solve(half.M @ v)) if v is not None else None for v in block]
            for ch, v in zip(chains, block):
                if v is not None:
                    ch.append(v)
            if all(v is None for v in block):
                break
        for ch in chains:
            for v in ch[:s_depth]:
                if v is not None:
                    basis.add(lu.solve(half.S @ v))
    return basis.matrix()


class Projected:
    """A half projected on an M-orthonormal basis V."""

    def __init__(self, half, V):
        self.half, self.V = half, V
        self.Kr = V.T @ (half.Kb @ V)
        self.Sr = V.T @ (half.S @ V)
        self.Mr = V.T @ (half.M @ V)
        self.fr = V.T @ half.f
        self.Cr = V[half.out, :]

    def receptance(self, w, E, chunk=2000):
        """u at the points (4 x len(w)) for a unit force at the drive point: batched solves of
        the projected pencil."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        E = np.broadcast_to(np.asarray(E, dtype=complex), w.shape)
        out = np.empty((len(self.half.out), len(w)), dtype=complex)
        for s in range(0, len(w), chunk):
            ww, ee = w[s:s + chunk], E[s:s + chunk]
            A = (self.Kr[None] + ee[:, None, None] * self.Sr[None]
                 - (ww ** 2)[:, None, None] * self.Mr[None])
            rhs = np.broadcast_to(self.fr.astype(complex), (len(ww), len(self.fr)))[..., None]
            q = np.linalg.solve(A, rhs)[..., 0]
            out[:, s:s + chunk] = (q @ self.Cr.T).T
        return out

    def accelerance(self, w, E):
        return -(np.asarray(w, dtype=float) ** 2) * self.receptance(w, E)

    def eig(self, E):
        """Eigenpairs of the projected (K_b + E S, M), ascending in Re(lambda)."""
        E = complex(E)
        if E.imag != 0.0:
            lam, Q = la.eig(self.Kr + E * self.Sr, self.Mr)
        else:
            lam, Q = la.eigh(self.Kr + E.real * self.Sr, self.Mr)
        order = np.argsort(lam.real)
        return lam[order], Q[:, order]

    def residual(self, E, lam, q):
        phi = self.V @ q
        return self.half.mode_residual(E, lam, phi), phi


def direct_receptance(half, w, E):
    """Full-order solve of (K_b + E S - w^2 M) x = f by complex sparse LU with one step of
    iterative refinement; x at the points and the relative residual."""
    A = (half.Kb + E * half.S - w ** 2 * half.M).tocsc()
    lu = factor(A)
    b = half.f.astype(complex)
    x = lu.solve(b)
    x += lu.solve(b - A @ x)
    # normwise backward error ||A x - b|| / (||A||_inf ||x|| + ||b||)
    resid = np.linalg.norm(A @ x - b) / (abs(A).sum(axis=1).max() * np.linalg.norm(x)
                                          + np.linalg.norm(b))
    return x[half.out], float(resid)


_JOB = {}


def _direct_job(wE):
    """A direct solve in a worker process (the half is inherited through fork)."""
    return direct_receptance(_JOB["half"], *wE)


def direct_receptances(half, wE, jobs):
    if jobs <= 1 or len(wE) == 1 or "fork" not in multiprocessing.get_all_start_methods():
        return [direct_receptance(half, w, E) for w, E in wE]
    _JOB["half"] = half
    with multiprocessing.get_context("fork").Pool(min(jobs, len(wE))) as pool:
        return pool.map(_direct_job, wE, chunksize=1)


def mode_row(proj, E, lam, q, kind):
    res, phi = proj.residual(E, lam, q)
    return {"f_hz": float(np.sqrt(lam.real) / (2 * np.pi)), "eta": float(lam.imag / lam.real),
            "symmetry": kind,
            "energy_xyz": [round(s, 6) for s in energy_shares(phi, proj.half.M, proj.half.comp)],
            "residual": res}


def mode_list(proj, E, fmax_hz, kind):
    lam, Q = proj.eig(E)
    lam = lam.astype(complex)
    return [mode_row(proj, complex(E), lam[k], Q[:, k], kind) for k in range(len(lam))
            if np.sqrt(lam[k].real) / (2 * np.pi) <= fmax_hz]


def self_consistent(proj, law, fmax_hz, iters=200):
    """Complex modes of the measured half with E* at their own frequency:
    w_r^2 = Re(lambda), E = E*(w_r) (fixed-point iteration on the projected problem)."""
    lam0, _ = proj.eig(law(2 * np.pi * 20.0))
    out = []
    for l0 in lam0[np.sqrt(lam0.real) / (2 * np.pi) < fmax_hz]:
        lam = l0
        for _ in range(iters):
            lams, Q = proj.eig(law(np.sqrt(lam.real)))
            k = int(np.argmin(np.abs(lams - lam)))
            done = abs(lams[k] - lam) < 1e-14 * abs(lam)
            lam = lams[k]
            if done:
                break
        E = complex(law(np.sqrt(lam.real)))
        row = mode_row(proj, E, lam, Q[:, k], "sym")
        row.update({"E_storage_pa": E.real, "E_loss_pa": E.imag})
        out.append(row)
    return out


def modal_basis(half, moduli):
    """Block Krylov basis for the mode lists: the rigid-motion inertia loads of the half (and
    the force on the measured half), frequency and modulus moments."""
    starts = half.inertia_loads() + ([half.f] if half.kind == "sym" else [])
    return Projected(half, krylov(half, moduli, starts, MODAL_DEPTH, MODAL_S_DEPTH))


def whole_joint_modes(joint, E, count):
    """The lowest modes of the whole joint at a real modulus E: Ritz pairs of both halves."""
    rows = []
    for kind in (("sym", "anti") if joint.half else ("full",)):
        rows += mode_list(modal_basis(Half(joint, kind), (E,)), E, np.inf, kind)[:count]
    rows.sort(key=lambda r: r["f_hz"])
    return rows[:count]


# ----------------------------------------------------------------------------------- chain

def hann_periodic(n):
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


def measure(rom, law, segments, seed):
    """Simulate the record and return lines, H1 (4 x L), coherence (4 x L) and statistics."""
    fs, nb = CHAIN["fs_hz"], CHAIN["block"]
    step = int(nb * (1.0 - CHAIN["overlap"]))
    N = nb + step * (segments - 1)
    rng = np.random.default_rng(seed)
    F = np.fft.rfft(rng.standard_normal(N))
    fk = np.arange(len(F)) * fs / N
    band = (fk > CHAIN["force_band_hz"][0]) & (fk <= CHAIN["force_band_hz"][1] * (1 + 1e-12))
    F[~band] = 0.0
    force = np.fft.irfft(F, N)
    scale = CHAIN["force_rms_n"] / np.sqrt(np.mean(force ** 2))
    force *= scale
    F *= scale
    t0 = time.time()
    wk = 2 * np.pi * fk[band]
    H = rom.accelerance(wk, law(wk))  # 4 x n_band: the FRF at every FFT bin
    frf_s = time.time() - t0
    acc = np.empty((4, N))
    for i in range(4):
        A = np.zeros_like(F)
        A[band] = H[i] * F[band]
        acc[i] = np.fft.irfft(A, N)
    f_meas = force + CHAIN["force_noise_rms_n"] * rng.standard_normal(N)
    a_meas = acc + CHAIN["accel_noise_rms_ms2"] * rng.standard_normal((4, N))
    win = hann_periodic(nb)
    starts = np.arange(segments) * step
    lines = np.arange(CHAIN["lines_hz"][0], CHAIN["lines_hz"][1] + 1)
    bins = np.rint(lines * nb / fs).astype(int)
    Gff = np.zeros(len(lines))
    Gfa = np.zeros((4, len(lines)), dtype=complex)
    Gaa = np.zeros((4, len(lines)))
    for s in starts:
        Fs = np.fft.rfft(win * f_meas[s:s + nb])[bins]
        As = np.fft.rfft(win * a_meas[:, s:s + nb], axis=1)[:, bins]
        Gff += np.abs(Fs) ** 2
        Gfa += np.conj(Fs)[None, :] * As
        Gaa += np.abs(As) ** 2
    H1 = Gfa / Gff[None, :]
    coh = np.abs(Gfa) ** 2 / (Gff[None, :] * Gaa)
    stats = {
        "N": int(N),
        "record_s": N / fs,
        "segments": int(segments),
        "fine_df_hz": fs / N,
        "n_bins_in_band": int(band.sum()),
        "force_rms_n": float(np.sqrt(np.mean(force ** 2))),
        "accel_rms_ms2": [float(v) for v in np.sqrt(np.mean(acc ** 2, axis=1))],
        "coherence_min": float(coh.min()),
        "coherence_median": float(np.median(coh)),
        "frf_eval_s": frf_s,
    }
    return lines.astype(float), H1, coh, stats


# ----------------------------------------------------------------------------------- output

def write_uff(path, lines, H1, coh, segments):
    common = {
        "type": 58, "binary": 0, "func_id": 0, "ver_num": 0, "load_case_id": 0,
        "rsp_ent_name": "BEAM", "rsp_dir": 2, "ref_ent_name": "BEAM", "ref_node": DRIVE,
        "ref_dir": 2, "abscissa_spacing": 1, "abscissa_min": float(lines[0]),
        "abscissa_inc": float(lines[1] - lines[0]), "z_axis_value": 0.0,
        "abscissa_spec_data_type": 18, "abscissa_len_unit_exp": 0,
        "abscissa_force_unit_exp": 0, "abscissa_temp_unit_exp": 0,
        "abscissa_axis_lab": "Frequency", "abscissa_axis_units_lab": "Hz",
        "z_axis_spec_data_type": 0, "z_axis_len_unit_exp": 0, "z_axis_force_unit_exp": 0,
        "z_axis_temp_unit_exp": 0, "z_axis_axis_lab": "NONE", "z_axis_axis_units_lab": "NONE",
        "id2": f"Level 1: random excitation {CHAIN['force_rms_n']} N rms at point {DRIVE} +Y",
        "id3": f"H1 estimator, {segments} averages, Hann, 1 Hz lines",
        "id5": "NONE",
        "x": lines,
    }
    # (title, units line, function type, ordinate data type, ordinate, denominator, values)
    acc = ("accelerance H{i},{d}", "Units SI: (m/s^2)/N", 4, 6,
           (12, 1, 0, "Acceleration", "m/s^2"), (13, 0, 1, "Force", "N"), H1.astype(complex))
    cohs = ("coherence {i},{d}", "Ordinary coherence (-)", 6, 4,
            (1, 0, 0, "Coherence", "none"), (0, 0, 0, "NONE", "none"), coh.astype(float))
    sets = []
    for title, units, func, dtype, (o_spec, o_len, o_force, o_lab, o_unit), \
            (d_spec, d_len, d_force, d_lab, d_unit), values in (acc, cohs):
        for i in range(4):
            d = dict(common)
            d.update({
                "id1": "Independent bonded joint: " + title.format(i=i + 1, d=DRIVE),
                "id4": units, "func_type": func, "rsp_node": i + 1, "ord_data_type": dtype,
                "ordinate_spec_data_type": o_spec, "ordinate_len_unit_exp": o_len,
                "ordinate_force_unit_exp": o_force, "ordinate_temp_unit_exp": 0,
                "ordinate_axis_lab": o_lab, "ordinate_axis_units_lab": o_unit,
                "orddenom_spec_data_type": d_spec, "orddenom_len_unit_exp": d_len,
                "orddenom_force_unit_exp": d_force, "orddenom_temp_unit_exp": 0,
                "orddenom_axis_lab": d_lab, "orddenom_axis_units_lab": d_unit,
                "data": values[i],
            })
            sets.append(d)
    if os.path.exists(path):
        os.remove(path)
    pyuff.UFF(path).write_sets(sets, mode="add")


def check_mesh(spec, r0, refine):
    """The first six modes of the whole joint at E = 7 MPa real on the mesh and on the mesh
    with every size and growth rate divided by a further `refine`."""
    half = "uniform" not in spec
    res = {"modulus_pa": 7.0e6, "refine_factor": refine}
    for label, r in (("base", r0), ("refined", r0 * refine)):
        t0 = time.time()
        j = Joint(spec, refine=r, half=half)
        modes = whole_joint_modes(j, 7.0e6, 6)
        res[label] = {"free_dofs": int(len(j.free("sym" if half else "full"))), "elements": j.counts,
                      "f_hz": [m["f_hz"] for m in modes],
                      "symmetry": [m["symmetry"] for m in modes],
                      "max_residual": max(m["residual"] for m in modes),
                      "time_s": round(time.time() - t0, 1)}
        del j
        print(f"  {label}: elements {res[label]['elements']}, {res[label]['free_dofs']} "
              f"free DOFs, {res[label]['time_s']:.0f} s", flush=True)
    res["rel_diff"] = [(a - b) / b for a, b in zip(res["base"]["f_hz"], res["refined"]["f_hz"])]
    print("  mode  half   base (Hz)     refined (Hz)   (base - refined) / refined")
    for k, (a, b, s) in enumerate(zip(res["base"]["f_hz"], res["refined"]["f_hz"],
                                      res["base"]["symmetry"])):
        print(f"  {k + 1:4d}  {s:4s} {a:13.6f} {b:13.6f}   {res['rel_diff'][k]:.2e}")
    return res


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", help="output folder")
    ap.add_argument("--segments", type=int, default=200, help="Welch segments (50 %% overlap)")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--mesh", choices=("matched", "graded"), default="matched",
                    help="matched: rfmlab's default discretisation of this joint, built here "
                         "(20-node, uniform 5 mm); graded: 27-node, graded towards the bond "
                         "line's edges (the mesh-convergence reference)")
    ap.add_argument("--refine-mesh", type=float, default=1.0,
                    help="divide every element size and growth rate of MESH by this")
    ap.add_argument("--check-mesh", action="store_true",
                    help="also solve the mesh refined by --refine and print the convergence "
                         "(slow: minutes, ~13 GB)")
    ap.add_argument("--refine", type=float, default=2.0, help="refinement of --check-mesh")
    ap.add_argument("--verify", type=int, default=10,
                    help="frequencies of the reduced basis's check against direct solves")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                    help="processes for the direct solves of the check")
    args = ap.parse_args(argv[1:])
    t_start = time.time()
    os.makedirs(args.out, exist_ok=True)
    law = lambda w: model4(w, TRUTH)  # noqa: E731

    matched = args.mesh == "matched"
    spec = MESH_MATCHED if matched else MESH
    joint = Joint(spec, refine=args.refine_mesh, half=not matched)
    if matched:
        sym, anti = Half(joint, "full"), None
        mesh_info = {"elements_whole_width": joint.counts, "elements": joint.n_elements,
                     "free_dofs": int(len(sym.free))}
    else:
        sym, anti = Half(joint, "sym"), Half(joint, "anti")
        mesh_info = {"elements_half_width": joint.counts, "elements": joint.n_elements,
                     "free_dofs_sym_half": int(len(sym.free)),
                     "free_dofs_anti_half": int(len(anti.free))}
    print(f"{args.mesh} mesh (refinement {args.refine_mesh:g}): elements {joint.counts} "
          f"({joint.n_elements['beam']} beam, {joint.n_elements['bond']} bond line), "
          f"{len(sym.free)} free DOFs ({'whole joint' if matched else 'symmetric half'}); "
          f"assembled in {joint.assembly_s:.1f} s", flush=True)

    # the reduced basis of the measured (symmetric) half
    t0 = time.time()
    rom = Projected(sym, krylov(sym, REF_MODULI, [sym.f], KRYLOV_DEPTH, KRYLOV_S_DEPTH))
    print(f"reduced basis: {rom.V.shape[1]} vectors ({time.time() - t0:.1f} s)", flush=True)

    # modes: real modulus 7.2 MPa (whole joint), self-consistent (measured half), all modes
    # below 520 Hz at E*(first y mode) (both halves)
    t0 = time.time()
    msym = modal_basis(sym, REF_MODULI)
    manti = modal_basis(anti, REF_MODULI) if anti is not None else None

    def both(E, fmax):
        rows = mode_list(msym, E, fmax, sym.kind)
        if manti is not None:
            rows += mode_list(manti, E, fmax, "anti")
        return sorted(rows, key=lambda m: m["f_hz"])

    real72 = both(7.2e6, 1000.0)[:8]
    y_modes = self_consistent(msym, law, 560.0)
    first = min((m for m in y_modes if m["energy_xyz"][1] > 0.5), key=lambda m: m["f_hz"])
    E1st = complex(first["E_storage_pa"], first["E_loss_pa"])
    at_first = both(E1st, 520.0)
    print(f"modes ({time.time() - t0:.1f} s). Whole joint at E = 7.2 MPa real: "
          + ", ".join(f"{m['f_hz']:.4f} Hz ({m['symmetry']})" for m in real72)
          + f"; largest residual {max(m['residual'] for m in real72):.1e}", flush=True)
    print("self-consistent modes at the truth (measured half): "
          + ", ".join(f"{m['f_hz']:.3f} Hz eta {m['eta']:.4f}" for m in y_modes), flush=True)

    # the reduced basis against direct solves
    t0 = time.time()
    lines = np.arange(1.0, 501.0)
    w_lines = 2 * np.pi * lines
    H_lines = rom.accelerance(w_lines, law(w_lines))
    wd = 2 * np.pi * np.linspace(1.0, 500.0, 20001)
    peak = np.abs(rom.accelerance(wd, law(wd))).max(axis=1)
    f_peaks = [round(m["f_hz"], 3) for m in y_modes if m["f_hz"] <= 500.0]
    n_more = max(args.verify - 2 - len(f_peaks), 0)
    f_check = sorted(set([1.0, 500.0] + f_peaks
                         + [round(float(v), 3) for v in np.geomspace(4.0, 470.0, n_more)]))
    wE = [(2 * np.pi * fc, complex(law(2 * np.pi * fc))) for fc in f_check]
    errs, resids = [], []
    for (w, E), (xd, resid) in zip(wE, direct_receptances(sym, wE, args.jobs)):
        hr = rom.accelerance(np.array([w]), np.array([E]))[:, 0]
        errs.append(np.abs(hr - (-w ** 2 * xd)) / peak)
        resids.append(resid)
    errs = np.array(errs)
    romcheck = {
        "frequencies_hz": [float(f) for f in f_check],
        "max_rel_error_per_frf": [float(v) for v in errs.max(axis=0)],
        "max_rel_error": float(errs.max()),
        "rel_error_per_frequency": [float(v) for v in errs.max(axis=1)],
        "direct_relative_residual_max": float(max(resids)),
        "peak_accelerance": [float(v) for v in peak],
        "vectors": int(rom.V.shape[1]),
        "time_s": round(time.time() - t0, 1),
    }
    print(f"reduced basis vs direct sparse LU at {len(f_check)} frequencies "
          f"({', '.join(f'{f:g}' for f in f_check)} Hz): max |H_rom - H_direct| / peak = "
          f"{romcheck['max_rel_error']:.1e} (per FRF "
          + ", ".join(f"{v:.1e}" for v in romcheck["max_rel_error_per_frf"])
          + f"); direct residual <= {romcheck['direct_relative_residual_max']:.0e} "
          f"({romcheck['time_s']:.1f} s)", flush=True)
    if romcheck["max_rel_error"] > 1e-6:
        raise SystemExit("reduced basis check failed (> 1e-6 of a peak)")

    # the measurement
    freq, H1, coh, stats = measure(rom, law, args.segments, args.seed)
    print(f"record: {stats['N']} samples ({stats['record_s']} s), {stats['n_bins_in_band']} "
          f"FFT bins in (0, 500] Hz (FRF in {stats['frf_eval_s']:.1f} s); force "
          f"{stats['force_rms_n']:.4f} N RMS; coherence min {stats['coherence_min']:.4f}, "
          f"median {stats['coherence_median']:.6f}", flush=True)
    write_uff(os.path.join(args.out, "level1.uff"), freq, H1, coh, args.segments)
    np.savez(os.path.join(args.out, "exact.npz"), freq_hz=lines, H_exact=H_lines,
             E_star=law(w_lines), points=np.arange(1, 5))

    if args.check_mesh:
        del rom, msym, manti, sym, anti, joint
        print("mesh convergence (E = 7 MPa real, first six modes of the whole joint):", flush=True)
        conv = check_mesh(spec, args.refine_mesh, args.refine)
        conv["source"] = "computed by this run"
    else:
        conv = dict(CONVERGENCE_RECORDED if args.refine_mesh == 1.0 and not matched else {})
        conv["source"] = "recorded by --check-mesh" if conv else "not computed"

    truth = {
        "note": "Truth of an independent time-domain virtual experiment (scripts/"
                "independent_td_joint.py): not rfmlab's code, not the paper's joint.",
        "generator": {
            "script": "scripts/independent_td_joint.py", "version": VERSION,
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "skfem": skfem.__version__,
            "pyuff": pyuff.__version__,
            "command": " ".join(["independent_td_joint.py"] + argv[1:]),
        },
        "geometry": {
            "beam_length_m": BEAM_L, "beam_thickness_m": BEAM_T, "beam_width_m": BEAM_W,
            "adhesive_x_start_m": 0.0, "adhesive_length_m": BOND_L,
            "adhesive_thickness_m": BOND_T, "base": "adhesive lower face fixed",
            "points": [{"id": i + 1, "position_m": [x, BEAM_T, BEAM_W / 2], "direction": "+y"}
                       for i, x in enumerate(POINTS_X)],
            "excitation_point": DRIVE,
        },
        "materials": {"beam": STEEL, "adhesive": GLUE},
        "law": {
            "name": "model4",
            "formula": "E*(w) = E0 + j h + j w eta1 E1 / (E1 + j w eta1)",
            "params": TRUTH,
            "E_star_at_modes": {"f_hz": [m["f_hz"] for m in y_modes],
                                "storage_pa": [m["E_storage_pa"] for m in y_modes],
                                "loss_pa": [m["E_loss_pa"] for m in y_modes]},
        },
        "conventions": "exp(+j w t); E* = E' + j E'' (E'' > 0); accelerance (m/s^2)/N; modes: "
                       "lambda = w_r^2 (1 + j eta); energy_xyz: kinetic-energy shares; "
                       "symmetry about z = 0.0125 (sym modes are the measured ones); residual = "
                       "||(K - lambda M) phi|| / ||K phi|| on the full half model",
        "model": {
            "element": ("20-node serendipity hexahedron (scikit-fem ElementHexS2), 3x3x3 Gauss"
                        if matched else
                        "27-node triquadratic hexahedron (scikit-fem ElementHex2), 3x3x3 Gauss"),
            "mesh": args.mesh, "mesh_spec": spec, "mesh_refinement": args.refine_mesh,
            **mesh_info,
            "symmetry": ("none: the whole width" if matched else
                         "half width z in [0, 0.0125]; data from the symmetric half (u_z = 0 on "
                         "the plane, force halved)"),
            "reduced_basis": {"reference_moduli_pa": list(REF_MODULI),
                              "krylov_depth": KRYLOV_DEPTH, "modulus_moments": KRYLOV_S_DEPTH,
                              "vectors": romcheck["vectors"]},
            "rom_check": romcheck,
            "mesh_convergence": conv,
        },
        "modes": {
            "real_modulus_7.2MPa": real72,
            "self_consistent_measured_half": y_modes,
            "first_y_mode": first,
            "at_first_y_mode_modulus": {"E_star_pa": [E1st.real, E1st.imag],
                                        "below_520_hz": at_first},
        },
        "level": {"name": "L1", "force_rms_n": CHAIN["force_rms_n"], "law": "model4",
                  "params": TRUTH},
        "measurement": {**CHAIN, "seed": args.seed, **stats},
        "runtime_s": round(time.time() - t_start, 1),
    }
    with open(os.path.join(args.out, "truth.json"), "w") as fh:
        json.dump(truth, fh, indent=1)
    print(f"wrote {os.path.join(args.out, 'level1.uff')}, truth.json, exact.npz "
          f"({time.time() - t_start:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
