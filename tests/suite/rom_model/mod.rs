//! Test model shared by tests/rom.rs and benches/rom.rs: Euler-Bernoulli beam FE (300 mm
//! steel, 10 x 20 mm) resting on adhesive springs with their own mass under the first 50 mm.
#![allow(dead_code)]
use rfmlab::common::Direction;
use rfmlab::fe::model::{ObservationPoint, SpMat, StructuralModel};

pub fn sp(n: usize, t: &[(usize, usize, f64)]) -> SpMat {
    faer::sparse::SparseColMat::try_new_from_triplets(
        n,
        n,
        &t.iter()
            .map(|&(i, j, v)| faer::sparse::Triplet::new(i, j, v))
            .collect::<Vec<_>>(),
    )
    .unwrap()
}

/// Beam: n_el elements, DOFs (w, theta) per node; adhesive: under each bond node a mid node
/// (y DOF) joined by springs 2 E A/t to ground and to the beam node.
pub fn beam_model(n_el: usize) -> StructuralModel {
    let l = 0.3;
    let h = l / n_el as f64;
    let (e, rho, b, t) = (198e9, 7800.0, 0.02, 0.01);
    let ei = e * b * t * t * t / 12.0;
    let ra = rho * b * t;
    let n_nodes = n_el + 1;
    let n_bond = (0..n_nodes)
        .filter(|&i| (i as f64 * h) <= 0.05 + 1e-12)
        .count();
    let n = 2 * n_nodes + n_bond;
    let (mut km, mut mm, mut sm) = (Vec::new(), Vec::new(), Vec::new());
    let ke = [
        [12.0, 6.0 * h, -12.0, 6.0 * h],
        [6.0 * h, 4.0 * h * h, -6.0 * h, 2.0 * h * h],
        [-12.0, -6.0 * h, 12.0, -6.0 * h],
        [6.0 * h, 2.0 * h * h, -6.0 * h, 4.0 * h * h],
    ];
    let me = [
        [156.0, 22.0 * h, 54.0, -13.0 * h],
        [22.0 * h, 4.0 * h * h, 13.0 * h, -3.0 * h * h],
        [54.0, 13.0 * h, 156.0, -22.0 * h],
        [-13.0 * h, -3.0 * h * h, -22.0 * h, 4.0 * h * h],
    ];
    for el in 0..n_el {
        let d = [2 * el, 2 * el + 1, 2 * el + 2, 2 * el + 3];
        for a in 0..4 {
            for c in 0..4 {
                km.push((d[a], d[c], ke[a][c] * ei / (h * h * h)));
                mm.push((d[a], d[c], me[a][c] * ra * h / 420.0));
            }
        }
    }
    // adhesive (tributary width per bond node), thickness 10 mm, density 1160
    for k in 0..n_bond {
        let trib = if k == 0 || k == n_bond - 1 {
            0.5 * h
        } else {
            h
        };
        let area = trib * b;
        let ks = 2.0 * area / 0.01; // per unit E, for half the thickness
        let mid = 2 * n_nodes + k;
        let w = 2 * k;
        sm.push((mid, mid, 2.0 * ks));
        sm.push((w, w, ks));
        sm.push((w, mid, -ks));
        sm.push((mid, w, -ks));
        let madh = 1160.0 * area * 0.01;
        mm.push((mid, mid, 0.5 * madh));
        mm.push((w, w, 0.25 * madh));
    }
    let k_b = sp(n, &km);
    let d_b: Vec<_> = km.iter().map(|&(i, j, v)| (i, j, 2e-3 * v)).collect();
    let c_b: Vec<_> = mm.iter().map(|&(i, j, v)| (i, j, 5.0 * v)).collect();
    let points = [0.1, 0.15, 0.2, 0.25]
        .iter()
        .enumerate()
        .map(|(i, &x)| {
            let node = (x / h).round() as usize;
            ObservationPoint {
                id: i as u32 + 1,
                position: Some([x, 0.01, 0.01]),
                direction: Direction::PY,
                dofs: vec![(2 * node, 1.0)],
                note: String::new(),
            }
        })
        .collect();
    StructuralModel {
        m: sp(n, &mm),
        k_b,
        s: sp(n, &sm),
        c_b: Some(sp(n, &c_b)),
        d_b: Some(sp(n, &d_b)),
        points,
        description: "test beam on adhesive springs".into(),
    }
}
