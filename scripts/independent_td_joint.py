#!/usr/bin/env python3
"""Independent time-domain virtual experiment of a bonded joint that is not the paper's.

Written for testing rfmlab's identification on data made by code that shares nothing with it:
numpy, scipy and scikit-fem only (no rfmlab import, no rfmlab formulas beyond the published
Model 4 law), 27-node triquadratic hexahedra instead of rfmlab's 20-node ones, a graded mesh,
its own reduced basis and its own Welch H1 measurement chain.

The default joint (SI; x along the beam, y through the thickness = the excitation direction, z
across):
  steel beam 0.400 x 0.008 x 0.025 m (E 205 GPa, nu 0.29, rho 7850), x in [0, 0.4],
  y in [0, 0.008], z in [0, 0.025];
  adhesive bond line under the beam's end: x in [0, 0.030], y in [-0.003, 0], full width,
  nu 0.45, rho 1250, its lower face y = -0.003 fixed (rigid base);
  points 1-4 at x = 0.120, 0.200, 0.280, 0.360 on the upper face centreline (y = 0.008,
  z = 0.0125), accelerations in +y; the force at point 2 in +y.
Adhesive law (rfmlab's Model 4, docs/method.md): E*(w) = E0 + j h + j w eta1 E1 / (E1 + j w eta1);
truth E0 = 7.2e6 Pa, h = 1.1e6 Pa, E1 = 2.8e6 Pa, eta1 = 5.0e3 Pa s. Conventions: exp(+j w t),
E* = E' + j E'' with E'' > 0, accelerance in (m/s^2)/N.

Other joints (--joint FILE.json, see load_joint): the beam's size and material, the adhesive's
length, thickness, start x_start (the bond line may lie anywhere along the beam, free beam on both
sides), Poisson's ratio and density, the four points' x on the upper face centreline, the drive
point, one or more levels (force RMS, Model 4 parameters, noise seed) and, optionally, graded mesh
sizes replacing MESH's. Level i is written to level<i>.uff; the file is copied as joint.json.

Effects (optional joint-file entries of a beam on a block or bond line; test data for a closed
loop that looks for what a model lacks):
  "base_springs": {"normal": k_n, "tangential": k_t} (N/m^3): the adhesive's lower face sits on
    distributed springs per unit area instead of the fixed base. The face's DOFs are free and
    the springs add the surface integral of k_n u_y v_y + k_t (u_x v_x + u_z v_z) over that
    face to the beam-side stiffness K_b (assembled with scikit-fem's facet basis on the face,
    consistent; independent of the adhesive's modulus; undamped).
  "masses": [{"point": id, "kg": m, "directions": "xyz"}]: a lumped mass at the point's node,
    added to M in each listed translation (any of "x", "y", "z"; default "y"): a sensor's
    inertia, no rotary inertia. The matched mesh is the whole joint and carries the whole
    mass; on the symmetric half (graded and converged meshes) the points lie on the mid-width
    plane, so the half carries half of it: in the symmetric half's x and y (u_z = 0 there) and
    in the antisymmetric half's z.
truth.json then holds "case" with "effects" in the form of studies/data/virtual's support_td and
mass3d_td ("support": k_normal_N_per_m3, k_tangential_N_per_m3, eta; "point_mass": point,
mass_kg, directions) and the model's details; without them every output is as before.

Single-lap joints (a joint file with "kind": "single_lap", see load_joint): two strips of one
material bonded over an overlap l_o by a bond line of thickness t_a (rfmlab's layout, width w
along z for all three parts):
  lower strip  x in [0, L],              y in [0, t1]
  adhesive     x in [L - l_o, L],        y in [t1, t1 + t_a]
  upper strip  x in [L - l_o, 2L - l_o], y in [t1 + t_a, t1 + t_a + t2]
perfectly bonded (shared nodes), the lower strip's end face x = 0 clamped (all three components
of every node on it fixed); the points [x, y] on the strips' upper faces (y = t1 or
t1 + t_a + t2) on the centreline z = w / 2, measured in +y. Only the graded and converged
meshes (MESH_LAP: a graded tensor grid over the bounding box with breaks at x = 0, L - l_o, L,
2L - l_o, the points' x, and y = 0, t1, t1 + t_a, top, keeping the cells inside the three
parts; graded towards both overlap ends in x, on both sides of each end, and towards the
clamped end x = 0, towards both faces of the bond line in y, inside it and in the strips, and
towards the free side z = 0; the symmetric half as for the beam-on-block joints). Their mode rows carry the adhesive's share of
the strain energy (adhesive_strain_energy_share = E' phi^H S phi / phi^H (K_b + E' S) phi).
The bond line holds little of the bending modes' energy, so they are very lightly damped (lap1:
loss factor 0.0035 at 78.5 Hz): the reduced basis needs --ref-moduli 5.6e6,7.2e6,10e6
--modulus-moments 8 and its check --direct-extended (the default direct solve's rounding is
1e-6 to 1e-5 of so sharp a peak); lap1 then passes --rom-tol 1e-6 (studies/data/virtual/
converged/README.md).

Single-lap points anywhere on the strips' outer surfaces (the joint file's points as
[x, y, z, "+x" | "+y" | "+z"], with "point_ids", "channels" and the drive among the points; see
load_joint): the drive's force acts along its point's direction. The mesh gets extra breaks at
the points' x, at their y inside a strip and at their (mirrored) z inside the half width, so
every point is a node and the response is read at that node (snapped; no shape-function
interpolation is needed, and a point more than 1e-9 m from a node is an error). Such a load and
such points are not symmetric about the mid-width plane: the data are then the sum of both
halves, the symmetric (u_z = 0 on the plane) and the antisymmetric (u_x = u_y = 0 on it), each
loaded with half the mirrored force, f_s = 1/2 s_d e_d and f_a = 1/2 a_d e_d at the drive's
node in the half z in [0, w / 2] (s = (1, 1, -1), a = (-1, -1, 1) for a point mirrored from
z > w / 2, else 1), and a point's response u_c = s_c u_s,c + a_c u_a,c at its (mirrored) node
(a component held on the plane contributes 0); each half has its own reduced basis (the same
moduli and moments) and the check against direct solves sums both halves' solves.

FE model. K(w) = K_b + E*(w) S - w^2 M, with K_b the beam's stiffness, S the adhesive's stiffness
assembled at unit Young's modulus and M the consistent mass; 3x3x3 Gauss points (exact for these
box elements). Three meshes (--mesh):

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
    from both ends of the bond line in x (here x = 0 and 0.030; on the free beam beside a bond
    line that starts away from the beam's end, from that end too), from both faces of the bond
    line and from the free side z = 0 (sizes in MESH). The joint and its load are symmetric about z = 0.0125 and the points lie on that
    plane, so the data come from the half z in [0, 0.0125] with u_z = 0 on the plane (the force
    halved); the antisymmetric modes (u_x = u_y = 0 on the plane) are computed for the mode
    lists. 31 388 free DOFs in the measured half, 80 s. The first y mode at 7.2 MPa (real)
    under --refine-mesh 0.7 / 1 / 1.41 / 2: 15.4540 / 15.4130 / 15.3936 / 15.3788 Hz (10 660 /
    31 388 / 72 900 / 199 784 DOFs): slow convergence (observed order 0.8 from the last three),
    an extrapolated 15.334 Hz (the three coarser meshes alone suggested second order and
    15.373 Hz). The matched (rfmlab default) mesh's 15.6438 Hz is 2.0 % above it: the measure
    of what a 5 mm mesh with two elements through a 3 mm bond line misses.
  converged: the graded mesh refined along --refine-seq (e.g. 1, 1.41, 2: every size and growth
    rate divided by the factor) until the lowest four modes of the measured half at 7.2 MPa
    (real) and its first y mode at the level-1 truth move less than --conv-tol (1e-4) between
    successive meshes. The corner singularities usually make that unreachable in memory; then
    the last three meshes give a Richardson extrapolation with the observed order (h = 1 /
    factor; with h = DOFs^(-1/3) too, as the element counts are rounded up) and the finest
    mesh's estimated remaining error per mode, or "irregular" where the changes alternate in
    sign or no order fits (with four meshes or more, the order and extrapolation of the three
    before are recorded too, a check of their steadiness). The data are made on the finest
    mesh, or on the mesh of --data-refine (one of the sequence) where the finest one's LUs for
    the data would not fit in memory and it serves the extrapolation only. truth.json
    (model.mesh_convergence) records every mesh's frequencies and DOFs, the orders, the
    extrapolated values and the remaining error of the finest and of the data's mesh. On the
    data's mesh the antisymmetric half's mode basis is built at one modulus only (memory).

Reduced basis (for the FRF at every FFT bin of the record): a block Krylov basis at the real
moduli E_r = 7.2 and 10 MPa (E'(w) runs from 7.2 to 9.9 MPa over 0-500 Hz; where another level's
E'(w) leaves that span, its ends, e.g. 5.6 and 10 MPa; --ref-moduli gives others): K_r^-1 f, then 14
frequency moments K_r^-1 M v and 4 modulus moments K_r^-1 S v each (K_r = K_b + E_r S),
M-orthonormalised; the projected pencil is solved per bin. It is checked against direct sparse
LU solves of the full model (scipy SuperLU) at --verify frequencies 1-500 Hz including the peaks
(per level);
the largest error relative to each FRF's peak is 6.6e-7 on the matched mesh and 5.4e-8 on the
graded one (the run stops above --rom-tol, 1e-6). On finer meshes the error has a floor that
more basis vectors did not lower (round-off, it seems): 1.3e-6 at level 2 of the 3 mm bond
line's 72 900-DOF mesh, unchanged by a third expansion modulus. That floor is the default
chains' ("shared", see krylov: a modulus's moments continue from vectors orthogonalised
against the other modulus's, so they do not span its Krylov space). On base springs it rises
to 3e-4 at the paper's joint's second y mode (390 Hz) whatever the depth or the number of
moduli; --krylov-chains own continues every chain from its own vectors and brings it to 1e-7
with as many vectors (krylov_own_chains). The check's frequencies are the self-consistent y
modes, which on the whole-width matched mesh can repeat one mode and miss another (the
iteration from a z mode's start lands on a neighbour): --verify-at adds frequencies.

Measurement chain (as the independent virtual experiments of docs/data.md): fs 2048 Hz; a
record of N = 1024 (segments + 1) samples; the force is white Gaussian noise with its FFT bins outside
(0, 500] Hz zeroed, scaled to 3.3 N RMS; the responses are the exact periodic steady state (the
record's FFT times the FRF at every bin up to 500 Hz, zero above, inverse FFT); white sensor
noise 0.002 N RMS on the force and 0.002 m/s^2 RMS on each acceleration; Welch with periodic
Hann 2048-sample (1 s) blocks at 50 % overlap: H1 = G_fa / G_ff, coherence
|G_fa|^2 / (G_ff G_aa), lines 1-500 Hz. Random numbers: numpy default_rng(seed): the force
record, then the force noise, then the noise of channels 1-4. Other levels: the force RMS of the
level, seed + i - 1 for level i unless the joint file states its seed.

Written into OUT_DIR:
  level1.uff   UFF58 ASCII: the 4 accelerances H1 (func type 4, response node i +Y, reference
               node 2 +Y, (m/s^2)/N) then the 4 coherences (func type 6); level2.uff ... for
               further levels of a joint file. Points given as [x, y, z, "+d"]: the channels'
               point ids and directions (UFF58 codes x 1, y 2, z 3, as rfmlab's reader maps
               them), reference node the drive's id and direction
  truth.json   geometry, materials, law and parameters, E*(f), the modes, the mesh, its
               convergence, the reduced basis check, the chain's settings and statistics,
               versions; "levels": per level id, name, force_rms_N, law, params (the form
               rfmlab's `[measurements] truth` reads), its modes, check and statistics
  exact.npz    freq_hz (1..500) and H_exact (4 x 500 complex): the noise-free accelerance at
               the lines (no leakage), E_star at the lines, H_exact_L2 ... of further levels;
               for checks only (not written with --no-exact)
  joint.json   the joint file, with --joint

Usage: independent_td_joint.py OUT_DIR [--joint FILE.json] [--mesh matched|graded|converged]
                               [--segments 200] [--seed 21] [--refine-mesh 1]
                               [--refine-seq 1,1.41,2] [--conv-tol 1e-4] [--check-mesh]
                               [--verify 10] [--verify-at F1,F2] [--direct-extended]
                               [--krylov-chains shared|own] [--no-exact] [--jobs 2]
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
from skfem import (Basis, BilinearForm, ElementHex2, ElementHexS2, ElementVector, FacetBasis,
                   MeshHex, asm)
from skfem.helpers import ddot, dot, sym_grad, trace

import pyuff

VERSION = "1.0"

# The joint (the default; --joint FILE.json replaces these, see load_joint)
JOINT_NAME = "bond3"
BEAM_L, BEAM_T, BEAM_W = 0.400, 0.008, 0.025
BOND_X0, BOND_L, BOND_T = 0.0, 0.030, 0.003  # the bond line spans x in [BOND_X0, BOND_X0 + BOND_L]
STEEL = {"E": 205e9, "nu": 0.29, "rho": 7850.0}
GLUE = {"nu": 0.45, "rho": 1250.0}
POINTS_X = (0.120, 0.200, 0.280, 0.360)  # ids 1..4, upper face centreline, +y
DRIVE = 2  # the force acts at point 2, +y
TRUTH = {"E0": 7.2e6, "h": 1.1e6, "E1": 2.8e6, "eta1": 5.0e3}
# Excitation levels: (name, force RMS in N, Model 4 parameters, noise seed or None for --seed);
# the default is level 1 alone.
LEVELS = [("L1", 3.3, TRUTH, None)]
REF_MODULI = (7.2e6, 10.0e6)  # real moduli of the reduced basis's expansions
KRYLOV_DEPTH = 14  # frequency moments per modulus
KRYLOV_S_DEPTH = 4  # modulus moments per modulus
# How each modulus's frequency moments continue (--krylov-chains, see krylov): "shared" (each
# next moment from the vector orthogonalised against the whole basis so far) or "own" (from the
# chain's own Arnoldi vectors: a true Krylov space of every modulus)
KRYLOV_CHAINS = "shared"
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

# The single-lap joint's graded tensor grid (a joint file with "kind": "single_lap"), the same
# (size at the graded end(s), growth per unit distance, cap) as MESH: x in the overlap graded
# towards both its ends; x on the strips beside it graded away from the nearest overlap end (on
# both sides of each end) and from the clamped end x = 0 (x_clamp: size there and growth, capped
# by x_strip's cap; the size is continuous across the breaks at the points); y in the bond line
# graded towards both its faces; y in each strip graded away from its bond face (an integer
# instead: that many equal elements, multiplied by --refine-mesh); z graded away from the free
# side z = 0. Chosen by trials on lap1 at refine 1: without the clamp's grading its first two
# modes (78 and 445 Hz) were 0.5 and 0.4 % high (the clamped edges are singular too); with it,
# the strips' x cap of 15 mm as in MESH put mode 2 0.4 % above a 5 mm cap, 7.5 mm 0.04 %, while
# 2.5 mm moved it by 1e-4 (the thin strips' 27-node elements stiffen at large aspect ratios);
# finer z or finer strips in y moved it by less than 3e-5.
MESH_LAP = {
    "element": "hex27",
    "x_overlap": (5e-4, 0.5, 3e-3),
    "x_strip": (1e-3, 0.8, 5e-3),
    "x_clamp": (1e-3, 0.8),
    "y_bond": (5e-4, 0.6),
    "y_strip": (5e-4, 1.0, 3e-3),
    "z": (1e-3, 0.8, 6e-3),
}

# The kind of joint: "beam_on_block" (the default and every joint file without "kind") or
# "single_lap" (LAP holds its geometry, POINTS_Y the points' y).
JOINT_KIND = "beam_on_block"
LAP = None
POINTS_Y = None
# Single-lap points given as [x, y, z, "+d"] (load_lap): a list of {"id", "pos", "comp", "dir"}
# and the measured point ids (channels); None for the classic [x, y] points.
POINTS_SPEC = None
CHANNELS = None

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

# Effects a joint file may add to a beam on a block or bond line (load_joint): distributed
# springs under the adhesive's lower face instead of the fixed base ({"normal": k_n,
# "tangential": k_t}, N/m^3, or None), and lumped masses at points' nodes (a list of
# {"point": id, "kg": m, "directions": "xyz"}).
BASE_SPRINGS = None
MASSES = []


def model4(w, p):
    """Model 4: a spring E0, a structural damper h and one Maxwell branch (E1, eta1)."""
    w = np.asarray(w, dtype=float)
    return p["E0"] + 1j * p["h"] + 1j * w * p["eta1"] * p["E1"] / (p["E1"] + 1j * w * p["eta1"])


def load_joint(path):
    """Replace the default joint by the one of a JSON file (SI). A beam on a block or bond
    line (no "kind", or "kind": "beam_on_block"):
      {"name": "...",
       "beam": {"length", "thickness", "width", "E", "nu", "rho"},
       "adhesive": {"length", "thickness", "x_start", "nu", "rho"},
       "points_x": [...],            # upper face centreline, +y, ids 1, 2, ...
       "drive": 2,                   # the point id of the force
       "levels": [{"name": "L1", "force_rms_n": 3.3,
                   "params": {"E0", "h", "E1", "eta1"}, "seed": 21 (optional)}, ...],
       "seed": 21,                   # optional: the noise seed of level 1 (else --seed);
                                     # level i's is seed + i - 1 unless it states its own
       "mesh": {...},                # optional: entries of MESH to replace (graded sizes)
       "base_springs": {"normal": 3.0e10, "tangential": 3.0e10},
                                     # optional (N/m^3): the adhesive's lower face on
                                     # distributed springs instead of the fixed base
       "masses": [{"point": 4, "kg": 0.012, "directions": "xyz"}]}
                                     # optional: lumped masses at points' nodes, acting in the
                                     # listed translations (see the module doc, "Effects")
    A single-lap joint (see the module doc for the layout):
      {"name": "...", "kind": "single_lap",
       "strips": {"length",          # L, each strip along x
                  "thickness_lower", "thickness_upper",   # t1 (the strip at x = 0), t2
                  "width", "E", "nu", "rho"},             # both strips' material
       "overlap": 0.025,             # l_o < L: the upper strip spans [L - l_o, 2L - l_o]
       "adhesive": {"thickness", "nu", "rho"},            # t_a; over the whole overlap and width
       "support": "clamped",         # the lower strip's end face x = 0 fixed (the only support)
       "points": [[x, y], ...],      # four points on the strips' upper faces (y = t1 or
                                     # t1 + t_a + t2), centreline z = w / 2, +y, ids 1, 2, ...
                 or [[x, y, z, "+z"], ...],   # or anywhere on a strip's outer surface,
                                     # measured in "+x", "+y" or "+z" (then all points so)
       "point_ids": [5, 31, ...],    # optional with the second form: the points' ids (else
                                     # 1, 2, ...)
       "channels": [31, 32, ...],    # optional with the second form: the measured points (the
                                     # UFF's channels, in this order; else every point)
       "drive", "seed", "levels",    # as above (the second form: the drive is one of the
                                     # points, the force along its direction)
       "response_noise_rms": 0.01,   # optional: the accelerometers' white noise RMS, m/s^2
                                     # (over the sampled span 0-1024 Hz; default CHAIN's 0.002)
       "force_noise_rel": 0.002,     # optional: the force sensor's noise RMS as a fraction of
                                     # the level's force RMS (default CHAIN's 0.002 N absolute)
       "mesh": {...}}                # optional: entries of MESH_LAP to replace
    Returns the parsed file."""
    global JOINT_NAME, BEAM_L, BEAM_T, BEAM_W, BOND_X0, BOND_L, BOND_T, STEEL, GLUE
    global POINTS_X, DRIVE, TRUTH, LEVELS, MESH, MESH_MATCHED, BASE_SPRINGS, MASSES
    with open(path) as fh:
        cfg = json.load(fh)
    kind = cfg.get("kind", "beam_on_block")
    if kind == "single_lap":
        for key in ("base_springs", "masses"):
            if key in cfg:
                raise SystemExit(f"{path}: {key!r} is for a beam on a block or bond line only")
        return load_lap(cfg, path)
    if kind != "beam_on_block":
        raise SystemExit(f"{path}: unknown kind {kind!r} (beam_on_block or single_lap)")
    b, a = cfg["beam"], cfg["adhesive"]
    JOINT_NAME = cfg.get("name", os.path.splitext(os.path.basename(path))[0])
    BEAM_L, BEAM_T, BEAM_W = float(b["length"]), float(b["thickness"]), float(b["width"])
    BOND_X0, BOND_L, BOND_T = float(a.get("x_start", 0.0)), float(a["length"]), float(a["thickness"])
    STEEL = {"E": float(b["E"]), "nu": float(b["nu"]), "rho": float(b["rho"])}
    GLUE = {"nu": float(a["nu"]), "rho": float(a["rho"])}
    POINTS_X = tuple(float(x) for x in cfg["points_x"])
    DRIVE = int(cfg["drive"])
    if len(POINTS_X) != 4:
        raise SystemExit(f"{path}: four points expected, got {len(POINTS_X)}")
    BASE_SPRINGS, MASSES = load_effects(cfg, path)
    if not (0.0 <= BOND_X0 and BOND_X0 + BOND_L <= BEAM_L + 1e-12):
        raise SystemExit(f"{path}: the bond line [{BOND_X0}, {BOND_X0 + BOND_L}] m leaves the beam")
    LEVELS = []
    for i, lv in enumerate(cfg["levels"]):
        seed = lv.get("seed")
        LEVELS.append((lv.get("name", f"L{i + 1}"), float(lv["force_rms_n"]),
                       {k: float(lv["params"][k]) for k in ("E0", "h", "E1", "eta1")}, seed))
    TRUTH = LEVELS[0][2]
    MESH = {**MESH, **{k: (tuple(v) if isinstance(v, list) else v)
                       for k, v in cfg.get("mesh", {}).items()}}
    # the matched mesh of another joint: a uniform grid of about 5 mm, two elements through the
    # bond line and two through the beam
    cells = lambda length: max(1, int(round(length / 0.005)))  # noqa: E731
    MESH_MATCHED = {"element": "hex20",
                    "uniform": {"x_before": cells(BOND_X0), "x_bond": cells(BOND_L),
                                "x_beam": cells(BEAM_L - BOND_X0 - BOND_L), "y_bond": 2,
                                "y_beam": 2, "z": cells(BEAM_W)}}
    return cfg


def load_effects(cfg, path):
    """The optional "base_springs" and "masses" of a beam-on-block joint file (see load_joint):
    the springs as {"normal": k_n, "tangential": k_t} (N/m^3) or None, the masses as a list of
    {"point": id, "kg": m, "directions": "xyz"}."""
    springs = None
    if "base_springs" in cfg:
        b = cfg["base_springs"]
        if not isinstance(b, dict) or set(b) != {"normal", "tangential"}:
            raise SystemExit(f"{path}: base_springs: {{\"normal\": k_n, \"tangential\": k_t}} "
                             f"(N/m^3) expected, got {b!r}")
        springs = {k: float(b[k]) for k in ("normal", "tangential")}
        if not all(np.isfinite(v) and v > 0.0 for v in springs.values()):
            raise SystemExit(f"{path}: base_springs: positive stiffnesses expected, got {b!r}")
    masses = []
    for i, m in enumerate(cfg.get("masses", [])):
        where = f"{path}: masses[{i}]"
        if not isinstance(m, dict) or not {"point", "kg"} <= set(m) \
                or not set(m) <= {"point", "kg", "directions"}:
            raise SystemExit(f"{where}: {{\"point\": id, \"kg\": m, \"directions\": "
                             f"\"xyz\"}} expected, got {m!r}")
        point, kg, dirs = int(m["point"]), float(m["kg"]), str(m.get("directions", "y"))
        if not 1 <= point <= len(POINTS_X):
            raise SystemExit(f"{where}: point {point} is not one of 1..{len(POINTS_X)}")
        if not (np.isfinite(kg) and kg > 0.0):
            raise SystemExit(f"{where}: a positive mass in kg expected, got {m['kg']!r}")
        if not dirs or set(dirs) - set("xyz") or len(set(dirs)) != len(dirs):
            raise SystemExit(f"{where}: directions: distinct letters of \"xyz\" expected, got "
                             f"{dirs!r}")
        masses.append({"point": point, "kg": kg, "directions": "".join(sorted(dirs))})
    return springs, masses


def load_levels(cfg):
    levels = []
    for i, lv in enumerate(cfg["levels"]):
        levels.append((lv.get("name", f"L{i + 1}"), float(lv["force_rms_n"]),
                       {k: float(lv["params"][k]) for k in ("E0", "h", "E1", "eta1")},
                       lv.get("seed")))
    return levels


def load_lap(cfg, path):
    """The single-lap joint of a parsed joint file (see load_joint)."""
    global JOINT_NAME, JOINT_KIND, LAP, BEAM_L, BEAM_T, BEAM_W, BOND_X0, BOND_L, BOND_T
    global STEEL, GLUE, POINTS_X, POINTS_Y, DRIVE, TRUTH, LEVELS, MESH, MESH_MATCHED
    st, a = cfg["strips"], cfg["adhesive"]
    JOINT_NAME = cfg.get("name", os.path.splitext(os.path.basename(path))[0])
    JOINT_KIND = "single_lap"
    L, lo = float(st["length"]), float(cfg["overlap"])
    t1, t2 = float(st["thickness_lower"]), float(st["thickness_upper"])
    ta, w = float(a["thickness"]), float(st["width"])
    support = cfg.get("support", "clamped")
    if support != "clamped":
        raise SystemExit(f"{path}: support {support!r}: only \"clamped\" (a free-free joint's "
                         "stiffness is singular at the reduced basis's expansion point w = 0)")
    if not 0.0 < lo < L:
        raise SystemExit(f"{path}: the overlap {lo} m must lie in (0, {L}) m")
    LAP = {"L": L, "t1": t1, "t2": t2, "ta": ta, "w": w, "overlap": lo, "support": support}
    # the bounding box and the bond line in the beam-on-block names some shared code reads
    BEAM_L, BEAM_T, BEAM_W = 2 * L - lo, t1 + ta + t2, w
    BOND_X0, BOND_L, BOND_T = L - lo, lo, ta
    STEEL = {"E": float(st["E"]), "nu": float(st["nu"]), "rho": float(st["rho"])}
    GLUE = {"nu": float(a["nu"]), "rho": float(a["rho"])}
    if any(len(p) == 4 for p in cfg["points"]):
        return load_lap_points(cfg, path)
    pts = [tuple(float(v) for v in p) for p in cfg["points"]]
    if len(pts) != 4:
        raise SystemExit(f"{path}: four points expected, got {len(pts)}")
    for x, y in pts:
        on_lower = np.isclose(y, t1) and 0.0 <= x <= L - lo + 1e-12
        on_upper = np.isclose(y, t1 + ta + t2) and L - lo - 1e-12 <= x <= 2 * L - lo + 1e-12
        if not (on_lower or on_upper):
            raise SystemExit(f"{path}: point [{x}, {y}] is not on a strip's upper face (the "
                             f"lower strip's y = {t1} for x in [0, {L - lo}], the upper "
                             f"strip's y = {t1 + ta + t2})")
    POINTS_X = tuple(p[0] for p in pts)
    POINTS_Y = tuple(p[1] for p in pts)
    DRIVE = int(cfg["drive"])
    LEVELS = load_levels(cfg)
    TRUTH = LEVELS[0][2]
    MESH = {**MESH_LAP, **{k: (tuple(v) if isinstance(v, list) else v)
                           for k, v in cfg.get("mesh", {}).items()}}
    MESH_MATCHED = None  # no matched (rfmlab default) mesh of a lap joint here
    return cfg


def load_lap_points(cfg, path):
    """The rest of load_lap for points given as [x, y, z, "+d"] (anywhere on a strip's outer
    surface, any axis direction), with optional "point_ids", "channels" and noise keys."""
    global POINTS_X, POINTS_Y, POINTS_SPEC, CHANNELS, DRIVE, TRUTH, LEVELS, MESH, MESH_MATCHED
    L, lo, t1, ta, t2, w = (LAP[k] for k in ("L", "overlap", "t1", "ta", "t2", "w"))
    ids = [int(v) for v in cfg.get("point_ids", range(1, len(cfg["points"]) + 1))]
    if len(ids) != len(cfg["points"]) or len(set(ids)) != len(ids):
        raise SystemExit(f"{path}: point_ids must give one distinct id per point")
    tol = 1e-12
    spec = []
    for pid, p in zip(ids, cfg["points"]):
        if len(p) != 4 or str(p[3]) not in ("+x", "+y", "+z"):
            raise SystemExit(f"{path}: point {pid}: [x, y, z, \"+x\" | \"+y\" | \"+z\"] expected "
                             f"(all points in that form), got {p}")
        x, y, z = (float(v) for v in p[:3])
        # the strips' boxes (x0, x1, y0, y1) and the bonded face each has (y, x range)
        boxes = [((0.0, L, 0.0, t1), t1), ((L - lo, 2 * L - lo, t1 + ta, t1 + ta + t2), t1 + ta)]
        ok = False
        for (x0, x1, y0, y1), y_bond in boxes:
            inside = (x0 - tol <= x <= x1 + tol and y0 - tol <= y <= y1 + tol
                      and -tol <= z <= w + tol)
            on_face = (min(abs(x - x0), abs(x - x1), abs(y - y0), abs(y - y1), abs(z),
                           abs(z - w)) <= tol)
            bonded = abs(y - y_bond) <= tol and L - lo + tol < x < L - tol
            if inside and on_face and not bonded:
                ok = True
        if not ok:
            raise SystemExit(f"{path}: point {pid} [{x}, {y}, {z}] is not on a strip's outer "
                             "surface")
        spec.append({"id": pid, "pos": np.array([x, y, z]), "comp": "xyz".index(p[3][1]),
                     "dir": str(p[3])})
    POINTS_SPEC = spec
    CHANNELS = [int(v) for v in cfg.get("channels", ids)]
    DRIVE = int(cfg["drive"])
    for c in CHANNELS + [DRIVE]:
        if c not in ids:
            raise SystemExit(f"{path}: point {c} (channel or drive) is not one of {ids}")
    POINTS_X = tuple(float(sp_["pos"][0]) for sp_ in spec)
    POINTS_Y = tuple(float(sp_["pos"][1]) for sp_ in spec)
    if "response_noise_rms" in cfg:
        CHAIN["accel_noise_rms_ms2"] = float(cfg["response_noise_rms"])
    if "force_noise_rel" in cfg:
        CHAIN["force_noise_rel"] = float(cfg["force_noise_rel"])
        CHAIN["force_noise_rms_n"] = None
    LEVELS = load_levels(cfg)
    TRUTH = LEVELS[0][2]
    MESH = {**MESH_LAP, **{k: (tuple(v) if isinstance(v, list) else v)
                           for k, v in cfg.get("mesh", {}).items()}}
    MESH_MATCHED = None
    return cfg


def mirrored(pos):
    """A position mapped into the half z in [0, w / 2] and whether it was mirrored."""
    if pos[2] > BEAM_W / 2 + 1e-12:
        return np.array([pos[0], pos[1], BEAM_W - pos[2]]), True
    return np.array(pos, dtype=float), False


def point_targets():
    """The points' coordinates (x, y, z), ids 1, 2, ..."""
    if POINTS_SPEC is not None:
        return [sp_["pos"] for sp_ in POINTS_SPEC]
    if JOINT_KIND == "single_lap":
        return [np.array([x, y, BEAM_W / 2]) for x, y in zip(POINTS_X, POINTS_Y)]
    return [np.array([x, BEAM_T, BEAM_W / 2]) for x in POINTS_X]


