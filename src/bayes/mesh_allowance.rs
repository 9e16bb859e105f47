//! The mesh's remaining discretisation error in the posterior (docs/method.md, "The mesh's
//! discretisation error").
//!
//! With the allowance the model's adhesive and adherend stiffnesses are already corrected by the
//! estimated excesses ([`crate::discretisation`]: S / (1 + c delta), K_b / (1 + c delta_b), c
//! the estimate's calibration [`ESTIMATE_SHARE_CENTRE`]). Two uncertainties are left, and both are marginalised here:
//!
//! 1. **The correction's size.** c has an sd of [`ESTIMATE_SHARE_SD`], so the adhesive's
//!    stiffness is uncertain by a factor (1 + u), u ~ N(0, (sd delta)^2). K_b + E*(w) S depends
//!    on E* and S through their product only, so u is exactly a factor on every parameter that
//!    scales E*(w) (moduli in Pa, viscosities in Pa s): each draw's scale parameters are
//!    multiplied by one draw of (1 + u), and the Laplace covariance gains u's variance times
//!    theta_i theta_j.
//! 2. **What the corrections leave of each mode.** Mode k's relative error eps_k = e_k / f_k
//!    is r_k = eps_k - (phi_k delta + (1 - phi_k) delta_b) / 2 away from the corrections of the
//!    adhesive (delta) and the adherends (delta_b), eps_k itself is uncertain by [`MODE_SD`] of
//!    itself, and the adherends' correction by its own sd (not a factor on the law, so it stays
//!    with the mode). A mode-wise error moves the law's parameters: their
//!    offset b satisfies G b = -eps, G_kj = d ln f_k / d theta_j = (phi_k / 2) d ln E'(w_k) /
//!    d theta_j over the in-band modes the points see, as far as the data pin the frequencies:
//!    the fit trades the frequency mismatch (mode k's costing 1 / (g_k^T Sigma g_k), the
//!    posterior's own precision of ln f_k, R its diagonal) against the rest of the FRFs (the
//!    posterior's precision Sigma^-1), b = -A eps, A = Sigma G^T (G Sigma G^T + R)^-1, Sigma the
//!    law's Laplace covariance. (Exact matching, R = 0, overstates the offset where the law can
//!    hardly move two modes apart: a 17 % interval on the paper block's eta1.) With
//!    eps ~ N(0, diag((c r_k)^2 + (MODE_SD eps_k)^2)), each draw gets A eps and the Laplace
//!    covariance gains A Cov(eps) A^T. This is what lets a viscosity, set by
//!    the dispersion between modes, carry a mesh error that differs from mode to mode.
//!
//! The effects and the noise scales are unchanged.

use super::PosteriorResult;
use crate::discretisation::{Discretisation, ESTIMATE_SHARE_CENTRE, ESTIMATE_SHARE_SD};
use crate::material::ConstitutiveModel;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// Whether a law parameter of `unit` scales E*(w) (module doc).
pub fn scales_modulus(unit: &str) -> bool {
    matches!(unit, "Pa" | "Pa s")
}

/// Sd of each mode's own error, relative to its estimate (module doc).
pub const MODE_SD: f64 = 0.2;
/// R's scale (module doc): a frequency mismatch of mode k costs 1 / (MATCH_RIDGE g_k^T Sigma
/// g_k).
pub const MATCH_RIDGE: f64 = 0.1;
/// Least share of a mode's kinetic energy along the measured axes for it to count.
pub const MIN_MEASURED_SHARE: f64 = 0.3;

/// The linear map A (law parameters x modes, physical units) and the modes' errors eps.
struct Map {
    a: Vec<Vec<f64>>,
    /// Per mode: the sd of its error after the common correction.
    sd: Vec<f64>,
}

