//! Single-mode circle fit (Ewins, Modal Testing, sec. 4.3), as used for the paper's Table 2.
//!
//! Near an isolated mode with structural (hysteretic) damping the receptance is
//!
//! H(w) = A / (w_r^2 - w^2 + j eta w_r^2) + (slowly varying residual),
//!
//! whose Nyquist plot is an exact circle: this is why the fit works on the receptance
//! (mobility and accelerance inputs are first converted, H = Y / (j w) = -H'' / w^2; for
//! viscous damping the mobility circle would be the exact one, the receptance circle is
//! then a close approximation for light damping). Steps:
//!
//! 1. Points: the lines of the band (or `points_each_side` lines either side of the
//!    largest |H| in the band).
//! 2. Circle: algebraic least squares (Kasa: minimise sum (x^2 + y^2 + D x + E y + F)^2 on
//!    centred, scaled coordinates), refined by a geometric least-squares fit
//!    (minimise sum (|z_k - c| - R)^2, Levenberg-Marquardt).
//! 3. Natural frequency: where the sweep rate d(theta)/d(w^2) of the points around the
//!    centre is largest. For the model above the angle around the centre obeys
//!    psi(s) = psi_r + 2 atan((s - s_r)/gamma), s = w^2, gamma = eta s_r, whose rate peaks at
//!    s = s_r. The maximum is bracketed by the finite-difference rates between lines,
//!    interpolated by a parabola, then refined by fitting psi(s) to all points (so a few
//!    points across a heavily damped resonance, e.g. eta = 0.2 at 22 Hz with 1 Hz lines,
//!    still locate it to a small fraction of a line).
//! 4. Loss factor from every pair of points a below and b above resonance:
//!    eta_ab = (w_b^2 - w_a^2) / (w_r^2 (tan(theta_a/2) + tan(theta_b/2))), with theta the
//!    angle between the point and the resonance point seen from the centre; the mean over
//!    pairs is the estimate, their sample standard deviation the scatter.
//! 5. Modal constant from the diameter: |A| = 2 R eta w_r^2, phase from the resonance
//!    point (the end of the diameter through the resonance).