def ref_moduli():
    """Real moduli of the reduced basis's expansions: the default (7.2, 10) MPa when they span
    E'(w) of every level over 0-500 Hz, else that span's ends."""
    w = 2 * np.pi * np.linspace(0.0, CHAIN["lines_hz"][1], 501)
    lo = min(float(model4(w, p).real.min()) for _, _, p, _ in LEVELS)
    hi = max(float(model4(w, p).real.max()) for _, _, p, _ in LEVELS)
    if lo >= REF_MODULI[0] * (1 - 1e-9) and hi <= REF_MODULI[1]:
        return REF_MODULI
    return (min(lo, REF_MODULI[0]), max(hi, REF_MODULI[1]))


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


def nodes_graded_to(a, b, ends, h_max):
    """Nodes on [a, b] with element size min(h_max, min over `ends` (e, h_e, grow) of
    h_e + grow * |x - e|) (the ends may lie outside [a, b]): as many elements as the integral of
    1/size."""
    span = b - a
    d = [np.linspace(a, b, 4001)]
    for e, h, _ in ends:
        if a - 1e-12 <= e <= b + 1e-12:
            g = np.geomspace(1e-4 * h, span, 600)
            d += [e + g, e - g]
    d = np.unique(np.clip(np.concatenate(d), a, b))
    size = np.full_like(d, h_max)
    for e, h, g in ends:
        size = np.minimum(size, h + g * np.abs(d - e))
    dens = 1.0 / size
    s = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(d))])
    n = max(1, int(np.ceil(s[-1] - 1e-6)))
    return np.interp(np.linspace(0.0, s[-1], n + 1), s, d)


