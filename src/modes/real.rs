//! Sparse real generalized symmetric eigensolver: the lowest modes of K x = lambda M x with
//! K symmetric positive definite and M symmetric positive definite.
//!
//! Method: shift-invert Lanczos in the M inner product with full reorthogonalisation
//! (Ericsson & Ruhe 1980; Grimes, Lewis & Simon 1994). The operator
//! A = (K - sigma M)^-1 M is self-adjoint in <x, y>_M = x^T M y and its largest eigenvalues
//! 1 / (lambda - sigma) belong to the eigenvalues lambda closest to the shift sigma
//! (sigma <= 0 keeps K - sigma M positive definite, so a sparse Cholesky factorisation is
//! used; its symbolic analysis is done once). The Krylov basis Q (M-orthonormal, reorthogonalised
//! twice per step) is grown in blocks; after each block a Rayleigh-Ritz step on the
//! shift-invert operator, (Q^T M A Q) y = nu (Q^T M Q) y, gives Ritz pairs with
//! lambda = sigma + 1 / nu, accepted when every requested pair satisfies the shift-invert
//! residual ||x - (lambda - sigma) A x||_M <= `tol` (x M-normalised).
//!
//! The projection is of A, not of the original pencil: Q^T K Q carries the rounding of
//! K's largest eigenvalues (a steel adherend meshed finely: lambda_max / lambda_1 ~ 1e11),
//! which floors the low Ritz pairs at a residual of ~1e-5 once the basis holds converged
//! vectors; A's spectrum is bounded by 1 / (lambda_1 - sigma), so its projection is not.
//!
//! All loops are sequential (faer with `Par::Seq`), so results do not depend on the number
//! of threads.

use super::ModesError;
use crate::fe::model::SpMat;
use crate::linalg::spmv_real;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};
use rand::{RngExt, SeedableRng};

/// Tuning knobs of [`real_modes`].
#[derive(Clone, Debug)]
pub struct EigenParams {
    /// Convergence tolerance on the relative residual ||K x - lambda M x|| / ||K x|| of every
    /// requested mode (default 1e-10).
    pub tol: f64,
    /// Shift sigma (1/s^2 units, i.e. rad^2/s^2); must be <= 0 so that K - sigma M is positive
    /// definite (default 0).
    pub shift: f64,
    /// Lanczos vectors added between two Rayleigh-Ritz convergence checks (default 16).
    pub block: usize,
    /// Largest Krylov basis before giving up with [`ModesError::NotConverged`]
    /// (default 0 = automatic: max(6 n + 60, 120), capped at the number of DOFs).
    pub max_basis: usize,
    /// Seed of the random start vector (default 1).
    pub seed: u64,
}

impl Default for EigenParams {
    fn default() -> Self {
        EigenParams {
            tol: 1e-10,
            shift: 0.0,
            block: 16,
            max_basis: 0,
            seed: 1,
        }
    }
}

/// Sparse Cholesky of a real SPD matrix, symbolic analysis and numeric factor, solving with
/// `Par::Seq`.
pub(crate) struct SparseLlt {
    symbolic: faer::sparse::linalg::cholesky::SymbolicCholesky<usize>,
    values: Vec<f64>,
}

impl SparseLlt {
    /// Factorise the SPD matrix `a` (both triangles stored; the lower one is read).
    pub(crate) fn new(a: &SpMat) -> Result<Self, ModesError> {
        let symbolic = factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| ModesError::Factorization(format!("symbolic Cholesky: {e:?}")))?;
        let mut values = vec![0.0; symbolic.len_val()];
        let req = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
        let mut buf = MemBuffer::try_new(req)
            .map_err(|_| ModesError::Factorization("out of memory for Cholesky".into()))?;
        symbolic
            .factorize_numeric_llt(
                &mut values,
                a.as_ref(),
                Side::Lower,
                LltRegularization {
                    dynamic_regularization_delta: 0.0,
                    dynamic_regularization_epsilon: 0.0,
                },
                Par::Seq,
                MemStack::new(&mut buf),
                Default::default(),
            )
            .map_err(|_| {
                ModesError::Factorization(
                    "K - sigma M is not positive definite: is the model constrained (adhesive modulus > 0, fixed DOFs removed) and the shift <= 0?".into(),
                )
            })?;
        Ok(SparseLlt { symbolic, values })
    }

    /// Solve A X = B in place.
    pub(crate) fn solve_in_place(&self, rhs: faer::MatMut<'_, f64>) {
        let req = self
            .symbolic
            .solve_in_place_scratch::<f64>(rhs.ncols(), Par::Seq);
        let mut buf = MemBuffer::new(req);
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut buf),
        );
    }
}

