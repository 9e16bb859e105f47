//! Small numeric helpers shared by the FE and FRF tests: a sparse matrix-vector product
//! (fe_element.rs, fe_joint.rs) and the central FRF difference of the finite-difference
//! sensitivity checks (frf_full.rs, paper_joint.rs).
#![allow(dead_code)]

use rfmlab::common::C64;
use rfmlab::fe::model::SpMat;
use rfmlab::frf::FrfEngine;

/// y = A x for a sparse (column-compressed) A.
pub fn spmv(a: &SpMat, x: &[f64]) -> Vec<f64> {
    let (sym, val) = a.parts();
    let mut y = vec![0.0; a.nrows()];
    for (j, &xj) in x.iter().enumerate().take(a.ncols()) {
        for p in sym.col_ptr()[j]..sym.col_ptr()[j + 1] {
            y[sym.row_idx()[p]] += val[p] * xj;
        }
    }
    y
}

/// H(E* + step) - H(E* - step) for every entry of a sweep on lines `w` (rad/s), with the same
/// complex `step` added to every line's modulus `e`; the caller divides by its own step.
pub fn sweep_difference(engine: &dyn FrfEngine, w: &[f64], e: &[C64], step: C64) -> Vec<C64> {
    let ep: Vec<C64> = e.iter().map(|&x| x + step).collect();
    let em: Vec<C64> = e.iter().map(|&x| x - step).collect();
    let hp = engine.sweep(w, &ep, false).unwrap();
    let hm = engine.sweep(w, &em, false).unwrap();
    hp.h.iter().zip(&hm.h).map(|(p, m)| p - m).collect()
}