def lap_axes(spec, refine=1.0, half=True):
    """Node coordinates along x, y and z of the single-lap joint's bounding box, and the
    element counts through the lower strip, the bond line and the upper strip."""
    r = float(refine)
    L, lo, t1, ta, t2 = LAP["L"], LAP["overlap"], LAP["t1"], LAP["ta"], LAP["t2"]
    x0, x1 = L - lo, L  # the overlap's ends
    cuts = sorted(set([0.0, x0, x1, 2 * L - lo] + list(POINTS_X)))
    hc, gc = spec["x_clamp"][:2]
    parts = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        in_overlap = a >= x0 - 1e-12 and b <= x1 + 1e-12
        he, g, hm = spec["x_overlap"] if in_overlap else spec["x_strip"]
        ends = [(x0, he / r, g / r), (x1, he / r, g / r)] + [(0.0, hc / r, gc / r)]
        parts.append(nodes_graded_to(a, b, ends, hm / r))
    x = join(*parts)

    def strip(a, b, face):
        if isinstance(spec["y_strip"], (int, np.integer)):
            return np.linspace(a, b, int(round(spec["y_strip"] * r)) + 1)
        he, g, hm = spec["y_strip"]
        if POINTS_SPEC is not None:  # breaks at the points' y inside the strip
            cy = sorted(set([a, b] + [float(sp_["pos"][1]) for sp_ in POINTS_SPEC
                                      if a + 1e-12 < sp_["pos"][1] < b - 1e-12]))
            if len(cy) > 2:
                return join(*[nodes_graded_to(c0, c1, [(face, he / r, g / r)], hm / r)
                              for c0, c1 in zip(cy[:-1], cy[1:])])
        return nodes_graded_to(a, b, [(face, he / r, g / r)], hm / r)

    he, g = spec["y_bond"]
    y_lower = strip(0.0, t1, t1)
    y_bond = graded_nodes(t1, t1 + ta, he / r, he / r, g / r, ta)
    y_upper = strip(t1 + ta, t1 + ta + t2, t1 + ta)
    y = join(y_lower, y_bond, y_upper)
    he, g, hm = spec["z"]
    cz = []
    if POINTS_SPEC is not None:  # breaks at the points' (mirrored) z inside the half width
        cz = sorted(set(float(mirrored(sp_["pos"])[0][2]) for sp_ in POINTS_SPEC
                        if 1e-12 < mirrored(sp_["pos"])[0][2] < BEAM_W / 2 - 1e-12))
    if cz:
        cz = [0.0] + cz + [BEAM_W / 2]
        z = join(*[nodes_graded_to(c0, c1, [(0.0, he / r, g / r)], hm / r)
                   for c0, c1 in zip(cz[:-1], cz[1:])])
    else:
        z = graded_nodes(0.0, BEAM_W / 2, he / r, None, g / r, hm / r)
    if not half:
        z = join(z, (BEAM_W - z[::-1]))
    return x, y, z, (len(y_lower) - 1, len(y_bond) - 1, len(y_upper) - 1)