/// a + c b for sparse a, b of the same size (union pattern).
pub fn sp_add(a: &SpMat, b: &SpMat, c: f64) -> Result<SpMat, ModesError> {
    let mut t: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(a.val().len() + b.val().len());
    for x in a.triplet_iter() {
        t.push(Triplet::new(x.row, x.col, *x.val));
    }
    if c != 0.0 {
        for x in b.triplet_iter() {
            t.push(Triplet::new(x.row, x.col, c * *x.val));
        }
    }
    SparseColMat::try_new_from_triplets(a.nrows(), a.ncols(), &t)
        .map_err(|e| ModesError::BadInput(format!("cannot combine matrices: {e:?}")))
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Lowest `n` eigenpairs of K x = lambda M x (K, M symmetric positive definite, sparse).
///
/// Returns the eigenvalues lambda (rad^2/s^2) in ascending order and the eigenvectors as the
/// columns of an M-orthonormal matrix (X^T M X = I). See the module docs for the method.
pub fn real_modes(
    k: &SpMat,
    m: &SpMat,
    n: usize,
    params: &EigenParams,
) -> Result<(Vec<f64>, Mat<f64>), ModesError> {
    let nd = k.nrows();
    if k.ncols() != nd || m.nrows() != nd || m.ncols() != nd {
        return Err(ModesError::BadInput(format!(
            "K is {}x{} and M is {}x{}: both must be square of the same size",
            k.nrows(),
            k.ncols(),
            m.nrows(),
            m.ncols()
        )));
    }
    if n == 0 {
        return Ok((Vec::new(), Mat::zeros(nd, 0)));
    }
    if n > nd {
        return Err(ModesError::BadInput(format!(
            "{n} modes requested but the model has only {nd} DOFs"
        )));
    }
    if params.shift > 0.0 || !params.shift.is_finite() {
        return Err(ModesError::BadInput(format!(
            "EigenParams::shift = {} must be finite and <= 0",
            params.shift
        )));
    }
    let op = if params.shift != 0.0 {
        sp_add(k, m, -params.shift)?
    } else {
        k.clone()
    };
    let llt = SparseLlt::new(&op)?;
    let max_basis = if params.max_basis == 0 {
        (6 * n + 60).max(120)
    } else {
        params.max_basis.max(n)
    }
    .min(nd);
    let block = params.block.max(1);

    // Krylov basis Q (columns), M Q and A Q cached.
    let mut q: Vec<Vec<f64>> = Vec::new();
    let mut mq: Vec<Vec<f64>> = Vec::new();
    let mut aq: Vec<Vec<f64>> = Vec::new();
    let mut tr_rows: Vec<Vec<f64>> = Vec::new();
    let mut mr_rows: Vec<Vec<f64>> = Vec::new();
    let mut rng = rand::rngs::StdRng::seed_from_u64(params.seed);
    let mut next: Vec<f64> = (0..nd).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut tmp = vec![0.0; nd];
    // push the start vector through the operator once (removes components the operator damps)
    {
        spmv_real(m, &next, &mut tmp);
        let mut col = faer::Mat::from_fn(nd, 1, |i, _| tmp[i]);
        llt.solve_in_place(col.as_mut());
        next = (0..nd).map(|i| col[(i, 0)]).collect();
    }
    let mut last_residuals = vec![f64::INFINITY; n];
    loop {
        let target = (q.len() + block).min(max_basis);
        while q.len() < target {
            // M-orthogonalise `next` against Q twice (modified Gram-Schmidt with the cached
            // M q_i), then normalise
            spmv_real(m, &next, &mut tmp);
            let norm0 = dot(&next, &tmp).max(0.0).sqrt();
            for _pass in 0..2 {
                for (qi, mqi) in q.iter().zip(&mq) {
                    let c = dot(mqi, &next);
                    for (x, y) in next.iter_mut().zip(qi) {
                        *x -= c * y;
                    }
                }
            }
            spmv_real(m, &next, &mut tmp);
            let norm = dot(&next, &tmp).max(0.0).sqrt();
            if !norm.is_finite() || norm <= 1e-10 * norm0 {
                // invariant subspace found (or breakdown): restart with a fresh random vector
                next = (0..nd).map(|_| rng.random_range(-1.0..1.0)).collect();
                continue;
            }
            let inv = 1.0 / norm;
            let qi: Vec<f64> = next.iter().map(|x| x * inv).collect();
            let mqi: Vec<f64> = tmp.iter().map(|x| x * inv).collect();
            // A q_i = (K - sigma M)^-1 M q_i, also the next Krylov vector
            let mut col = faer::Mat::from_fn(nd, 1, |i, _| mqi[i]);
            llt.solve_in_place(col.as_mut());
            let aqi: Vec<f64> = (0..nd).map(|i| col[(i, 0)]).collect();
            next = aqi.clone();
            // new row of the projected matrices Q^T M A Q and Q^T M Q (symmetrised)
            let mut trow: Vec<f64> = (0..q.len())
                .map(|j| 0.5 * (dot(&mq[j], &aqi) + dot(&mqi, &aq[j])))
                .collect();
            trow.push(dot(&mqi, &aqi));
            let mut mrow: Vec<f64> = (0..q.len())
                .map(|j| 0.5 * (dot(&q[j], &mqi) + dot(&qi, &mq[j])))
                .collect();
            mrow.push(dot(&qi, &mqi));
            tr_rows.push(trow);
            mr_rows.push(mrow);
            q.push(qi);
            mq.push(mqi);
            aq.push(aqi);
        }
        let p = q.len();
        if p >= n {
            // Rayleigh-Ritz on the shift-invert operator: (Q^T M A Q) y = nu (Q^T M Q) y,
            // largest nu first (solved as -T y = -nu B y, ascending)
            let sym = |rows: &Vec<Vec<f64>>, sign: f64| {
                Mat::from_fn(p, p, |i, j| {
                    sign * if j <= i { rows[i][j] } else { rows[j][i] }
                })
            };
            let tr = sym(&tr_rows, -1.0);
            let mr = sym(&mr_rows, 1.0);
            let (neg_nu, y) = dense_generalized_spd(&tr, &mr)?;
            if neg_nu[..n].iter().any(|v| !(*v < 0.0)) {
                // fewer positive Ritz values than modes requested: grow the basis
                if q.len() >= max_basis {
                    return Err(ModesError::Factorization(
                        "shift-invert Rayleigh-Ritz gave a non-positive Ritz value: is M positive definite?".into(),
                    ));
                }
                continue;
            }
            let theta: Vec<f64> = neg_nu[..n].iter().map(|v| params.shift - 1.0 / v).collect();
            // Ritz vectors for the lowest n, and the shift-invert residual
            // ||x - (theta - sigma) (K - sigma M)^-1 M x||_M (x M-normalised): unlike
            // ||K x - theta M x|| / ||K x||, whose rounding floor grows with cond(K) (stiff steel
            // on a soft adhesive: ~1e10), it is well conditioned for the low modes.
            let mut x = Mat::<f64>::zeros(nd, n);
            let mut mxs = Mat::<f64>::zeros(nd, n);
            for c in 0..n {
                for (i, (qi, mqi)) in q.iter().zip(&mq).enumerate() {
                    let yi = y[(i, c)];
                    for r in 0..nd {
                        x[(r, c)] += qi[r] * yi;
                        mxs[(r, c)] += mqi[r] * yi;
                    }
                }
            }
            let mut kinv_mx = mxs.clone();
            llt.solve_in_place(kinv_mx.as_mut());
            let mut residuals = vec![0.0; n];
            let mut rv = vec![0.0; nd];
            let mut mrv = vec![0.0; nd];
            for c in 0..n {
                let scale = theta[c] - params.shift;
                for r in 0..nd {
                    rv[r] = x[(r, c)] - scale * kinv_mx[(r, c)];
                }
                spmv_real(m, &rv, &mut mrv);
                residuals[c] = dot(&rv, &mrv).max(0.0).sqrt();
            }
            let worst = residuals.iter().cloned().fold(0.0, f64::max);
            if worst <= params.tol {
                return Ok((theta[..n].to_vec(), x));
            }
            last_residuals = residuals;
        }
        if q.len() >= max_basis {
            let worst = last_residuals.iter().cloned().fold(0.0, f64::max);
            return Err(ModesError::NotConverged {
                what: format!(
                    "real eigensolver: {n} modes with a Krylov basis of {} vectors (EigenParams::max_basis)",
                    q.len()
                ),
                residual: worst,
                tol: params.tol,
            });
        }
    }
}

/// Dense generalized symmetric-definite eigenproblem A y = theta B y (B SPD) via
/// B = L L^T, C = L^-1 A L^-T, C z = theta z, y = L^-T z. Eigenvalues ascending,
/// Y^T B Y = I.
pub(crate) fn dense_generalized_spd(
    a: &Mat<f64>,
    b: &Mat<f64>,
) -> Result<(Vec<f64>, Mat<f64>), ModesError> {
    let p = a.nrows();
    let llt = b.llt(Side::Lower).map_err(|_| {
        ModesError::Factorization("projected mass matrix is not positive definite".into())
    })?;
    let l = llt.L();
    // C = L^-1 A L^-T
    let mut c = a.clone();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, c.as_mut(), Par::Seq);
    let mut ct = c.transpose().to_owned();
    faer::linalg::triangular_solve::solve_lower_triangular_in_place(l, ct.as_mut(), Par::Seq);
    let c = Mat::from_fn(p, p, |i, j| 0.5 * (ct[(i, j)] + ct[(j, i)]));
    let evd = c
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| ModesError::Factorization(format!("dense symmetric eigensolver: {e:?}")))?;
    let theta: Vec<f64> = (0..p).map(|i| evd.S()[i]).collect();
    let mut y = evd.U().to_owned();
    faer::linalg::triangular_solve::solve_upper_triangular_in_place(
        l.transpose(),
        y.as_mut(),
        Par::Seq,
    );
    Ok((theta, y))
}