use super::ModalError;
use crate::common::{C64, J};
use crate::data::Quantity;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::{Conj, Mat, Par};

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Tuning of [`circle_fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct CircleFitParams {
    /// Number of lines either side of the largest |H| in the band to fit; 0 (the default)
    /// uses every line of the band, so the band chooses the points. The paper's bands are
    /// about +-5 Hz at 1 Hz resolution; a band spanning the half-power points (about
    /// eta f_r wide) or more gives the best loss factor.
    pub points_each_side: usize,
    /// With `points_each_side > 0`: centre the points on the line nearest this frequency
    /// (Hz) instead of the largest |H| in the band (default None).
    pub peak_guess_hz: Option<f64>,
    /// Refine the algebraic circle by a geometric least-squares fit (default true).
    pub geometric_refinement: bool,
    /// Pairs for the loss factor use points whose angle from the resonance point is at
    /// least this (degrees; default 10): closer points make tan(theta/2) noise-dominated.
    pub min_pair_angle_deg: f64,
    /// ... and at most this (degrees; default 160): far points carry little information.
    pub max_pair_angle_deg: f64,
    /// Iteration limit of the two small Levenberg-Marquardt fits (default 100).
    pub max_iterations: usize,
}

impl Default for CircleFitParams {
    fn default() -> Self {
        CircleFitParams {
            points_each_side: 0,
            peak_guess_hz: None,
            geometric_refinement: true,
            min_pair_angle_deg: 10.0,
            max_pair_angle_deg: 160.0,
            max_iterations: 100,
        }
    }
}

/// The modal parameters of one mode from [`circle_fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct CircleFitResult {
    /// Natural frequency f_r (Hz).
    pub freq_hz: f64,
    /// Modal (structural) loss factor eta_r: the mean of the pair estimates.
    pub loss_factor: f64,
    /// Sample standard deviation of the pair estimates (their scatter, not the error of
    /// the mean); 0 with a single pair.
    pub loss_factor_std: f64,
    /// Loss factor from the fitted angle law psi(s) (step 3), an independent check.
    pub loss_factor_angle_fit: f64,
    /// Receptance modal constant A (1/kg = (m/N) (rad/s)^2) of
    /// H = A / (w_r^2 - w^2 + j eta w_r^2); for accelerance or mobility input it is the
    /// modal constant of the equivalent receptance.
    pub modal_constant: C64,
    /// Centre of the receptance circle (m/N).
    pub circle_center: C64,
    /// Radius of the receptance circle (m/N).
    pub radius: f64,
    /// Number of lines fitted.
    pub n_points: usize,
    /// Number of point pairs averaged for the loss factor.
    pub n_pairs: usize,
    /// RMS distance of the points from the fitted circle, relative to the radius.
    pub rms_residual: f64,
}

impl CircleFitResult {
    /// The complex eigenvalue lambda_X = w_r^2 (1 + j eta_r) (rad^2/s^2) the IEM uses
    /// (method.md, eq. 20).
    pub fn eigenvalue(&self) -> C64 {
        let w = TWO_PI * self.freq_hz;
        C64::new(w * w, w * w * self.loss_factor)
    }
}

/// Circle-fit modal analysis of one FRF around one resonance (the paper's Table 2; see the
/// module documentation for the method). `freq_hz` and `h` are the lines and values
/// (SI units of `quantity`); only lines with `band_hz.0 <= f <= band_hz.1` and f > 0 are used.
pub fn circle_fit(
    freq_hz: &[f64],
    h: &[C64],
    quantity: Quantity,
    band_hz: (f64, f64),
    params: &CircleFitParams,
) -> Result<CircleFitResult, ModalError> {
    const NEEDED: usize = 5;
    if freq_hz.len() != h.len() {
        return Err(ModalError::LengthMismatch {
            n_freq: freq_hz.len(),
            n_values: h.len(),
        });
    }
    let (lo, hi) = band_hz;
    let too_few = |n| ModalError::TooFewPoints {
        lo_hz: lo,
        hi_hz: hi,
        n_points: n,
        needed: NEEDED,
    };
    // 1. Lines of the band, as receptance.
    let mut s = Vec::new(); // w^2
    let mut z = Vec::new(); // receptance
    let mut prev_f = f64::NEG_INFINITY;
    for (&f, &v) in freq_hz.iter().zip(h) {
        if !(f >= lo && f <= hi) || f <= 0.0 {
            continue;
        }
        if !f.is_finite() || !v.re.is_finite() || !v.im.is_finite() {
            return Err(ModalError::NonFinite { freq_hz: f });
        }
        if f <= prev_f {
            return Err(ModalError::NotIncreasing { freq_hz: f });
        }
        prev_f = f;
        let w = TWO_PI * f;
        let r = match quantity {
            Quantity::Receptance => v,
            Quantity::Mobility => v / (J * w),
            Quantity::Accelerance => -v / (w * w),
        };
        s.push(w * w);
        z.push(r);
    }
    if params.points_each_side > 0 && !z.is_empty() {
        let peak = match params.peak_guess_hz {
            Some(fg) => {
                let sg = (TWO_PI * fg).powi(2);
                (0..s.len())
                    .min_by(|&a, &b| (s[a] - sg).abs().total_cmp(&(s[b] - sg).abs()))
                    .unwrap_or(0)
            }
            None => (0..z.len())
                .max_by(|&a, &b| z[a].norm().total_cmp(&z[b].norm()))
                .unwrap_or(0),
        };
        let first = peak.saturating_sub(params.points_each_side);
        let last = (peak + params.points_each_side).min(z.len() - 1);
        s = s[first..=last].to_vec();
        z = z[first..=last].to_vec();
    }
    let n = z.len();
    if n < NEEDED {
        return Err(too_few(n));
    }
    let degenerate = |why: &str| ModalError::DegenerateCircle {
        lo_hz: lo,
        hi_hz: hi,
        why: why.to_string(),
    };

    // 2. Circle.
    let (mut center, mut radius) =
        kasa_fit(&z).ok_or_else(|| degenerate("collinear or coincident points"))?;
    if params.geometric_refinement {
        if let Some((c, r)) = geometric_fit(&z, center, radius, params.max_iterations) {
            center = c;
            radius = r;
        }
    }
    if !(radius.is_finite() && radius > 0.0) {
        return Err(degenerate("zero or infinite radius"));
    }
    let rms_residual = (z
        .iter()
        .map(|p| ((p - center).norm() - radius).powi(2))
        .sum::<f64>()
        / n as f64)
        .sqrt()
        / radius;

    // 3. Angles around the centre, unwrapped, oriented to increase with frequency.
    let mut phi: Vec<f64> = Vec::with_capacity(n);
    for p in &z {
        let a = (p - center).arg();
        let a = match phi.last() {
            None => a,
            Some(&prev) => prev + wrap_pi(a - prev),
        };
        phi.push(a);
    }
    // sigma = +1: clockwise with increasing frequency (e^{j w t}, positive modal constant sense).
    let sigma = if phi[n - 1] - phi[0] <= 0.0 {
        1.0
    } else {
        -1.0
    };
    let psi: Vec<f64> = phi.iter().map(|a| -sigma * a).collect();

    // Finite-difference sweep rates between lines, at mid-points in s.
    let rates: Vec<(f64, f64)> = (0..n - 1)
        .map(|k| {
            (
                0.5 * (s[k] + s[k + 1]),
                (psi[k + 1] - psi[k]) / (s[k + 1] - s[k]),
            )
        })
        .collect();
    let kmax = (0..rates.len())
        .max_by(|&a, &b| rates[a].1.total_cmp(&rates[b].1))
        .unwrap_or(0);
    let (mut s_r, rate_max) = if kmax > 0 && kmax + 1 < rates.len() {
        parabola_vertex(rates[kmax - 1], rates[kmax], rates[kmax + 1]).unwrap_or(rates[kmax])
    } else {
        rates[kmax]
    };
    if rate_max.is_nan() || rate_max <= 0.0 {
        return Err(degenerate("the points do not sweep around the centre"));
    }
    s_r = s_r.clamp(s[0], s[n - 1]);
    let mut gamma = 2.0 / rate_max;
    let mut psi_r = interp(&s, &psi, s_r);
    if let Some((p, sr, g)) = angle_law_fit(&s, &psi, psi_r, s_r, gamma, params.max_iterations) {
        if sr > s[0] && sr < s[n - 1] {
            psi_r = p;
            s_r = sr;
            gamma = g;
        }
    }
    let freq = s_r.sqrt() / TWO_PI;

    // 4. Loss factor from pairs either side of the resonance.
    let (amin, amax) = (
        params.min_pair_angle_deg.to_radians(),
        params.max_pair_angle_deg.to_radians(),
    );
    let below: Vec<(f64, f64)> = (0..n)
        .filter(|&k| s[k] < s_r)
        .map(|k| (s[k], psi_r - psi[k]))
        .filter(|x| x.1 > 0.0 && x.1 < std::f64::consts::PI)
        .collect();
    let above: Vec<(f64, f64)> = (0..n)
        .filter(|&k| s[k] > s_r)
        .map(|k| (s[k], psi[k] - psi_r))
        .filter(|x| x.1 > 0.0 && x.1 < std::f64::consts::PI)
        .collect();
    let pair_eta = |filter: bool| -> Vec<f64> {
        let ok = |t: f64| !filter || (t >= amin && t <= amax);
        let mut v = Vec::new();
        for &(sa, ta) in below.iter().filter(|x| ok(x.1)) {
            for &(sb, tb) in above.iter().filter(|x| ok(x.1)) {
                v.push((sb - sa) / (s_r * ((0.5 * ta).tan() + (0.5 * tb).tan())));
            }
        }
        v
    };
    let mut etas = pair_eta(true);
    if etas.is_empty() {
        etas = pair_eta(false);
    }
    if etas.is_empty() {
        return Err(ModalError::OneSided {
            freq_hz: freq,
            lo_hz: lo,
            hi_hz: hi,
        });
    }
    let m = etas.len() as f64;
    let eta = etas.iter().sum::<f64>() / m;
    let eta_std = if etas.len() > 1 {
        (etas.iter().map(|e| (e - eta).powi(2)).sum::<f64>() / (m - 1.0)).sqrt()
    } else {
        0.0
    };

    // 5. Modal constant: A = sigma j gamma 2R e^{j phi_r}, phi_r the resonance point's angle.
    let phi_r = -sigma * psi_r;
    let modal_constant = sigma * J * (eta * s_r) * 2.0 * radius * C64::from_polar(1.0, phi_r);

    Ok(CircleFitResult {
        freq_hz: freq,
        loss_factor: eta,
        loss_factor_std: eta_std,
        loss_factor_angle_fit: gamma / s_r,
        modal_constant,
        circle_center: center,
        radius,
        n_points: n,
        n_pairs: etas.len(),
        rms_residual,
    })
}

/// Angle wrapped to (-pi, pi].
fn wrap_pi(a: f64) -> f64 {
    let t = a.rem_euclid(TWO_PI);
    if t > std::f64::consts::PI {
        t - TWO_PI
    } else {
        t
    }
}

/// Linear interpolation of y(x) at x0 (x increasing), clamped to the ends.
fn interp(x: &[f64], y: &[f64], x0: f64) -> f64 {
    let k = x.partition_point(|&v| v < x0).clamp(1, x.len() - 1);
    let t = (x0 - x[k - 1]) / (x[k] - x[k - 1]);
    y[k - 1] + t * (y[k] - y[k - 1])
}

/// Vertex (x, y) of the parabola through three points with distinct x; None if it opens upward.
fn parabola_vertex(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> Option<(f64, f64)> {
    // Divided differences: p(x) = y_a + d1 (x - x_a) + d2 (x - x_a)(x - x_b).
    let d_ab = (b.1 - a.1) / (b.0 - a.0);
    let d_bc = (c.1 - b.1) / (c.0 - b.0);
    let d2 = (d_bc - d_ab) / (c.0 - a.0);
    if d2.is_nan() || d2 >= 0.0 {
        return None;
    }
    let xv = 0.5 * (a.0 + b.0 - d_ab / d2);
    if !(xv >= a.0 && xv <= c.0) {
        return None;
    }
    let yv = a.1 + d_ab * (xv - a.0) + d2 * (xv - a.0) * (xv - b.0);
    Some((xv, yv))
}

/// Solve the 3x3 system m x = b by faer's LU with partial pivoting (sequential); None when a
/// pivot is below 1e-12 of the largest entry of `m` (numerically singular: collinear points
/// have no circle) or the solution is not finite.
fn solve3(m: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let largest = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    let mut lu = Mat::from_fn(3, 3, |i, j| m[i][j]);
    let (mut fwd, mut bwd) = ([0usize; 3], [0usize; 3]);
    factor::lu_in_place(
        lu.as_mut(),
        &mut fwd,
        &mut bwd,
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(
            factor::lu_in_place_scratch::<usize, f64>(3, 3, Par::Seq, Default::default()),
        )),
        Default::default(),
    );
    if !(0..3).all(|i| lu[(i, i)].abs() > 1e-12 * largest) {
        return None;
    }
    let mut x = Mat::from_fn(3, 1, |i, _| b[i]);
    solve::solve_in_place_with_conj(
        lu.as_ref(),
        lu.as_ref(),
        faer::perm::PermRef::new_checked(&fwd, &bwd, 3),
        Conj::No,
        x.as_mut(),
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(solve::solve_in_place_scratch::<
            usize,
            f64,
        >(3, 1, Par::Seq))),
    );
    let x = [x[(0, 0)], x[(1, 0)], x[(2, 0)]];
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Kasa's algebraic circle fit on centred, scaled coordinates: (centre, radius).
fn kasa_fit(z: &[C64]) -> Option<(C64, f64)> {
    let n = z.len() as f64;
    let mean = z.iter().sum::<C64>() / n;
    let scale = (z.iter().map(|p| (p - mean).norm_sqr()).sum::<f64>() / n).sqrt();
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    // Minimise sum (u^2 + v^2 + D u + E v + F)^2: normal equations in (D, E, F).
    let mut m = [[0.0; 3]; 3];
    let mut b = [0.0; 3];
    for p in z {
        let q = (p - mean) / scale;
        let row = [q.re, q.im, 1.0];
        let rhs = -(q.re * q.re + q.im * q.im);
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += row[i] * row[j];
            }
            b[i] += row[i] * rhs;
        }
    }
    let [d, e, f] = solve3(m, b)?;
    let r2 = 0.25 * (d * d + e * e) - f;
    if r2.is_nan() || r2 <= 0.0 {
        return None;
    }
    Some((
        mean + scale * C64::new(-0.5 * d, -0.5 * e),
        scale * r2.sqrt(),
    ))
}