def lap_mesh(spec, refine=1.0, half=True):
    """The single-lap joint's graded tensor grid: the cells of the bounding box inside the
    lower strip, the bond line or the upper strip (shared nodes: perfect bond)."""
    x, y, z, (ny_lower, ny_bond, ny_upper) = lap_axes(spec, refine, half)
    m = MeshHex.init_tensor(x, y, z)
    L, lo, t1, ta = LAP["L"], LAP["overlap"], LAP["t1"], LAP["ta"]
    c = m.p[:, m.t].mean(axis=1)
    lower = (c[0] < L) & (c[1] < t1)
    bond = (c[0] > L - lo) & (c[0] < L) & (c[1] > t1) & (c[1] < t1 + ta)
    upper = (c[0] > L - lo) & (c[1] > t1 + ta)
    m = m.remove_elements(np.nonzero(~(lower | bond | upper))[0])
    c = m.p[:, m.t].mean(axis=1)
    in_bond = (c[1] > t1) & (c[1] < t1 + ta)
    counts = {"x": len(x) - 1, "y_lower": ny_lower, "y_bond": ny_bond, "y_upper": ny_upper,
              "z": len(z) - 1}
    return m, np.nonzero(~in_bond)[0], np.nonzero(in_bond)[0], counts


def join(*parts):
    out = [parts[0][:1]]
    for p in parts:
        out.append(p[1:])
    return np.concatenate(out)


def grid_axes(spec, refine=1.0, half=True):
    """Node coordinates along x, y and z; `refine` divides every size and growth rate (or
    multiplies the counts of a uniform spec)."""
    r = float(refine)
    x0, x1 = BOND_X0, BOND_X0 + BOND_L
    if "uniform" in spec:
        n = {k: int(round(v * r)) for k, v in spec["uniform"].items()}
        parts = [np.linspace(x0, x1, n["x_bond"] + 1), np.linspace(x1, BEAM_L, n["x_beam"] + 1)]
        if x0 > 0.0:
            parts.insert(0, np.linspace(0.0, x0, n["x_before"] + 1))
        x = join(*parts)
        y = join(np.linspace(-BOND_T, 0.0, n["y_bond"] + 1), np.linspace(0.0, BEAM_T, n["y_beam"] + 1))
        z = np.linspace(0.0, BEAM_W, n["z"] + 1)
        return x, y, z, n["y_bond"]
    # x: the bond line graded towards both its ends; the free beam on either side broken at
    # the points and graded towards the bond line's end it touches
    he, g, hm = spec["x_bond"]
    x = [(x0, graded_nodes(x0, x1, he / r, he / r, g / r, hm / r))]
    he, g, hm = spec["x_beam"]
    ends = [e for e in (x0, x1) if 0.0 < e < BEAM_L]
    cuts = sorted(set([0.0, BEAM_L, x0, x1] + [p for p in POINTS_X if not x0 < p < x1]))
    for a, b in zip(cuts[:-1], cuts[1:]):
        if a >= x0 and b <= x1:
            continue
        ha = he / r if any(np.isclose(a, e) for e in ends) else None
        hb = he / r if any(np.isclose(b, e) for e in ends) else None
        x.append((a, graded_nodes(a, b, ha, hb, g / r, hm / r)))
    x = join(*[nodes for _, nodes in sorted(x, key=lambda t: t[0])])
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
    if JOINT_KIND == "single_lap":
        return lap_mesh(spec, refine, half)
    x, y, z, ny_bond = grid_axes(spec, refine, half)
    m = MeshHex.init_tensor(x, y, z)
    c = m.p[:, m.t].mean(axis=1)
    outside = (c[0] < BOND_X0) | (c[0] > BOND_X0 + BOND_L)
    m = m.remove_elements(np.nonzero((c[1] < 0.0) & outside)[0])
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
        self.base_area = None
        if BASE_SPRINGS is not None:
            self.K_b, self.base_area = base_springs(self.mesh, e, self.K_b)
        self.n = self.K_b.shape[0]
        self.loc = b_beam.doflocs
        self.comp = np.empty(self.n, dtype=np.int64)
        for c, idx in enumerate(b_beam.split_indices()):
            self.comp[idx] = c
        self.n_elements = ({"strips": int(len(beam)), "bond": int(len(bond))}
                           if JOINT_KIND == "single_lap" else
                           {"beam": int(len(beam)), "bond": int(len(bond))})
        self.assembly_s = time.time() - t0
        self.point_dofs = []
        if POINTS_SPEC is not None:
            # per point: its node's DOF of its direction in the half, and whether mirrored
            self.point_nodes = {}
            for sp_ in POINTS_SPEC:
                target, mir = mirrored(sp_["pos"]) if half else (sp_["pos"], False)
                cand = np.nonzero(self.comp == sp_["comp"])[0]
                d = np.linalg.norm(self.loc[:, cand].T - target, axis=1)
                k = int(np.argmin(d))
                if d[k] > 1e-9:
                    raise SystemExit(f"no node at point {sp_['id']} {target} (nearest "
                                     f"{d[k]:.2e} m away)")
                self.point_nodes[sp_["id"]] = (int(cand[k]), sp_["comp"], mir)
            return
        for target in point_targets():
            cand = np.nonzero(self.comp == 1)[0]
            d = np.linalg.norm(self.loc[:, cand].T - target, axis=1)
            k = int(np.argmin(d))
            if d[k] > 1e-12:
                raise SystemExit(f"no node at point {target}")
            self.point_dofs.append(int(cand[k]))
        self.mass_dofs = []
        if MASSES:
            self.M, self.mass_dofs = lumped_masses(self.M, self.loc, self.comp, self.point_dofs,
                                                   half)

    def free(self, kind):
        """Free DOFs: the base (a lap joint: its clamped end) fixed; on the mid-width plane
        u_z = 0 ('sym') or u_x = u_y = 0 ('anti'); 'full' for a whole-width mesh."""
        if JOINT_KIND == "single_lap":  # clamped: the lower strip's end face x = 0
            held = np.isclose(self.loc[0], 0.0)
        elif BASE_SPRINGS is not None:  # the base face free on its springs
            held = np.zeros(self.n, dtype=bool)
        else:
            held = np.isclose(self.loc[1], -BOND_T)
        if kind != "full":
            plane = np.isclose(self.loc[2], BEAM_W / 2)
            held |= plane & ((self.comp == 2) if kind == "sym" else (self.comp != 2))
        return np.nonzero(~held)[0]

    def restrict(self, kind):
        f = self.free(kind)
        return f, self.K_b[f][:, f].tocsc(), self.S[f][:, f].tocsc(), self.M[f][:, f].tocsc()


