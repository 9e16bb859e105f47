//! The RFM fixed point against an independent Gauss-Newton (the argument is
//! in the module doc of `rfmlab::rfm`).
//!
//! Noisy data (so the fixed point is not the truth) from an SLS law (paper Model 3) on a small
//! dense chain. The Gauss-Newton here is written directly on the FRF residual
//! r_il(p) = H'_A,ij(p) - H'_X,ij with its own dense inversion of Z and the analytic Jacobian
//! dr/dp = (dH'/dE*) (dE*/dp), dH'_ij/dE* = w^2 (H S H)_ij, weighted by 1/|dH'_ij/dE*|^2 at
//! the current iterate (iteratively reweighted), i.e. the FRF error in modulus units.
//! * With the analytical denominator, the RFM fixed point equals this GN solution to rounding.
//! * With the paper's measured-column denominator, the two agree to second order in the noise:
//!   their difference is small against the distance to the truth and scales like noise^2.

use crate::spring_model::{chain, N};
use faer::linalg::solvers::Solve;
use faer::Mat;
use rfmlab::common::{C64, J};
use rfmlab::material::ConstitutiveModel;
use rfmlab::rfm::{rfm_global, Denominator, DenseEngine, MeasuredColumn, RfmParams, StopReason};
use std::f64::consts::PI;

const MEASURED: [usize; 4] = [1, 3, 5, 7];
const INPUT_POINT: usize = 1; // observation point 1 = DOF 3

/// Paper Model 3 (SLS): E0 + j w eta1 E1 / (E1 + j w eta1), p = [E0, E1, eta1].
#[derive(Debug)]
struct Sls;
impl ConstitutiveModel for Sls {
    fn name(&self) -> &str {
        "model3"
    }
    fn description(&self) -> String {
        "SLS".into()
    }
    fn param_names(&self) -> Vec<String> {
        vec!["E0".into(), "E1".into(), "eta1".into()]
    }
    fn param_units(&self) -> Vec<String> {
        vec!["Pa".into(), "Pa".into(), "Pa s".into()]
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(0.0, f64::INFINITY); 3]
    }
    fn modulus(&self, p: &[f64], w: f64) -> C64 {
        let a = J * (w * p[2]);
        p[0] + a * p[1] / (p[1] + a)
    }
    fn jacobian(&self, p: &[f64], w: f64, out: &mut [C64]) {
        let a = J * (w * p[2]);
        let den = (p[1] + a) * (p[1] + a);
        out[0] = C64::new(1.0, 0.0);
        out[1] = a * a / den;
        out[2] = J * w * p[1] * p[1] / den;
    }
}

/// xorshift64* and Box-Muller: a seeded standard normal stream without extra dependencies.
struct Normal(u64);
impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn next(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}

/// Receptance matrix H = Z^-1 by dense LU (independent of the library's engine).
fn receptance(w: f64, e: C64) -> (Mat<C64>, Mat<f64>) {
    let (m, k, s) = chain();
    let z = Mat::<C64>::from_fn(N, N, |r, c| {
        C64::new(k[(r, c)] - w * w * m[(r, c)], 0.0) + e * s[(r, c)]
    });
    (z.partial_piv_lu().solve(Mat::<C64>::identity(N, N)), s)
}

/// Noisy data: H'_X = H'_true (1 + sigma (n1 + j n2) / sqrt 2), seeded.
fn data(omega: &[f64], truth: &[f64], sigma: f64, seed: u64) -> MeasuredColumn {
    let mut rng = Normal(seed);
    let dj = MEASURED[INPUT_POINT];
    let mut acc = Vec::new();
    for &w in omega {
        let (h, _) = receptance(w, Sls.modulus(truth, w));
        for &di in &MEASURED {
            let noise = C64::new(rng.next(), rng.next()) * (sigma / 2f64.sqrt());
            acc.push(-w * w * h[(di, dj)] * (1.0 + noise));
        }
    }
    MeasuredColumn {
        omega_rad_s: omega.to_vec(),
        input: INPUT_POINT,
        outputs: (0..MEASURED.len()).collect(),
        accelerance: acc,
    }
}

