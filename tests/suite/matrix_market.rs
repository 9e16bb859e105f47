//! Matrix Market import/export: our own round trip (bit-exact), a round trip through SciPy's
//! mmread/mmwrite (scripts/mm_roundtrip.py) giving the same FRFs to 1e-12, and malformed
//! input errors.
//!
//! Python: env RFMLAB_PYTHON, default `<crate root>/.venv/bin/python` (create it with
//! `python3 -m venv .venv && .venv/bin/pip install numpy scipy`). When it is missing the SciPy
//! test prints a skip notice, unless env CI is set, in which case it fails.

use crate::python_checks::{python_for_scipy, scipy_round_trip};
use rfmlab::common::C64;
use rfmlab::fe::matrix_market::{
    export_model, import_model, parse_dof_map, parse_mtx, MmError, MmPaths,
};
use rfmlab::fe::model::StructuralModel;
use rfmlab::fe::synthetic::{add_damping, lattice_model, LatticeParams};
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;
use std::path::Path;

fn model() -> StructuralModel {
    let mut m = lattice_model(&LatticeParams::new(10, 3, 2, 21)).model;
    add_damping(&mut m, 3.0, 1e-6, 0.01);
    m
}

fn sweep(model: &StructuralModel) -> Vec<C64> {
    let fm = FullModel::new(model, &[1], FullParams::default()).unwrap();
    let w: Vec<f64> = (0..25)
        .map(|l| 2.0 * std::f64::consts::PI * (20.0 + 80.0 * l as f64))
        .collect();
    let e = vec![C64::new(7e6, 1.5e6); w.len()];
    fm.sweep(&w, &e, false).unwrap().h
}

fn same_matrix(a: &rfmlab::fe::model::SpMat, b: &rfmlab::fe::model::SpMat) {
    let da = rfmlab::fe::synthetic::to_dense(a);
    let db = rfmlab::fe::synthetic::to_dense(b);
    assert_eq!((da.nrows(), da.ncols()), (db.nrows(), db.ncols()));
    for j in 0..da.ncols() {
        for i in 0..da.nrows() {
            assert_eq!(
                da[(i, j)].to_bits(),
                db[(i, j)].to_bits(),
                "entry ({i},{j})"
            );
        }
    }
}

#[test]
fn export_import_is_bit_exact() {
    let m = model();
    let dir = tempfile::tempdir().unwrap();
    export_model(&m, dir.path()).unwrap();
    let back = import_model(&MmPaths::in_dir(dir.path())).unwrap();
    same_matrix(&m.m, &back.m);
    same_matrix(&m.k_b, &back.k_b);
    same_matrix(&m.s, &back.s);
    same_matrix(m.c_b.as_ref().unwrap(), back.c_b.as_ref().unwrap());
    same_matrix(m.d_b.as_ref().unwrap(), back.d_b.as_ref().unwrap());
    assert_eq!(m.points.len(), back.points.len());
    for (p, q) in m.points.iter().zip(&back.points) {
        assert_eq!((p.id, p.direction, &p.dofs), (q.id, q.direction, &q.dofs));
    }
    assert_eq!(sweep(&m), sweep(&back));
}

#[test]
fn scipy_round_trip_gives_same_frfs() {
    let Some(py) = python_for_scipy("scipy_round_trip_gives_same_frfs") else {
        return;
    };
    let m = model();
    let back = scipy_round_trip(&py, &m);
    assert!(back.c_b.is_some() && back.d_b.is_some());
    let (a, b) = (sweep(&m), sweep(&back));
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).norm() / x.norm())
        .fold(0.0, f64::max);
    eprintln!("scipy round trip: max relative FRF difference {worst:.1e}");
    assert!(worst < 1e-12);
}

fn parse_err(text: &str) -> String {
    match parse_mtx(text, Path::new("K_b.mtx")) {
        Err(e @ MmError::Parse { .. }) => e.to_string(),
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn malformed_matrix_market_is_a_clear_error() {
    let ok = "%%MatrixMarket matrix coordinate real symmetric\n% c\n2 2 2\n1 1 4.0\n2 1 -1\n";
    let a = parse_mtx(ok, Path::new("x.mtx")).unwrap();
    let d = rfmlab::fe::synthetic::to_dense(&a);
    assert_eq!(
        (d[(0, 0)], d[(1, 0)], d[(0, 1)], d[(1, 1)]),
        (4.0, -1.0, -1.0, 0.0)
    );

    let e = parse_err("%%MatrixMarket matrix coordinate real general\n2 2 1\n3 1 1.0\n");
    assert!(
        e.contains("K_b.mtx, line 3") && e.contains("outside"),
        "{e}"
    );
    let e = parse_err("%%MatrixMarket matrix coordinate real general\n2 2 2\n1 1 1.0\n");
    assert!(e.contains("announces 2 entries"), "{e}");
    let e = parse_err("%%MatrixMarket matrix coordinate pattern general\n2 2 1\n1 1\n");
    assert!(e.contains("pattern"), "{e}");
    let e = parse_err("%%MatrixMarket matrix array real general\n2 2\n1\n2\n3\n4\n");
    assert!(e.contains("coordinate"), "{e}");
    let e = parse_err("%%MatrixMarket matrix coordinate real general\n2 2 1\n1 1 abc\n");
    assert!(e.contains("line 3") && e.contains("abc"), "{e}");
    let e = parse_err("hello\n");
    assert!(e.contains("line 1"), "{e}");
}

#[test]
fn mismatched_sizes_name_the_files() {
    let m = model();
    let dir = tempfile::tempdir().unwrap();
    export_model(&m, dir.path()).unwrap();
    std::fs::write(
        dir.path().join("S.mtx"),
        "%%MatrixMarket matrix coordinate real general\n3 3 1\n1 1 1.0\n",
    )
    .unwrap();
    let e = import_model(&MmPaths::in_dir(dir.path())).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, MmError::SizeMismatch(_)));
    assert!(
        msg.contains("S.mtx is 3x3") && msg.contains("M.mtx"),
        "{msg}"
    );
}

#[test]
fn dof_map_format() {
    let text = "id,direction,dof,weight\n# comment\n1,+y,5,1.0\n2,-2,7,0.5\n2,-y,8,0.5\n3,z,1\n";
    let pts = parse_dof_map(text, Path::new("dofmap.csv"), 10).unwrap();
    assert_eq!(pts.len(), 3);
    assert_eq!(pts[1].dofs, vec![(6, 0.5), (7, 0.5)]);
    assert_eq!(pts[2].dofs, vec![(0, 1.0)]);
    let e = parse_dof_map("1,+y,11,1\n", Path::new("dofmap.csv"), 10)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dofmap.csv, line 1") && e.contains("outside 1..=10"),
        "{e}"
    );
    let e = parse_dof_map("1,+w,1,1\n", Path::new("dofmap.csv"), 10)
        .unwrap_err()
        .to_string();
    assert!(e.contains("direction '+w'"), "{e}");
}