def base_springs(mesh, element, K_b):
    """K_b plus the distributed springs under the adhesive's lower face y = -BOND_T: the surface
    integral of k_n u_y v_y + k_t (u_x v_x + u_z v_z) over that face (scikit-fem facet basis,
    Gauss rule exact for the products of the face's shape functions); and the face's area."""
    facets = mesh.facets_satisfying(lambda x: np.isclose(x[1], -BOND_T))
    if len(facets) == 0:
        raise SystemExit("base_springs: no element face lies on the adhesive's lower face")
    fb = FacetBasis(mesh, element, facets=facets, intorder=4)
    kn, kt = BASE_SPRINGS["normal"], BASE_SPRINGS["tangential"]
    springs = BilinearForm(lambda u, v, w: kn * u[1] * v[1] + kt * (u[0] * v[0] + u[2] * v[2]))
    area = float(asm(BilinearForm(lambda u, v, w: u[1] * v[1]), fb).sum())
    return (K_b + asm(springs, fb)).tocsr(), area


def lumped_masses(M, loc, comp, point_dofs, half):
    """M plus MASSES: each mass at its point's node in its directions' DOFs (no rotary inertia).
    On the half width the points lie on the mid-width plane, so the half carries half of each
    mass (the symmetric half's x and y, the antisymmetric half's z); the whole width carries it
    whole. Returns the matrix and (point, direction, DOF, mass added) rows."""
    rows, added = [], []
    for m in MASSES:
        node = loc[:, point_dofs[m["point"] - 1]]
        if half and not np.isclose(node[2], BEAM_W / 2):
            raise SystemExit(f"mass at point {m['point']}: off the mid-width plane, the half "
                             "model cannot carry it")
        share = 0.5 * m["kg"] if half else m["kg"]
        for d in m["directions"]:
            cand = np.nonzero(comp == "xyz".index(d))[0]
            k = cand[int(np.argmin(np.linalg.norm(loc[:, cand].T - node, axis=1)))]
            rows.append(int(k))
            added.append({"point": m["point"], "direction": d, "dof": int(k), "kg": share})
    extra = sp.csr_matrix((np.array([a["kg"] for a in added]), (rows, rows)), shape=M.shape)
    return (M + extra).tocsr(), added


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
        self.C = None
        if POINTS_SPEC is not None:  # general points: weighted outputs, mirrored force
            pos = {g: i for i, g in enumerate(self.free)}
            sign = lambda c, mir: (1.0 if not mir else  # noqa: E731
                                   ((1.0, 1.0, -1.0) if kind == "sym" else (-1.0, -1.0, 1.0))[c])
            self.C = np.zeros((len(CHANNELS), n))
            for i, pid in enumerate(CHANNELS):
                g, c, mir = joint.point_nodes[pid]
                if g in pos:
                    self.C[i, pos[g]] = sign(c, mir) if kind != "full" else 1.0
            g, c, mir = joint.point_nodes[DRIVE]
            if g in pos:
                self.f[pos[g]] = 0.5 * sign(c, mir) if kind != "full" else 1.0
            self.out = np.arange(len(CHANNELS))
        elif kind == "anti":  # the points lie on the plane, held in y: no force, no outputs
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
    moments in the modulus). KRYLOV_CHAINS "shared": v_k is the vector as orthogonalised against
    the whole basis, so the second modulus's chain starts from what the first one's lacks and is
    not that modulus's Krylov space (enough without base springs: 1e-6 of a peak); "own": see
    krylov_own_chains."""
    if KRYLOV_CHAINS == "own":
        return krylov_own_chains(half, moduli, starts, depth, s_depth)
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


def krylov_own_chains(half, moduli, starts, depth, s_depth=0):
    """krylov with every chain continued from its own vectors: per modulus E_r and start load b,
    the Arnoldi vectors u_0 ~ K_r^-1 b, u_k+1 ~ K_r^-1 M u_k (M-orthonormalised within the chain
    only) span that modulus's Krylov space; each u_k and, for k < s_depth, K_r^-1 S u_k join
    the basis. On the paper's joint on base springs the shared chains stall at 4e-5 of the
    response (M-norm) at 390 Hz and 10 MPa, the expansion modulus itself, these reach 1e-13
    there with as many vectors."""
    basis = MBasis(half.M)
    for E in moduli:
        lu = half.lu(E)
        for b in starts:
            chain = MBasis(half.M)
            u = chain.add(lu.solve(b))
            for k in range(depth + 1):
                if u is None:
                    break
                basis.add(u)
                if k < s_depth:
                    basis.add(lu.solve(half.S @ u))
                if k < depth:
                    u = chain.add(lu.solve(half.M @ u))
    return basis.matrix()


class Projected:
    """A half projected on an M-orthonormal basis V."""

    def __init__(self, half, V):
        self.half, self.V = half, V
        self.Kr = V.T @ (half.Kb @ V)
        self.Sr = V.T @ (half.S @ V)
        self.Mr = V.T @ (half.M @ V)
        self.fr = V.T @ half.f
        self.Cr = V[half.out, :] if half.C is None else half.C @ V

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


class PairROM:
    """The sum of the symmetric and antisymmetric halves' reduced models (general single-lap
    points: each half's outputs already carry the mirror signs)."""

    def __init__(self, roms):
        self.roms = roms
        self.V = np.zeros((0, sum(r.V.shape[1] for r in roms)))  # V.shape[1]: vectors in all
        self.vectors = [int(r.V.shape[1]) for r in roms]

    def receptance(self, w, E):
        return sum(r.receptance(w, E) for r in self.roms)

    def accelerance(self, w, E):
        return -(np.asarray(w, dtype=float) ** 2) * self.receptance(w, E)


def direct_receptance(half, w, E, extended=False):
    """Full-order solve of (K_b + E S - w^2 M) x = f by complex sparse LU with one step of
    iterative refinement; x at the points and the relative residual. extended: the refinement's
    residuals in extended precision (numpy longdouble) with the matrix summed from K_b, S and M
    in extended precision too, repeated until the correction stalls (at most 6 steps): at a
    sharp resonance (loss factor ~0.003) the rounding of the summed matrix and of the residual
    alone moves the solution by 1e-6 to 1e-5 of the peak."""
    A = (half.Kb + E * half.S - w ** 2 * half.M).tocsc()
    lu = factor(A)
    b = half.f.astype(complex)
    x = lu.solve(b)
    if extended:
        xl = x.astype(np.clongdouble)
        Al = (half.Kb.astype(np.clongdouble) + np.clongdouble(E) * half.S.astype(np.clongdouble)
              - np.longdouble(w) ** 2 * half.M.astype(np.clongdouble)).tocsr()
        bl = b.astype(np.clongdouble)
        for _ in range(6):
            dx = lu.solve(np.asarray(bl - Al @ xl).astype(complex))
            xl += dx.astype(np.clongdouble)
            if np.linalg.norm(dx) <= 1e-16 * np.linalg.norm(x):
                break
        x = xl.astype(complex)
        resid = float(np.linalg.norm((Al @ xl - bl).astype(complex))
                      / (abs(A).sum(axis=1).max() * np.linalg.norm(x) + np.linalg.norm(b)))
        return (x[half.out] if half.C is None else half.C @ x), resid
    x += lu.solve(b - A @ x)
    # normwise backward error ||A x - b|| / (||A||_inf ||x|| + ||b||)
    resid = np.linalg.norm(A @ x - b) / (abs(A).sum(axis=1).max() * np.linalg.norm(x)
                                          + np.linalg.norm(b))
    return (x[half.out] if half.C is None else half.C @ x), float(resid)


_JOB = {}


def _direct_job(wE):
    """A direct solve in a worker process (the half is inherited through fork)."""
    return direct_receptance(_JOB["half"], *wE, extended=_JOB["extended"])


def direct_receptances(half, wE, jobs, extended=False):
    if jobs <= 1 or len(wE) == 1 or "fork" not in multiprocessing.get_all_start_methods():
        return [direct_receptance(half, w, E, extended) for w, E in wE]
    _JOB["half"], _JOB["extended"] = half, extended
    with multiprocessing.get_context("fork").Pool(min(jobs, len(wE))) as pool:
        return pool.map(_direct_job, wE, chunksize=1)


def adhesive_share(half, E, phi):
    """The adhesive's share of the strain energy of a mode at the modulus E:
    E' phi^H S phi / phi^H (K_b + E' S) phi."""
    a = complex(E).real * float(np.real(np.vdot(phi, half.S @ phi)))
    return a / (float(np.real(np.vdot(phi, half.Kb @ phi))) + a)


def mode_row(proj, E, lam, q, kind):
    res, phi = proj.residual(E, lam, q)
    row = {"f_hz": float(np.sqrt(lam.real) / (2 * np.pi)), "eta": float(lam.imag / lam.real),
           "symmetry": kind,
           "energy_xyz": [round(s, 6) for s in energy_shares(phi, proj.half.M, proj.half.comp)],
           "residual": res}
    if JOINT_KIND == "single_lap":
        row["adhesive_strain_energy_share"] = round(adhesive_share(proj.half, E, phi), 6)
    return row


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


def measure(rom, law, segments, seed, force_rms_n=None):
    """Simulate the record (force RMS force_rms_n, CHAIN's by default) and return lines, H1
    (4 x L), coherence (4 x L) and statistics."""
    force_rms_n = CHAIN["force_rms_n"] if force_rms_n is None else force_rms_n
    fs, nb = CHAIN["fs_hz"], CHAIN["block"]
    step = int(nb * (1.0 - CHAIN["overlap"]))
    N = nb + step * (segments - 1)
    rng = np.random.default_rng(seed)
    F = np.fft.rfft(rng.standard_normal(N))
    fk = np.arange(len(F)) * fs / N
    band = (fk > CHAIN["force_band_hz"][0]) & (fk <= CHAIN["force_band_hz"][1] * (1 + 1e-12))
    F[~band] = 0.0
    force = np.fft.irfft(F, N)
    scale = force_rms_n / np.sqrt(np.mean(force ** 2))
    force *= scale
    F *= scale
    t0 = time.time()
    wk = 2 * np.pi * fk[band]
    H = rom.accelerance(wk, law(wk))  # 4 x n_band: the FRF at every FFT bin
    frf_s = time.time() - t0
    nch = H.shape[0]
    acc = np.empty((nch, N))
    for i in range(nch):
        A = np.zeros_like(F)
        A[band] = H[i] * F[band]
        acc[i] = np.fft.irfft(A, N)
    f_noise = (CHAIN["force_noise_rms_n"] if CHAIN.get("force_noise_rel") is None
               else CHAIN["force_noise_rel"] * force_rms_n)
    f_meas = force + f_noise * rng.standard_normal(N)
    a_meas = acc + CHAIN["accel_noise_rms_ms2"] * rng.standard_normal((nch, N))
    win = hann_periodic(nb)
    starts = np.arange(segments) * step
    lines = np.arange(CHAIN["lines_hz"][0], CHAIN["lines_hz"][1] + 1)
    bins = np.rint(lines * nb / fs).astype(int)
    Gff = np.zeros(len(lines))
    Gfa = np.zeros((nch, len(lines)), dtype=complex)
    Gaa = np.zeros((nch, len(lines)))
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
        **({} if CHAIN.get("force_noise_rel") is None else {"force_noise_rms_n": f_noise}),
        "accel_rms_ms2": [float(v) for v in np.sqrt(np.mean(acc ** 2, axis=1))],
        "coherence_min": float(coh.min()),
        "coherence_median": float(np.median(coh)),
        "frf_eval_s": frf_s,
    }
    return lines.astype(float), H1, coh, stats