/// Levenberg-Marquardt ([`crate::inference::lm`]) on three parameters from `p0`:
/// `normal(p)` gives the Gauss-Newton normal equations (J^T J and -J^T r, the undamped step's
/// right-hand side) or None where the model breaks down (the fit then fails); `cost_of` the
/// sum of squares; a trial point that is not `feasible` counts as no decrease. Stops when the
/// Newton decrement is below 1e-15 of the cost, when no damped step decreases it, or after
/// `max_iter` iterations.
fn levenberg_marquardt3(
    p0: [f64; 3],
    cost_of: impl Fn([f64; 3]) -> f64,
    normal: impl Fn([f64; 3]) -> Option<([[f64; 3]; 3], [f64; 3])>,
    feasible: impl Fn([f64; 3]) -> bool,
    max_iter: usize,
) -> Option<[f64; 3]> {
    use crate::inference::lm::{levenberg_marquardt, LmParams, LmStop, Quadratic};
    let at = |x: &[f64]| [x[0], x[1], x[2]];
    // f = |r|^2: gradient 2 J^T r, Gauss-Newton curvature 2 J^T J.
    let quadratic = |x: &[f64]| -> Result<Quadratic, &str> {
        let p = at(x);
        let (jtj, minus_jtr) = normal(p).ok_or("the model breaks down")?;
        Ok((
            cost_of(p),
            minus_jtr.iter().map(|v| -2.0 * v).collect(),
            (0..9).map(|k| 2.0 * jtj[k / 3][k % 3]).collect(),
        ))
    };
    let value = |x: &[f64]| {
        let p = at(x);
        if feasible(p) {
            cost_of(p)
        } else {
            f64::INFINITY
        }
    };
    let out = levenberg_marquardt(
        &p0,
        quadratic,
        value,
        &LmParams {
            max_iters: max_iter as u64,
            tol: f64::MIN_POSITIVE,
            rel_tol: 1e-15,
            give_up_above: f64::INFINITY,
        },
    );
    match out.stop {
        LmStop::Failed(_) => None,
        _ => Some(at(&out.x)),
    }
}