/// Independent IRLS Gauss-Newton on rho_il = r_il / |g_il|, g_il = dH'_A,ij/dE*.
/// Returns (parameters, norm of the weighted gradient relative to its scale, iterations).
fn gauss_newton(d: &MeasuredColumn, p0: &[f64]) -> (Vec<f64>, f64, usize) {
    let dj = MEASURED[INPUT_POINT];
    let n_p = p0.len();
    let mut p = p0.to_vec();
    let mut jac = vec![C64::new(0.0, 0.0); n_p];
    for it in 1..=100 {
        // Normal equations in scaled parameters dq = dp / p: A^T A dq = -A^T rho.
        let mut ata = Mat::<f64>::zeros(n_p, n_p);
        let mut atb = Mat::<f64>::zeros(n_p, 1);
        let mut scale = 0.0;
        for (l, &w) in d.omega_rad_s.iter().enumerate() {
            let (h, s) = receptance(w, Sls.modulus(&p, w));
            let hs = &h * Mat::<C64>::from_fn(N, N, |r, c| C64::new(s[(r, c)], 0.0));
            let hsh = &hs * &h;
            Sls.jacobian(&p, w, &mut jac);
            for (k, &di) in MEASURED.iter().enumerate() {
                let r = -w * w * h[(di, dj)] - d.accelerance[l * MEASURED.len() + k];
                let g = w * w * hsh[(di, dj)];
                let wt = 1.0 / g.norm();
                let rho = r * wt;
                let row: Vec<C64> = (0..n_p).map(|c| g * jac[c] * p[c] * wt).collect();
                for a in 0..n_p {
                    atb[(a, 0)] -= row[a].re * rho.re + row[a].im * rho.im;
                    scale += row[a].norm() * rho.norm();
                    for b in 0..n_p {
                        ata[(a, b)] += row[a].re * row[b].re + row[a].im * row[b].im;
                    }
                }
            }
        }
        let grad = (0..n_p).map(|a| atb[(a, 0)].powi(2)).sum::<f64>().sqrt() / scale;
        let dq = ata.partial_piv_lu().solve(&atb);
        let mut change: f64 = 0.0;
        for c in 0..n_p {
            p[c] *= 1.0 + dq[(c, 0)];
            change = change.max(dq[(c, 0)].abs());
        }
        if change < 1e-13 {
            return (p, grad, it);
        }
    }
    panic!("Gauss-Newton did not converge");
}

fn engine() -> DenseEngine {
    let (m, k, s) = chain();
    DenseEngine::new(
        m,
        k,
        s,
        MEASURED.iter().map(|&d| vec![(d, 1.0)]).collect(),
        (0..MEASURED.len()).collect(),
    )
    .unwrap()
}

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) / y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn rfm_fixed_point_is_the_weighted_gauss_newton_solution() {
    let truth = [4.7121e6, 5.5573e6, 6.0491e3];
    let start = [5.0e6, 4.0e6, 4.0e3];
    let omega: Vec<f64> = (0..250)
        .map(|i| 2.0 * PI * (2.0 + 2.0 * i as f64))
        .collect();
    let eng = engine();
    let tight = RfmParams {
        tol_rel_change: 1e-13,
        max_iterations: 200,
        ..RfmParams::default()
    };
    let mut gaps = Vec::new();
    for sigma in [0.02, 0.04] {
        let d = data(&omega, &truth, sigma, 20240611);
        let (p_gn, grad, it_gn) = gauss_newton(&d, &start);
        let analytical = rfm_global(
            &eng,
            &d,
            &Sls,
            &start,
            &RfmParams {
                denominator: Denominator::Analytical,
                ..tight.clone()
            },
        )
        .unwrap();
        let paper = rfm_global(&eng, &d, &Sls, &start, &tight).unwrap();
        let off_truth = max_rel(&p_gn, &truth);
        let eq_analytical = max_rel(&analytical.params, &p_gn);
        let eq_paper = max_rel(&paper.params, &p_gn);
        println!(
            "noise {sigma}: GN {p_gn:?} ({it_gn} it, rel grad {grad:.1e}); |GN - truth| {off_truth:.2e}; \
             |RFM(analytical) - GN| {eq_analytical:.2e} ({} it); |RFM(paper) - GN| {eq_paper:.2e} ({} it)",
            analytical.iterations, paper.iterations
        );
        assert_eq!(analytical.stop_reason, StopReason::Converged);
        assert_eq!(paper.stop_reason, StopReason::Converged);
        assert!(
            off_truth > 1e-3,
            "noise must move the fixed point off the truth ({off_truth:e})"
        );
        assert!(
            eq_analytical < 1e-9,
            "RFM (analytical denominator) vs GN: {eq_analytical:e}"
        );
        assert!(
            eq_paper < 0.1 * off_truth,
            "RFM (paper) vs GN: {eq_paper:e} vs {off_truth:e}"
        );
        gaps.push(eq_paper);
    }
    // Second order in the noise: doubling sigma multiplies the gap by about 4 (not 2).
    let ratio = gaps[1] / gaps[0];
    println!("gap ratio for doubled noise: {ratio:.2}");
    assert!(ratio > 2.8 && ratio < 6.0, "ratio {ratio}");
}