/// A for one posterior (module doc), None when no measured in-band mode has an error.
fn map_of(
    post: &PosteriorResult,
    law: &dyn ConstitutiveModel,
    d: &Discretisation,
    band_max_hz: f64,
) -> Option<Map> {
    let nl = law.n_params();
    let lap = &post.map.laplace;
    let dim = lap.dim();
    if nl == 0 || nl > dim || !lap.positive_definite {
        return None;
    }
    let theta = &lap.physical[..nl];
    let e_ref = d.reference_modulus_pa;
    let mut g: Vec<Vec<f64>> = Vec::new();
    let mut sd = Vec::new();
    let mut jac = vec![crate::common::C64::new(0.0, 0.0); nl];
    for m in &d.modes {
        if m.measured_share < MIN_MEASURED_SHARE || m.rel_error == 0.0 {
            continue;
        }
        // the mode's frequency at the identified law: f^2 scales as (1 - phi) + phi E' / E_ref
        let mut f = m.freq_hz;
        for _ in 0..4 {
            let e = law.modulus(theta, std::f64::consts::TAU * f).re;
            f = m.freq_hz
                * ((1.0 - m.adhesive_share) + m.adhesive_share * e / e_ref)
                    .max(1e-6)
                    .sqrt();
        }
        if f > band_max_hz * 1.05 {
            continue;
        }
        let w = std::f64::consts::TAU * f;
        let e = law.modulus(theta, w).re;
        if !(e > 0.0) {
            continue;
        }
        law.jacobian(theta, w, &mut jac);
        g.push(
            jac.iter()
                .map(|j| 0.5 * m.adhesive_share * j.re / e)
                .collect(),
        );
        let left = m.rel_error - d.explained(m);
        // the adherends' correction is not a factor on the law: its uncertainty stays with the
        // mode
        let adherend = 0.5 * (1.0 - m.adhesive_share) * ESTIMATE_SHARE_SD * d.adherend_excess;
        sd.push(
            (ESTIMATE_SHARE_CENTRE * left)
                .hypot(MODE_SD * m.rel_error)
                .hypot(adherend),
        );
    }
    let k = g.len();
    if k == 0 {
        return None;
    }
    // Sigma G^T (nl x k) and G Sigma G^T (k x k), Sigma the law's block of the Laplace covariance
    let sigma = |i: usize, j: usize| lap.cov_physical[i * dim + j];
    let sg: Vec<Vec<f64>> = (0..nl)
        .map(|i| {
            (0..k)
                .map(|r| (0..nl).map(|j| sigma(i, j) * g[r][j]).sum())
                .collect()
        })
        .collect();
    let mut gsg: Vec<f64> = (0..k)
        .flat_map(|r| (0..k).map(move |s| (r, s)))
        .map(|(r, s)| (0..nl).map(|i| g[r][i] * sg[i][s]).sum())
        .collect();
    // the frequencies are matched as well as the data know them, not exactly (module doc): a
    // mismatch of mode k costs 1 / (g_k^T Sigma g_k), the posterior's own precision of ln f_k
    for r in 0..k {
        let v = gsg[r * k + r];
        if !(v > 0.0 && v.is_finite()) {
            return None;
        }
        gsg[r * k + r] += MATCH_RIDGE * v;
    }
    // A = Sigma G^T (G Sigma G^T + R)^-1, the matrix symmetric positive definite: row i of A
    // solves (G Sigma G^T + R) x = row i of Sigma G^T
    let l = crate::linalg::dense::cholesky(&gsg, k)?;
    let a: Vec<Vec<f64>> = sg
        .iter()
        .map(|row| crate::linalg::dense::chol_solve(&l, k, row))
        .collect();
    Some(Map { a, sd })
}

