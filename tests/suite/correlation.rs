//! FRAC, SCC, ACC (paper eq. 38-40): identities on seeded random complex vectors.

use rand::rngs::Xoshiro256PlusPlus;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfmlab::common::C64;
use rfmlab::correlation::{
    acc, acc_curve, frac, frac_per_frf, normalised_sensitivity, normalised_sensitivity_scaled, scc,
    scc_curve,
};

fn randvec(rng: &mut Xoshiro256PlusPlus, n: usize) -> Vec<C64> {
    (0..n)
        .map(|_| {
            let re: f64 = StandardNormal.sample(rng);
            let im: f64 = StandardNormal.sample(rng);
            C64::new(re, im)
        })
        .collect()
}

fn scale(x: &[C64], c: C64) -> Vec<C64> {
    x.iter().map(|v| v * c).collect()
}

#[test]
fn frac_and_scc_are_one_for_any_complex_multiple() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(38);
    for n in [1, 2, 4, 500] {
        let x = randvec(&mut rng, n);
        for c in [
            C64::new(1.0, 0.0),
            C64::new(-3.0, 0.5),
            C64::new(0.0, 1e-6),
            C64::new(1e8, -2e8),
        ] {
            let a = scale(&x, c);
            assert!(
                (frac(&x, &a) - 1.0).abs() < 1e-12,
                "n {n} c {c}: {}",
                frac(&x, &a)
            );
            assert!((scc(&x, &a) - 1.0).abs() < 1e-12);
            // ACC(x, c x) = 2|c| / (1 + |c|^2).
            let m = c.norm();
            assert!((acc(&x, &a) - 2.0 * m / (1.0 + m * m)).abs() < 1e-12);
        }
    }
}

#[test]
fn acc_identities() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(40);
    let x = randvec(&mut rng, 4);
    assert!((acc(&x, &x) - 1.0).abs() < 1e-15);
    let x2 = scale(&x, C64::new(2.0, 0.0));
    assert!((acc(&x, &x2) - 0.8).abs() < 1e-15, "{}", acc(&x, &x2));
    // A phase rotation keeps SCC at 1 but ACC sees only |x^H a|: also 1 for a pure phase.
    let xr = scale(&x, C64::from_polar(1.0, 0.7));
    assert!((acc(&x, &xr) - 1.0).abs() < 1e-12);
}

#[test]
fn symmetric_and_bounded() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(39);
    for _ in 0..200 {
        let x = randvec(&mut rng, 6);
        let a = randvec(&mut rng, 6);
        for f in [frac, scc, acc] {
            let v = f(&x, &a);
            assert!((0.0..=1.0).contains(&v), "{v}");
            assert!((v - f(&a, &x)).abs() < 1e-14);
        }
        // ACC <= sqrt(FRAC)-type bound: 2|x^H a|/(|x|^2+|a|^2) <= |x^H a|/(|x||a|).
        assert!(acc(&x, &a) <= frac(&x, &a).sqrt() + 1e-14);
    }
    // Orthogonal vectors: 0.
    let x = [C64::new(1.0, 0.0), C64::new(0.0, 0.0)];
    let a = [C64::new(0.0, 0.0), C64::new(0.0, 2.0)];
    assert_eq!(frac(&x, &a), 0.0);
    assert_eq!(acc(&x, &a), 0.0);
    // Conjugate transpose, not plain transpose: x = [1, j], a = [1, j] -> x^T a = 0 but FRAC = 1.
    let x = [C64::new(1.0, 0.0), C64::new(0.0, 1.0)];
    assert!((frac(&x, &x) - 1.0).abs() < 1e-15);
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let z = [C64::new(0.0, 0.0); 3];
    let x = [C64::new(1.0, 0.0); 3];
    assert_eq!(frac(&z, &x), 0.0);
    assert_eq!(acc(&z, &z), 0.0);
    assert!(frac(&x, &x[..2]).is_nan());
    assert!(acc(&x, &x[..2]).is_nan());
}

#[test]
fn curves_over_line_frf_matrices() {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(41);
    let n_lines = 50;
    let x: Vec<Vec<C64>> = (0..n_lines).map(|_| randvec(&mut rng, 4)).collect();
    // a: line k scaled by c_k (SCC = 1 everywhere), FRF 2 column perturbed.
    let a: Vec<Vec<C64>> = x
        .iter()
        .enumerate()
        .map(|(k, row)| scale(row, C64::new(1.0 + 0.01 * k as f64, 0.1)))
        .collect();
    let s = scc_curve(&x, &a);
    let c = acc_curve(&x, &a);
    assert_eq!(s.len(), n_lines);
    for k in 0..n_lines {
        assert!((s[k] - 1.0).abs() < 1e-12);
        let m = C64::new(1.0 + 0.01 * k as f64, 0.1).norm();
        assert!((c[k] - 2.0 * m / (1.0 + m * m)).abs() < 1e-12);
    }
    // FRAC per FRF equals frac of the extracted column.
    let f = frac_per_frf(&x, &a);
    assert_eq!(f.len(), 4);
    for (j, fj) in f.iter().enumerate() {
        let cx: Vec<C64> = x.iter().map(|r| r[j]).collect();
        let ca: Vec<C64> = a.iter().map(|r| r[j]).collect();
        assert_eq!(*fj, frac(&cx, &ca));
        assert!(*fj < 1.0 && *fj > 0.9);
    }
    // Same scale on every line: FRAC = 1 per FRF.
    let b: Vec<Vec<C64>> = x.iter().map(|r| scale(r, C64::new(0.3, -2.0))).collect();
    assert!(frac_per_frf(&x, &b).iter().all(|v| (v - 1.0).abs() < 1e-12));
}

#[test]
fn normalised_sensitivity_definition() {
    let h = [C64::new(1.0, 1.0), C64::new(0.0, -4.0), C64::new(2.0, 0.0)];
    let dh = [C64::new(3.0, 4.0), C64::new(0.0, 0.0), C64::new(-8.0, 0.0)];
    let s = normalised_sensitivity(&dh, &h);
    assert_eq!(s, vec![5.0 / 4.0, 0.0, 2.0]);
    let s2 = normalised_sensitivity_scaled(&dh, &h, 7e6);
    assert_eq!(s2, vec![5.0 / 4.0 * 7e6, 0.0, 2.0 * 7e6]);
    assert_eq!(
        normalised_sensitivity(&dh, &[C64::new(0.0, 0.0); 3]),
        vec![0.0; 3]
    );
}