# ----------------------------------------------------------------------------------- output

def write_uff(path, lines, H1, coh, segments, level=1, force_rms_n=None):
    force_rms_n = CHAIN["force_rms_n"] if force_rms_n is None else force_rms_n
    if POINTS_SPEC is not None:  # general points: ids and UFF direction codes x 1, y 2, z 3
        by_id = {sp_["id"]: sp_ for sp_ in POINTS_SPEC}
        rsp = [(pid, by_id[pid]["comp"] + 1, by_id[pid]["dir"].upper()) for pid in CHANNELS]
        ref = (DRIVE, by_id[DRIVE]["comp"] + 1, by_id[DRIVE]["dir"].upper())
    else:
        rsp = [(i + 1, 2, "+Y") for i in range(4)]
        ref = (DRIVE, 2, "+Y")
    common = {
        "type": 58, "binary": 0, "func_id": 0, "ver_num": 0, "load_case_id": 0,
        "rsp_ent_name": "BEAM", "rsp_dir": 2, "ref_ent_name": "BEAM", "ref_node": ref[0],
        "ref_dir": ref[1], "abscissa_spacing": 1, "abscissa_min": float(lines[0]),
        "abscissa_inc": float(lines[1] - lines[0]), "z_axis_value": 0.0,
        "abscissa_spec_data_type": 18, "abscissa_len_unit_exp": 0,
        "abscissa_force_unit_exp": 0, "abscissa_temp_unit_exp": 0,
        "abscissa_axis_lab": "Frequency", "abscissa_axis_units_lab": "Hz",
        "z_axis_spec_data_type": 0, "z_axis_len_unit_exp": 0, "z_axis_force_unit_exp": 0,
        "z_axis_temp_unit_exp": 0, "z_axis_axis_lab": "NONE", "z_axis_axis_units_lab": "NONE",
        "id2": f"Level {level}: random excitation {force_rms_n} N rms at point {DRIVE} {ref[2]}",
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
        for i, (node, code, _) in enumerate(rsp):
            d = dict(common)
            d.update({
                "id1": "Independent bonded joint: " + title.format(i=node, d=DRIVE),
                "id4": units, "func_type": func, "rsp_node": node, "rsp_dir": code,
                "ord_data_type": dtype,
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


def observed_order(h, f):
    """Richardson extrapolation from the last three meshes (sizes h, values f): the observed
    order p from (f1 - f2) / (f2 - f3) = (h1^p - h2^p) / (h2^p - h3^p), then
    f_inf = f3 - (f2 - f3) h3^p / (h2^p - h3^p). None where the differences change sign or no
    order in [0.2, 12] fits (irregular convergence)."""
    (h1, h2, h3), (f1, f2, f3) = h[-3:], f[-3:]
    d1, d2 = f1 - f2, f2 - f3
    if d2 == 0.0:
        return {"order": None, "extrapolated": f3, "regular": True}
    if d1 * d2 <= 0.0:
        return {"order": None, "extrapolated": None, "regular": False}
    g = lambda q: (h1 ** q - h2 ** q) / (h2 ** q - h3 ** q) - d1 / d2  # noqa: E731
    if g(0.2) * g(12.0) > 0.0:
        return {"order": None, "extrapolated": None, "regular": False}
    from scipy.optimize import brentq
    q = brentq(g, 0.2, 12.0, xtol=1e-12)
    return {"order": q, "extrapolated": f3 - d2 * h3 ** q / (h2 ** q - h3 ** q), "regular": True}


def converge(refines, tol, law, data_refine=None, n_modes=4):
    """The graded mesh refined along `refines` (each factor divides every size and growth rate)
    until the lowest n_modes modes of the measured half at 7.2 MPa (real) and its first y mode at
    the level-1 truth (self-consistent) move less than tol between successive meshes; returns the
    joint of the data (the finest mesh, or the mesh of refinement data_refine, one of
    `refines`), its measured half and the record."""
    E = REF_MODULI[0]
    rows, joint, sym = [], None, None
    for r in refines:
        del joint, sym
        t0 = time.time()
        joint = Joint(MESH, refine=r, half=True)
        sym = Half(joint, "sym")
        proj = modal_basis(sym, (E,))
        modes = mode_list(proj, E, np.inf, "sym")[:n_modes]
        y_sc = self_consistent(proj, law, 560.0)
        first = min((m for m in y_sc if m["energy_xyz"][1] > 0.5), key=lambda m: m["f_hz"])
        row = {"refine": r, "free_dofs_sym_half": int(len(sym.free)), "elements": joint.counts,
               "f_hz_real_7.2MPa": [m["f_hz"] for m in modes],
               "energy_y": [m["energy_xyz"][1] for m in modes],
               "max_residual": max(m["residual"] for m in modes),
               "first_y_mode_at_truth_hz": first["f_hz"], "first_y_mode_eta": first["eta"],
               "time_s": round(time.time() - t0, 1)}
        rows.append(row)
        del proj
        change = None
        if len(rows) > 1:
            prev = rows[-2]
            vals = row["f_hz_real_7.2MPa"] + [row["first_y_mode_at_truth_hz"]]
            old = prev["f_hz_real_7.2MPa"] + [prev["first_y_mode_at_truth_hz"]]
            change = max(abs(a - b) / a for a, b in zip(vals, old))
            row["max_rel_change_from_previous"] = change
        print(f"  refine {r:g}: elements {joint.counts}, {row['free_dofs_sym_half']} DOFs, "
              f"modes at 7.2 MPa " + ", ".join(f"{v:.4f}" for v in row["f_hz_real_7.2MPa"])
              + f" Hz, first y mode at the truth {first['f_hz']:.5f} Hz"
              + ("" if change is None else f", largest change {change:.1e}")
              + f" ({row['time_s']:.0f} s)", flush=True)
        if change is not None and change < tol:
            break
    tried = [rw["refine"] for rw in rows]
    if data_refine is None or data_refine == tried[-1]:
        data_refine, k_data = tried[-1], len(rows) - 1
    else:
        if data_refine not in tried:
            raise SystemExit(f"--data-refine {data_refine:g} is not one of the meshes {tried}")
        k_data = tried.index(data_refine)
        del joint, sym
        joint = Joint(MESH, refine=data_refine, half=True)
        sym = Half(joint, "sym")
    rec = {"modulus_pa": E, "tolerance": tol, "meshes": rows, "data_mesh_refine": data_refine,
           "converged": bool(len(rows) > 1 and rows[-1]["max_rel_change_from_previous"] < tol),
           "h": "1 / refine (every size and growth rate of the graded spec divided by refine)"}
    per_mode = []
    names = [f"sym mode {k + 1} at 7.2 MPa (real)" for k in range(n_modes)] \
        + ["first y mode, self-consistent at the level-1 truth"]
    for k, name in enumerate(names):
        key = (lambda rw: rw["f_hz_real_7.2MPa"][k]) if k < n_modes \
            else (lambda rw: rw["first_y_mode_at_truth_hz"])
        f = [key(rw) for rw in rows if (k >= n_modes or len(rw["f_hz_real_7.2MPa"]) > k)]
        if len(f) != len(rows):
            continue
        h = [1.0 / rw["refine"] for rw in rows]
        m = {"mode": name, "f_hz": f, "free_dofs": [rw["free_dofs_sym_half"] for rw in rows]}
        if k < n_modes:
            m["energy_y_finest"] = rows[-1]["energy_y"][k]
        if len(f) >= 3:
            m.update(observed_order(h, f))
        if len(f) >= 3:  # the same with h = DOFs^(-1/3): the element counts are rounded up
            hd = [n ** (-1.0 / 3.0) for n in m["free_dofs"]]
            alt = observed_order(hd, f)
            m["order_h_from_dofs"] = alt["order"]
            m["extrapolated_h_from_dofs"] = alt["extrapolated"]
        if len(f) >= 4:  # the same from the three meshes before: how steady the order is
            prev = observed_order(h[:-1], f[:-1])
            m["order_previous_three"] = prev["order"]
            m["extrapolated_previous_three"] = prev["extrapolated"]
        if len(f) < 3:
            m.update({"order": None, "extrapolated": None, "regular": None})
        m["data_mesh_f_hz"] = f[k_data]
        if m["extrapolated"] is not None:
            m["finest_rel_error"] = (f[-1] - m["extrapolated"]) / m["extrapolated"]
            m["data_mesh_rel_error"] = (f[k_data] - m["extrapolated"]) / m["extrapolated"]
            m["error_estimate"] = "Richardson extrapolation with the observed order"
        else:
            m["finest_rel_error"] = None
            m["data_mesh_rel_error"] = None
            m["error_estimate"] = ("irregular: no extrapolation; the last change "
                                   f"{(f[-1] - f[-2]) / f[-1]:+.2e} bounds its size only roughly"
                                   if len(f) > 1 else "one mesh only")
        m["last_rel_change"] = (f[-1] - f[-2]) / f[-1] if len(f) > 1 else None
        ex, ex_d = m.get("extrapolated"), m.get("extrapolated_h_from_dofs")
        m["extrapolation_spread_rel"] = abs(ex - ex_d) / ex if ex and ex_d else None
        po, pp = m.get("order"), m.get("order_previous_three")
        if ex is None:
            m["assessment"] = "irregular: no order fits the last three meshes"
        elif po is not None and pp is not None and abs(pp / po - 1.0) > 0.3:
            m["assessment"] = (f"order not steady ({pp:.2f} from the three meshes before, "
                               f"{po:.2f} from the last three): the coarser meshes are not yet "
                               "in the asymptotic range, the extrapolation is an estimate; "
                               "extrapolation_spread_rel compares h = 1 / refine with "
                               "h = DOFs^(-1/3)")
        elif (len(f) >= 4 and pp is None) or ex_d is None:
            m["assessment"] = ("no order fits the three meshes before or h = DOFs^(-1/3): "
                               "the extrapolation is an estimate")
        else:
            m["assessment"] = "regular"
        per_mode.append(m)
    rec["modes"] = per_mode
    return joint, sym, rec


def verify_rom(rom, sym, law, y_modes, n_verify, jobs, tol=1e-6, extended=False,
               extra_peaks=()):
    """The reduced basis against direct sparse LU solves of the full half at 1 and 500 Hz, the y
    modes' peaks and log-spaced frequencies up to n_verify in all."""
    t0 = time.time()
    wd = 2 * np.pi * np.linspace(1.0, 500.0, 20001)
    peak = np.abs(rom.accelerance(wd, law(wd))).max(axis=1)
    f_peaks = [round(m["f_hz"], 3) for m in y_modes if m["f_hz"] <= 500.0]
    f_peaks += [round(f, 3) for f in extra_peaks if f <= 500.0]
    n_more = max(n_verify - 2 - len(f_peaks), 0)
    f_check = sorted(set([1.0, 500.0] + f_peaks
                         + [round(float(v), 3) for v in np.geomspace(4.0, 470.0, n_more)]))
    wE = [(2 * np.pi * fc, complex(law(2 * np.pi * fc))) for fc in f_check]
    errs, resids = [], []
    if isinstance(sym, tuple):  # general single-lap points: the sum of both halves' solves
        per_half = [direct_receptances(h, wE, jobs, extended) for h in sym]
        direct = [(sum(r[k][0] for r in per_half), max(r[k][1] for r in per_half))
                  for k in range(len(wE))]
    else:
        direct = direct_receptances(sym, wE, jobs, extended)
    for (w, E), (xd, resid) in zip(wE, direct):
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
        **({"vectors_sym_anti": rom.vectors} if isinstance(rom, PairROM) else {}),
        "time_s": round(time.time() - t0, 1),
    }
    if extended:
        romcheck["direct_refinement"] = ("extended precision (longdouble residuals of the "
                                         "matrix summed in longdouble, up to 6 steps)")
    print(f"reduced basis vs direct sparse LU at {len(f_check)} frequencies "
          f"({', '.join(f'{f:g}' for f in f_check)} Hz): max |H_rom - H_direct| / peak = "
          f"{romcheck['max_rel_error']:.1e} (per FRF "
          + ", ".join(f"{v:.1e}" for v in romcheck["max_rel_error_per_frf"])
          + f"); direct residual <= {romcheck['direct_relative_residual_max']:.0e} "
          f"({romcheck['time_s']:.1f} s)", flush=True)
    if romcheck["max_rel_error"] > tol:
        raise SystemExit(f"reduced basis check failed (> {tol:g} of a peak)")
    return romcheck


def effects_record(joint):
    """truth.json's "case" of a joint with base springs or masses: its effects in the form of
    the independent experiments of studies/data/virtual (support_td, mass3d_td), with the
    model's details."""
    parts = []
    if BASE_SPRINGS is not None:
        parts.append(f"springs under the adhesive (k_n {BASE_SPRINGS['normal']:.3g}, k_t "
                     f"{BASE_SPRINGS['tangential']:.3g} N/m^3)")
    parts += [f"{1e3 * m['kg']:g} g mass at point {m['point']} ({', '.join(m['directions'])})"
              for m in MASSES]
    return {
        "name": JOINT_NAME,
        "description": "independent virtual experiment, Model 4, td, undeclared "
                       + " and ".join(parts),
        "effects": {
            "point_mass": [{"point": m["point"], "mass_kg": m["kg"],
                            "directions": m["directions"]} for m in MASSES],
            "shaker": None,
            "support": (None if BASE_SPRINGS is None else
                        {"k_normal_N_per_m3": BASE_SPRINGS["normal"],
                         "k_tangential_N_per_m3": BASE_SPRINGS["tangential"], "eta": 0.0}),
            "beam": None,
            "disbond": None,
            "channels": None,
        },
        "model": {
            "base_springs": (None if BASE_SPRINGS is None else
                             "surface integral of k_n u_y v_y + k_t (u_x v_x + u_z v_z) over "
                             "the adhesive's lower face added to K_b (consistent, scikit-fem "
                             "facet basis); the face's DOFs free; no damping"),
            "base_area_m2": joint.base_area,
            "masses": ("lumped at the point's node in each listed translation, no rotary "
                       "inertia; " + ("the whole width: the whole mass" if not joint.half else
                                      "half width: half of each mass (the points lie on the "
                                      "mid-width plane)")) if MASSES else None,
            "mass_dofs": joint.mass_dofs,
        },
    }


def lap_geometry():
    """truth.json's geometry of a single-lap joint."""
    L, lo, t1, ta, t2, w = (LAP[k] for k in ("L", "overlap", "t1", "ta", "t2", "w"))
    x0, x2, y1, y2 = (round(v, 12) for v in (L - lo, 2 * L - lo, t1 + ta, t1 + ta + t2))
    return {
        "kind": "single_lap", "strip_length_m": L, "lower_thickness_m": t1,
        "upper_thickness_m": t2, "width_m": w, "overlap_m": lo, "adhesive_thickness_m": ta,
        "lower_strip_m": {"x": [0.0, L], "y": [0.0, t1], "z": [0.0, w]},
        "adhesive_m": {"x": [x0, L], "y": [t1, y1], "z": [0.0, w]},
        "upper_strip_m": {"x": [x0, x2], "y": [y1, y2], "z": [0.0, w]},
        "bond": "perfect (shared nodes)",
        "support": "clamped: every node of the lower strip's end face x = 0 fixed "
                   "(u_x, u_y, u_z)",
        "points": ([{"id": sp_["id"], "position_m": [float(v) for v in sp_["pos"]],
                     "direction": sp_["dir"]} for sp_ in POINTS_SPEC]
                   if POINTS_SPEC is not None else
                   [{"id": i + 1, "position_m": [float(v) for v in p], "direction": "+y"}
                    for i, p in enumerate(point_targets())]),
        "excitation_point": DRIVE,
        **({"channels": CHANNELS} if POINTS_SPEC is not None else {}),
    }


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", help="output folder")
    ap.add_argument("--joint", help="JSON file of the joint (see load_joint); default: the "
                                    "400 x 8 x 25 mm beam on a 3 mm bond line at its end")
    ap.add_argument("--segments", type=int, default=200, help="Welch segments (50 %% overlap)")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--mesh", choices=("matched", "graded", "converged"), default=None,
                    help="matched: rfmlab's default discretisation of this joint, built here "
                         "(20-node, uniform 5 mm); graded: 27-node, graded towards the bond "
                         "line's edges (the mesh-convergence reference); converged: the graded "
                         "mesh refined along --refine-seq, data on the finest or --data-refine "
                         "(default matched; a single-lap joint: graded, it has no matched mesh)")
    ap.add_argument("--refine-mesh", type=float, default=1.0,
                    help="divide every element size and growth rate of MESH by this")
    ap.add_argument("--refine-seq", default="1,1.41,2",
                    help="--mesh converged: the refinements tried, coarsest first")
    ap.add_argument("--data-refine", type=float,
                    help="--mesh converged: the refinement of the data's mesh, one of "
                         "--refine-seq (default the finest; a finer mesh may serve the "
                         "extrapolation only where the data's LUs would not fit in memory)")
    ap.add_argument("--conv-tol", type=float, default=1e-4,
                    help="--mesh converged: stop when the modes move less than this")
    ap.add_argument("--check-mesh", action="store_true",
                    help="also solve the mesh refined by --refine and print the convergence "
                         "(slow: minutes, ~13 GB)")
    ap.add_argument("--refine", type=float, default=2.0, help="refinement of --check-mesh")
    ap.add_argument("--verify", type=int, default=10,
                    help="frequencies of the reduced basis's check against direct solves")
    ap.add_argument("--ref-moduli",
                    help="real moduli (Pa, comma separated) of the reduced basis's expansions "
                         "instead of the automatic two (see ref_moduli), e.g. 5.6e6,7.2e6,10e6 "
                         "where a level's check against direct solves fails with two")
    ap.add_argument("--krylov-depth", type=int,
                    help=f"frequency moments of the reduced basis per modulus ({KRYLOV_DEPTH})")
    ap.add_argument("--modulus-moments", type=int,
                    help=f"modulus moments of the reduced basis per modulus ({KRYLOV_S_DEPTH})")
    ap.add_argument("--krylov-chains", choices=("shared", "own"), default="shared",
                    help="shared (the default): each modulus's next frequency moment from the "
                         "vector orthogonalised against the whole basis; own: from the chain's "
                         "own Arnoldi vectors, a true Krylov space per modulus (see krylov; "
                         "needed with base_springs)")
    ap.add_argument("--verify-at",
                    help="further frequencies (Hz, comma separated) of the reduced basis's check, "
                         "e.g. a y mode's peak that the self-consistent mode list misses")
    ap.add_argument("--rom-tol", type=float, default=1e-6,
                    help="largest error of the reduced basis against the direct solves, "
                         "relative to each FRF's peak (the run stops above it)")
    ap.add_argument("--direct-extended", action="store_true",
                    help="the direct solves of the reduced basis's check refined with residuals "
                         "in extended precision (see direct_receptance): a reference good to "
                         "1e-9 of a peak at sharp resonances, where the default's rounding is "
                         "1e-6 to 1e-5 of it")
    ap.add_argument("--no-exact", action="store_true", help="do not write exact.npz")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1),
                    help="processes for the direct solves of the check")
    args = ap.parse_args(argv[1:])
    global KRYLOV_CHAINS
    KRYLOV_CHAINS = args.krylov_chains
    verify_at = [float(v) for v in args.verify_at.split(",")] if args.verify_at else []
    t_start = time.time()
    joint_cfg = load_joint(args.joint) if args.joint else None
    if args.mesh is None:
        args.mesh = "graded" if JOINT_KIND == "single_lap" else "matched"
    if JOINT_KIND == "single_lap" and args.mesh == "matched":
        raise SystemExit("a single-lap joint has no matched mesh here: --mesh graded or "
                         "converged")
    os.makedirs(args.out, exist_ok=True)
    law = lambda w: model4(w, TRUTH)  # noqa: E731
    base_seed = joint_cfg.get("seed", args.seed) if joint_cfg else args.seed
    ref = (tuple(float(v) for v in args.ref_moduli.split(",")) if args.ref_moduli
           else ref_moduli())

    matched = args.mesh == "matched"
    spec = MESH_MATCHED if matched else MESH
    conv = None
    if args.mesh == "converged":
        refines = [float(v) for v in args.refine_seq.split(",")]
        print(f"mesh convergence of joint {JOINT_NAME} along refinements {refines}:", flush=True)
        joint, sym, conv = converge(refines, args.conv_tol, law, args.data_refine)
        conv["source"] = "computed by this run"
        if REF_MODULI[0] not in ref:
            sym._lu.clear()  # the convergence's LU is not one of the reduced basis's
        anti = Half(joint, "anti")
        refine_used = conv["data_mesh_refine"]
    else:
        joint = Joint(spec, refine=args.refine_mesh, half=not matched)
        refine_used = args.refine_mesh
        if matched:
            sym, anti = Half(joint, "full"), None
        else:
            sym, anti = Half(joint, "sym"), Half(joint, "anti")
    if matched:
        mesh_info = {"elements_whole_width": joint.counts, "elements": joint.n_elements,
                     "free_dofs": int(len(sym.free))}
    else:
        mesh_info = {"elements_half_width": joint.counts, "elements": joint.n_elements,
                     "free_dofs_sym_half": int(len(sym.free)),
                     "free_dofs_anti_half": int(len(anti.free))}
    print(f"{args.mesh} mesh (refinement {refine_used:g}): elements {joint.counts} "
          + (f"({joint.n_elements['strips']} strips, " if JOINT_KIND == "single_lap" else
             f"({joint.n_elements['beam']} beam, ")
          + f"{joint.n_elements['bond']} bond line), "
          f"{len(sym.free)} free DOFs ({'whole joint' if matched else 'symmetric half'}); "
          f"assembled in {joint.assembly_s:.1f} s", flush=True)
    case = effects_record(joint) if BASE_SPRINGS is not None or MASSES else None
    if case is not None:
        print("effects: " + case["description"].split("undeclared ")[1]
              + (f"; base face {joint.base_area * 1e6:.1f} mm^2" if joint.base_area else ""),
              flush=True)

    # the reduced basis of the measured (symmetric) half
    t0 = time.time()
    rom = Projected(sym, krylov(sym, ref, [sym.f], args.krylov_depth or KRYLOV_DEPTH,
                                args.modulus_moments or KRYLOV_S_DEPTH))
    general = POINTS_SPEC is not None and anti is not None
    if general:  # general points: the antisymmetric half carries its share of force and outputs
        rom_a = Projected(anti, krylov(anti, ref, [anti.f], args.krylov_depth or KRYLOV_DEPTH,
                                       args.modulus_moments or KRYLOV_S_DEPTH))
        rom = PairROM([rom, rom_a])
        print(f"reduced basis: {rom.vectors} vectors (symmetric, antisymmetric half; "
              f"{time.time() - t0:.1f} s)", flush=True)
    else:
        print(f"reduced basis: {rom.V.shape[1]} vectors ({time.time() - t0:.1f} s)", flush=True)

    # modes: real modulus 7.2 MPa (whole joint), self-consistent (measured half), all modes
    # below 520 Hz at E*(first y mode) (both halves)
    t0 = time.time()
    msym = modal_basis(sym, ref)
    # (the finest mesh of --mesh converged: the antisymmetric half's basis at one modulus only,
    # to spare the memory of a second LU; its modes' residuals are recorded)
    manti = (modal_basis(anti, ref[:1] if args.mesh == "converged" else ref)
             if anti is not None else None)

    def both(E, fmax):
        rows = mode_list(msym, E, fmax, sym.kind)
        if manti is not None:
            rows += mode_list(manti, E, fmax, "anti")
        return sorted(rows, key=lambda m: m["f_hz"])

    real72 = both(7.2e6, 1000.0)[:8]
    print(f"modes ({time.time() - t0:.1f} s). Whole joint at E = 7.2 MPa real: "
          + ", ".join(f"{m['f_hz']:.4f} Hz ({m['symmetry']})" for m in real72)
          + f"; largest residual {max(m['residual'] for m in real72):.1e}", flush=True)

    lines = np.arange(1.0, 501.0)
    w_lines = 2 * np.pi * lines
    levels = []
    for i, (name, force_rms_n, params, seed) in enumerate(LEVELS):
        law_i = lambda w, p=params: model4(w, p)  # noqa: E731
        seed = base_seed + i if seed is None else int(seed)
        y_modes = self_consistent(msym, law_i, 560.0)
        first = min((m for m in y_modes if m["energy_xyz"][1] > 0.5), key=lambda m: m["f_hz"])
        E1st = complex(first["E_storage_pa"], first["E_loss_pa"])
        print(f"{name}: self-consistent modes at the truth (measured half): "
              + ", ".join(f"{m['f_hz']:.3f} Hz eta {m['eta']:.4f}" for m in y_modes), flush=True)
        H_lines = rom.accelerance(w_lines, law_i(w_lines))
        extra_peaks = tuple(verify_at)
        if general:  # the antisymmetric half's modes in band, self-consistent at the truth
            a_modes = self_consistent(manti, law_i, 560.0)
            for m in a_modes:
                m["symmetry"] = "anti"
            extra_peaks = [m["f_hz"] for m in a_modes] + verify_at
            print(f"{name}: self-consistent modes at the truth (antisymmetric half): "
                  + ", ".join(f"{m['f_hz']:.3f} Hz eta {m['eta']:.4f}" for m in a_modes),
                  flush=True)
        romcheck = verify_rom(rom, (sym, anti) if general else sym, law_i, y_modes, args.verify,
                              args.jobs, args.rom_tol, args.direct_extended, extra_peaks)
        freq, H1, coh, stats = measure(rom, law_i, args.segments, seed, force_rms_n)
        print(f"{name} record: {stats['N']} samples ({stats['record_s']} s), "
              f"{stats['n_bins_in_band']} FFT bins in (0, 500] Hz (FRF in "
              f"{stats['frf_eval_s']:.1f} s); force {stats['force_rms_n']:.4f} N RMS; coherence "
              f"min {stats['coherence_min']:.4f}, median {stats['coherence_median']:.6f}",
              flush=True)
        write_uff(os.path.join(args.out, f"level{i + 1}.uff"), freq, H1, coh, args.segments,
                  level=i + 1, force_rms_n=force_rms_n)
        levels.append({"id": i + 1, "name": name, "force_rms_N": force_rms_n, "law": "model4",
                       "params": params, "seed": seed, "file": f"level{i + 1}.uff",
                       "y_modes": y_modes, "first_y_mode": first,
                       **({"anti_modes": a_modes} if general else {}),
                       "E_star_first_y_mode_pa":
                       [E1st.real, E1st.imag], "rom_check": romcheck,
                       "measurement": {**CHAIN, "force_rms_n": force_rms_n, "seed": seed,
                                       **stats},
                       "_H_lines": H_lines})
    L1 = levels[0]
    y_modes, first, romcheck = L1["y_modes"], L1["first_y_mode"], L1["rom_check"]
    E1st = complex(*L1["E_star_first_y_mode_pa"])
    at_first = both(E1st, 520.0)
    if not args.no_exact:
        extra = {f"H_exact_L{lv['id']}": lv["_H_lines"] for lv in levels[1:]}
        np.savez(os.path.join(args.out, "exact.npz"), freq_hz=lines, H_exact=L1["_H_lines"],
                 E_star=law(w_lines),
                 points=np.array(CHANNELS) if POINTS_SPEC is not None else np.arange(1, 5),
                 **extra)
    for lv in levels:
        del lv["_H_lines"]

    if args.check_mesh:
        del rom, msym, manti, sym, anti, joint
        print("mesh convergence (E = 7 MPa real, first six modes of the whole joint):", flush=True)
        conv = check_mesh(spec, args.refine_mesh, args.refine)
        conv["source"] = "computed by this run"
    elif conv is None:
        conv = dict(CONVERGENCE_RECORDED if args.refine_mesh == 1.0 and not matched else {})
        conv["source"] = "recorded by --check-mesh" if conv else "not computed"

    files = ", ".join(lv["file"] for lv in levels)
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
        "joint": JOINT_NAME,
        "geometry": lap_geometry() if JOINT_KIND == "single_lap" else {
            "beam_length_m": BEAM_L, "beam_thickness_m": BEAM_T, "beam_width_m": BEAM_W,
            "adhesive_x_start_m": BOND_X0, "adhesive_length_m": BOND_L,
            "adhesive_thickness_m": BOND_T,
            "base": ("adhesive lower face fixed" if BASE_SPRINGS is None else
                     "adhesive lower face free on distributed springs (case.effects.support)"),
            "points": [{"id": i + 1, "position_m": [x, BEAM_T, BEAM_W / 2], "direction": "+y"}
                       for i, x in enumerate(POINTS_X)],
            "excitation_point": DRIVE,
        },
        "materials": ({"strips": STEEL, "adhesive": GLUE} if JOINT_KIND == "single_lap"
                      else {"beam": STEEL, "adhesive": GLUE}),
        **({"case": case} if case is not None else {}),
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
                       f"symmetry about z = {BEAM_W / 2:g} (sym modes are the measured ones); "
                       "residual = ||(K - lambda M) phi|| / ||K phi|| on the full half model",
        "model": {
            "element": ("20-node serendipity hexahedron (scikit-fem ElementHexS2), 3x3x3 Gauss"
                        if matched else
                        "27-node triquadratic hexahedron (scikit-fem ElementHex2), 3x3x3 Gauss"),
            "mesh": args.mesh, "mesh_spec": spec, "mesh_refinement": refine_used,
            **mesh_info,
            "symmetry": ("none: the whole width" if matched else
                         f"half width z in [0, {BEAM_W / 2:g}]; data the sum of the symmetric "
                         "(u_z = 0 on the plane) and antisymmetric (u_x = u_y = 0 on it) "
                         "halves, each with half the mirrored force (points and force off the "
                         "plane or not in y)" if POINTS_SPEC is not None else
                         f"half width z in [0, {BEAM_W / 2:g}]; data from the symmetric half "
                         "(u_z = 0 on the plane, force halved)"),
            "reduced_basis": {"reference_moduli_pa": list(ref),
                              "krylov_depth": args.krylov_depth or KRYLOV_DEPTH,
                              "modulus_moments": args.modulus_moments or KRYLOV_S_DEPTH,
                              **({"chains": "own (krylov_own_chains)"}
                                 if KRYLOV_CHAINS == "own" else {}),
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
        "level": {"name": "L1", "force_rms_n": L1["force_rms_N"], "law": "model4",
                  "params": TRUTH},
        "levels": levels,
        "measurement": L1["measurement"],
        "runtime_s": round(time.time() - t_start, 1),
    }
    with open(os.path.join(args.out, "truth.json"), "w") as fh:
        json.dump(truth, fh, indent=1)
    if joint_cfg is not None:
        with open(os.path.join(args.out, "joint.json"), "w") as fh:
            json.dump(joint_cfg, fh, indent=1)
    print(f"wrote {os.path.join(args.out, files)}, truth.json"
          f"{'' if args.no_exact else ', exact.npz'} ({time.time() - t_start:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