/// Widen every posterior's law parameters by the mesh's remaining error (module doc). `laws`
/// gives each model's law by name; `band_max_hz` is the highest analysed line. Draws get their
/// offsets from a generator seeded by `seed`, the level, the model and the sampler, so results
/// do not depend on the thread count.
pub fn apply(
    posteriors: &mut [PosteriorResult],
    d: &Discretisation,
    laws: &[(&str, &dyn ConstitutiveModel)],
    band_max_hz: f64,
    seed: u64,
) {
    if !d.allowance {
        return;
    }
    let su = ESTIMATE_SHARE_SD * d.stiffness_excess.abs();
    for post in posteriors {
        let Some(&(_, law)) = laws.iter().find(|(n, _)| *n == post.model) else {
            continue;
        };
        let nl = law.n_params();
        let units = law.param_units();
        let scale: Vec<bool> = units.iter().map(|u| scales_modulus(u)).collect();
        let map = map_of(post, law, d, band_max_hz);
        let lap = &mut post.map.laplace;
        let dim = lap.dim();
        if nl > dim {
            continue;
        }
        // the covariance the two uncertainties add (physical units, the law's block)
        let mut add = vec![vec![0.0; nl]; nl];
        for i in 0..nl {
            for j in 0..nl {
                if scale[i] && scale[j] {
                    add[i][j] += su * su * lap.physical[i] * lap.physical[j];
                }
                if let Some(m) = &map {
                    add[i][j] += (0..m.sd.len())
                        .map(|r| m.a[i][r] * m.a[j][r] * m.sd[r] * m.sd[r])
                        .sum::<f64>();
                }
            }
        }
        for i in 0..nl {
            for j in 0..nl {
                lap.cov_physical[i * dim + j] += add[i][j];
                let (gi, gj) = match (post.priors.get(i), post.priors.get(j)) {
                    (Some(pi), Some(pj)) => (pi.dp_dx(lap.x[i]), pj.dp_dx(lap.x[j])),
                    _ => continue,
                };
                if gi.abs() > 0.0 && gj.abs() > 0.0 {
                    lap.cov_x[i * dim + j] += add[i][j] / (gi * gj);
                }
            }
        }
        let key = super::posterior::level_hash(&format!("{}/{}", post.level, post.model));
        for (s_idx, s) in post.samplers.iter_mut().enumerate() {
            let mut rng = rand::rngs::StdRng::seed_from_u64(
                seed ^ key ^ 0x9e37_79b9_7f4a_7c15u64.wrapping_mul(s_idx as u64 + 1),
            );
            let rows = s.draws.values.first().map_or(0, |c| c.len());
            for r in 0..rows {
                let z: f64 = StandardNormal.sample(&mut rng);
                let f = 1.0 + su * z;
                let n: Vec<f64> = map.as_ref().map_or(Vec::new(), |m| {
                    m.sd.iter()
                        .map(|sd| {
                            let z: f64 = StandardNormal.sample(&mut rng);
                            sd * z
                        })
                        .collect()
                });
                for i in 0..nl {
                    let Some(col) = s.draws.values.get_mut(i) else {
                        continue;
                    };
                    if scale[i] {
                        col[r] *= f;
                    }
                    if let Some(m) = &map {
                        col[r] += (0..n.len()).map(|k| m.a[i][k] * n[k]).sum::<f64>();
                    }
                }
            }
        }
        let sd_rel: Vec<String> = (0..nl)
            .map(|i| {
                format!(
                    "{} {:.2} %",
                    post.names.get(i).map_or("?", |s| s.as_str()),
                    100.0 * add[i][i].max(0.0).sqrt() / post.map.laplace.physical[i].abs()
                )
            })
            .collect();
        post.notes.push(format!(
            "The law's parameters carry the mesh's remaining discretisation error (docs/method.md): the adhesive's stiffness corrected by {:.2} % of the continuum's with an sd of {:.2} %, and {} measured in-band mode(s) whose errors one correction does not explain; the sds this adds: {}.",
            100.0 * ESTIMATE_SHARE_CENTRE * d.stiffness_excess,
            100.0 * su,
            map.as_ref().map_or(0, |m| m.sd.len()),
            sd_rel.join(", ")
        ));
    }
}