/// Geometric circle fit: minimise sum (|z_k - c| - R)^2 by Levenberg-Marquardt from (c0, r0).
fn geometric_fit(z: &[C64], c0: C64, r0: f64, max_iter: usize) -> Option<(C64, f64)> {
    // p = (Re c, Im c, R)
    let cost_of = |p: [f64; 3]| {
        let c = C64::new(p[0], p[1]);
        z.iter()
            .map(|q| ((q - c).norm() - p[2]).powi(2))
            .sum::<f64>()
    };
    let normal = |p: [f64; 3]| {
        let c = C64::new(p[0], p[1]);
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for q in z {
            let d = q - c;
            let dist = d.norm();
            if dist == 0.0 {
                return None;
            }
            let res = dist - p[2];
            let g = [-d.re / dist, -d.im / dist, -1.0];
            for i in 0..3 {
                for j in 0..3 {
                    jtj[i][j] += g[i] * g[j];
                }
                jtr[i] -= g[i] * res;
            }
        }
        Some((jtj, jtr))
    };
    let p = levenberg_marquardt3(
        [c0.re, c0.im, r0],
        cost_of,
        normal,
        |p| p[2] > 0.0,
        max_iter,
    )?;
    Some((C64::new(p[0], p[1]), p[2]))
}

/// Fit psi_k = psi_r + 2 atan((s_k - s_r)/gamma) by Levenberg-Marquardt (s scaled by s_r0).
/// Returns (psi_r, s_r, gamma).
fn angle_law_fit(
    s: &[f64],
    psi: &[f64],
    psi_r0: f64,
    s_r0: f64,
    gamma0: f64,
    max_iter: usize,
) -> Option<(f64, f64, f64)> {
    let s0 = s_r0;
    let x: Vec<f64> = s.iter().map(|v| v / s0).collect();
    let cost_of = |p: [f64; 3]| {
        x.iter()
            .zip(psi)
            .map(|(&xk, &yk)| (yk - p[0] - 2.0 * ((xk - p[1]) / p[2]).atan()).powi(2))
            .sum::<f64>()
    };
    let normal = |p: [f64; 3]| {
        let mut jtj = [[0.0; 3]; 3];
        let mut jtr = [0.0; 3];
        for (&xk, &yk) in x.iter().zip(psi) {
            let u = (xk - p[1]) / p[2];
            let res = yk - p[0] - 2.0 * u.atan();
            let da = 2.0 / (1.0 + u * u);
            // d(model)/d(psi_r, x_r, g)
            let g = [1.0, -da / p[2], -da * u / p[2]];
            for i in 0..3 {
                for j in 0..3 {
                    jtj[i][j] += g[i] * g[j];
                }
                jtr[i] += g[i] * res;
            }
        }
        Some((jtj, jtr))
    };
    let p0 = [psi_r0, 1.0, gamma0 / s0];
    if !(p0[2] > 0.0 && p0[2].is_finite()) {
        return None;
    }
    let p = levenberg_marquardt3(p0, cost_of, normal, |p| p[1] > 0.0 && p[2] > 0.0, max_iter)?;
    Some((p[0], p[1] * s0, p[2] * s0))
}
