//! Steel cantilever 300 x 10 x 20 mm clamped at x = 0 (no adhesive): the first bending
//! frequencies in y (thickness 10 mm) and z (width 20 mm) against beam theory.
//!
//! Eigenvalues by subspace iteration with faer's sparse Cholesky of K (Bathe's method):
//! Y = K^-1 M X, Rayleigh-Ritz on span(Y), repeat.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use rfmlab::fe::element::Integration;
use rfmlab::fe::joint::{build_cantilever, IsoMaterial};
use rfmlab::fe::mesh::HexMesh;
use rfmlab::fe::model::SpMat;

const L: f64 = 0.3;
const T: f64 = 0.01;
const W: f64 = 0.02;
const STEEL: IsoMaterial = IsoMaterial {
    e_pa: 198e9,
    nu: 0.3,
    rho_kg_m3: 7800.0,
};

fn spmm(a: &SpMat, x: &Mat<f64>) -> Mat<f64> {
    let (sym, val) = a.parts();
    let mut y = Mat::<f64>::zeros(a.nrows(), x.ncols());
    for c in 0..x.ncols() {
        for j in 0..a.ncols() {
            let xj = x[(j, c)];
            for p in sym.col_ptr()[j]..sym.col_ptr()[j + 1] {
                y[(sym.row_idx()[p], c)] += val[p] * xj;
            }
        }
    }
    y
}

/// Lowest `p` eigenpairs of K x = lambda M x by subspace iteration (deterministic start).
fn lowest_modes(k: &SpMat, m: &SpMat, p: usize, iters: usize) -> (Vec<f64>, Mat<f64>) {
    let n = k.nrows();
    let chol = k.sp_cholesky(Side::Lower).expect("clamped K is SPD");
    let mut x = Mat::<f64>::from_fn(n, p, |i, j| {
        (((i * 31 + j * 17) % 23) as f64 - 11.0) + if i % p == j { 50.0 } else { 0.0 }
    });
    let mut lam = vec![0.0; p];
    for _ in 0..iters {
        let y = chol.solve(spmm(m, &x));
        let kr = y.transpose() * spmm(k, &y);
        let mr = y.transpose() * spmm(m, &y);
        // reduced generalized problem via Cholesky of M_r
        let llt = mr.llt(Side::Lower).expect("M_r SPD");
        let lr = llt.L().to_owned();
        // A = L^-1 K_r L^-T
        let mut linv = Mat::<f64>::identity(p, p);
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(
            lr.as_ref(),
            linv.as_mut(),
            faer::Par::Seq,
        );
        let a = &linv * &kr * linv.transpose();
        let a = Mat::<f64>::from_fn(p, p, |i, j| 0.5 * (a[(i, j)] + a[(j, i)]));
        let evd = a.self_adjoint_eigen(Side::Lower).expect("evd");
        let q = linv.transpose() * evd.U();
        x = &y * &q;
        for (i, l) in lam.iter_mut().enumerate() {
            *l = evd.S().column_vector()[i];
        }
    }
    (lam, x)
}

/// Fraction of the mode's squared displacement in y and z.
fn yz_share(mesh: &HexMesh, x: &Mat<f64>, col: usize) -> (f64, f64) {
    let dofs = rfmlab::fe::assembly::DofMap::new(mesh);
    let (mut s, mut sy, mut sz) = (0.0, 0.0, 0.0);
    for n in 0..mesh.n_nodes() {
        for c in 0..3 {
            if let Some(d) = dofs.dof(n, c) {
                let v = x[(d, col)] * x[(d, col)];
                s += v;
                if c == 1 {
                    sy += v;
                }
                if c == 2 {
                    sz += v;
                }
            }
        }
    }
    (sy / s, sz / s)
}

/// First clamped-free bending frequency (Hz) of a rectangular section of depth h in the
/// bending plane: Euler-Bernoulli, and a Timoshenko estimate (shear and rotary inertia
/// added as Dunkerley-type corrections: 1/w^2 = 1/w_EB^2 (1 + (l1 r / L)^2) + 1/w_s^2,
/// with the clamped-free shear-beam frequency w_s = pi / (2 L) sqrt(kappa G / rho),
/// kappa = 10 (1 + nu) / (12 + 11 nu) for a rectangle).
fn beam_theory(h: f64) -> (f64, f64) {
    let l1 = 1.875_104_068_711_961;
    let r = h / 12f64.sqrt();
    let c = (STEEL.e_pa / STEEL.rho_kg_m3).sqrt();
    let w_eb = l1 * l1 * c * r / (L * L);
    let g = STEEL.e_pa / (2.0 * (1.0 + STEEL.nu));
    let kappa = 10.0 * (1.0 + STEEL.nu) / (12.0 + 11.0 * STEEL.nu);
    let w_s = std::f64::consts::PI / (2.0 * L) * (kappa * g / STEEL.rho_kg_m3).sqrt();
    let inv = (1.0 + (l1 * r / L).powi(2)) / (w_eb * w_eb) + 1.0 / (w_s * w_s);
    let tp = 2.0 * std::f64::consts::PI;
    (w_eb / tp, 1.0 / inv.sqrt() / tp)
}

fn first_bending(div: [usize; 3]) -> (f64, f64) {
    let (model, mesh) = build_cantilever([L, T, W], div, &STEEL, Integration::Full).unwrap();
    let (lam, x) = lowest_modes(&model.k_b, &model.m, 4, 12);
    let mut fy = None;
    let mut fz = None;
    for (i, &l) in lam.iter().enumerate() {
        let f = l.sqrt() / (2.0 * std::f64::consts::PI);
        let (sy, sz) = yz_share(&mesh, &x, i);
        if sy > 0.9 && fy.is_none() {
            fy = Some(f);
        }
        if sz > 0.9 && fz.is_none() {
            fz = Some(f);
        }
    }
    (fy.expect("a y-bending mode"), fz.expect("a z-bending mode"))
}

#[test]
fn cantilever_bending_frequencies_converge_to_beam_theory() {
    let (eb_y, ti_y) = beam_theory(T);
    let (eb_z, ti_z) = beam_theory(W);
    let coarse = first_bending([30, 1, 2]);
    let fine = first_bending([60, 2, 4]);
    println!("beam theory y: EB {eb_y:.3} Hz, Timoshenko {ti_y:.3} Hz; z: EB {eb_z:.3} Hz, Timoshenko {ti_z:.3} Hz");
    println!("FE 30x1x2: y {:.3} Hz, z {:.3} Hz", coarse.0, coarse.1);
    println!("FE 60x2x4: y {:.3} Hz, z {:.3} Hz", fine.0, fine.1);
    // nested meshes, consistent mass: Rayleigh-Ritz upper bounds decrease under refinement
    assert!(fine.0 <= coarse.0 * (1.0 + 1e-9) && fine.1 <= coarse.1 * (1.0 + 1e-9));
    for (fe, ti, name) in [(fine.0, ti_y, "y"), (fine.1, ti_z, "z")] {
        let rel = (fe - ti) / ti;
        println!("{name}: FE / Timoshenko - 1 = {:+.3} %", 100.0 * rel);
        assert!(
            rel.abs() < 0.01,
            "{name}: {fe} Hz vs {ti} Hz ({:+.2} %)",
            100.0 * rel
        );
    }
}
