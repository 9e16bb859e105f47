//! The level-to-level change of E' and E'' of one model: at the first two bending modes of the
//! joint (from the lower level's MAP: the modal frequency `f_r` solves
//! `(2 pi f_r)^2 = Re lambda_r(E*(2 pi f_r))`, a fixed point on the ROM's complex modes) and at
//! chosen frequencies, `Delta E' = E'_high(f) - E'_low(f)` over pairs of posterior draws of the
//! two levels (independent posteriors: draw `i` of one with draw `i` of the other is a draw of
//! the pair), with its 50 % and 95 % intervals and `P(E'_high < E'_low)`, the probability
//! that the adhesive is softer at the higher level. Checked by the unit tests below (the
//! change of two independent normals, numpy's quantiles).

use crate::bayes::PosteriorResult;
use crate::common::quantile_sorted;
use crate::frf::FrfEngine;
use crate::material::ConstitutiveModel;
use crate::stage::LevelData;
use std::f64::consts::TAU;

/// Quantiles of a sample (linear interpolation between order statistics, numpy's default).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Quantiles {
    pub q2_5: f64,
    pub q25: f64,
    pub median: f64,
    pub q75: f64,
    pub q97_5: f64,
}

impl Quantiles {
    pub fn of(v: &[f64]) -> Quantiles {
        let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        s.sort_by(f64::total_cmp);
        Quantiles {
            q2_5: quantile_sorted(&s, 0.025),
            q25: quantile_sorted(&s, 0.25),
            median: quantile_sorted(&s, 0.5),
            q75: quantile_sorted(&s, 0.75),
            q97_5: quantile_sorted(&s, 0.975),
        }
    }
    /// Whether `v` lies in the 95 % interval.
    pub fn contains95(&self, v: f64) -> bool {
        v >= self.q2_5 && v <= self.q97_5
    }
}

/// The change of a quantity from the lower to the higher level over paired draws.
#[derive(Clone, Debug, PartialEq)]
pub struct ChangeStats {
    pub low: Quantiles,
    pub high: Quantiles,
    /// `high - low`.
    pub change: Quantiles,
    /// `high / low - 1`.
    pub rel_change: Quantiles,
    /// `P(high < low)`.
    pub p_lower: f64,
    pub n_pairs: usize,
}

/// [`ChangeStats`] of draws `low` and `high` of two independent posteriors (paired by index,
/// over the shorter length).
pub fn change_stats(low: &[f64], high: &[f64]) -> ChangeStats {
    let n = low.len().min(high.len());
    let d: Vec<f64> = (0..n).map(|i| high[i] - low[i]).collect();
    let r: Vec<f64> = (0..n).map(|i| high[i] / low[i] - 1.0).collect();
    ChangeStats {
        low: Quantiles::of(&low[..n]),
        high: Quantiles::of(&high[..n]),
        change: Quantiles::of(&d),
        rel_change: Quantiles::of(&r),
        p_lower: d.iter().filter(|x| **x < 0.0).count() as f64 / n.max(1) as f64,
        n_pairs: n,
    }
}

/// One row of the level change.
#[derive(Clone, Debug)]
pub struct ChangeRow {
    pub model: String,
    /// "storage" (E') or "loss" (E'').
    pub quantity: &'static str,
    /// "mode 1", "mode 2" or "chosen".
    pub point: String,
    pub freq_hz: f64,
    pub stats: ChangeStats,
    /// The truth's values at both levels (simulated data whose sidecar gives them), Pa.
    pub truth_low: f64,
    pub truth_high: f64,
}

/// The lowest `n` bending modes (vertical: y energy fraction >= 0.5 where the engine says)
/// with frequency in `band_hz`, for the law `law` at `p`.
pub fn modal_frequencies(
    engine: &dyn FrfEngine,
    law: &dyn ConstitutiveModel,
    p: &[f64],
    band_hz: (f64, f64),
    n: usize,
) -> Vec<f64> {
    let n_modes = 8;
    let Some(Ok(first)) = engine.complex_modes(law.modulus(p, TAU * 20.0), n_modes) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (r, m0) in first.iter().enumerate() {
        let vertical = m0.energy_fraction_xyz.is_none_or(|e| e[1] >= 0.5);
        if !vertical {
            continue;
        }
        let mut f = m0.lambda.re.max(0.0).sqrt() / TAU;
        for _ in 0..30 {
            let Some(Ok(m)) = engine.complex_modes(law.modulus(p, TAU * f.max(1e-3)), n_modes)
            else {
                break;
            };
            let Some(mr) = m.get(r) else { break };
            let fnew = mr.lambda.re.max(0.0).sqrt() / TAU;
            let done = (fnew - f).abs() <= 1e-9 * f.max(1e-9);
            f = fnew;
            if done {
                break;
            }
        }
        if f >= band_hz.0 && f <= band_hz.1 {
            out.push(f);
        }
        if out.len() == n {
            break;
        }
    }
    out
}

/// E*(f) columns over the draws of a posterior (every `step`-th draw).
fn moduli(law: &dyn ConstitutiveModel, p: &PosteriorResult, f_hz: f64) -> (Vec<f64>, Vec<f64>) {
    let Some(s) = p.figure_sampler() else {
        return (Vec::new(), Vec::new());
    };
    let nl = law.n_params();
    let n = s.draws.chain.len();
    let mut st = Vec::with_capacity(n);
    let mut lo = Vec::with_capacity(n);
    for r in 0..n {
        let par: Vec<f64> = (0..nl).map(|k| s.draws.values[k][r]).collect();
        let e = law.modulus(&par, TAU * f_hz);
        st.push(e.re);
        lo.push(e.im);
    }
    (st, lo)
}

/// The change rows of `law` between the posteriors `pl` at `low` and `ph` at `high` (E' and E''
/// at each named frequency of `points`), with the levels' truths where the data give them.
pub fn change_rows(
    law: &dyn ConstitutiveModel,
    (low, pl): (&LevelData, &PosteriorResult),
    (high, ph): (&LevelData, &PosteriorResult),
    points: &[(String, f64)],
) -> Vec<ChangeRow> {
    let mut out = Vec::new();
    for (point, f) in points {
        let f = *f;
        let (sl, ll) = moduli(law, pl, f);
        let (sh, lh) = moduli(law, ph, f);
        let truth = |l: &LevelData| l.truth.as_ref().map(|t| t.modulus(TAU * f));
        let (tl, th) = (truth(low), truth(high));
        for (quantity, a, b, ta, tb) in [
            ("storage", &sl, &sh, tl.map(|z| z.re), th.map(|z| z.re)),
            ("loss", &ll, &lh, tl.map(|z| z.im), th.map(|z| z.im)),
        ] {
            if a.is_empty() || b.is_empty() {
                continue;
            }
            out.push(ChangeRow {
                model: pl.model.clone(),
                quantity,
                point: point.clone(),
                freq_hz: f,
                stats: change_stats(a, b),
                truth_low: ta.unwrap_or(f64::NAN),
                truth_high: tb.unwrap_or(f64::NAN),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn change_of_two_independent_normals() {
        // low ~ N(10, 1), high ~ N(8, 0.5): change ~ N(-2, sqrt(1.25)); 95 % interval
        // -2 -+ 1.96 sqrt(1.25); P(high < low) = Phi(2 / sqrt(1.25)) = 0.96319.
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let n = 40000;
        let a: Vec<f64> = (0..n)
            .map(|_| Normal::new(10.0, 1.0).unwrap().sample(&mut rng))
            .collect();
        let b: Vec<f64> = (0..n)
            .map(|_| Normal::new(8.0, 0.5).unwrap().sample(&mut rng))
            .collect();
        let c = change_stats(&a, &b);
        let s = 1.25f64.sqrt();
        assert!((c.change.median + 2.0).abs() < 0.03, "{:?}", c.change);
        assert!(
            (c.change.q2_5 - (-2.0 - 1.959964 * s)).abs() < 0.05,
            "{:?}",
            c.change
        );
        assert!(
            (c.change.q97_5 - (-2.0 + 1.959964 * s)).abs() < 0.05,
            "{:?}",
            c.change
        );
        assert!((c.change.q25 - (-2.0 - 0.674490 * s)).abs() < 0.03);
        assert!((c.p_lower - 0.96319).abs() < 0.005, "{}", c.p_lower);
        assert!(c.change.contains95(-2.0) && !c.change.contains95(0.5));
        assert_eq!(c.n_pairs, n);
    }

    #[test]
    fn quantiles_interpolate_like_numpy() {
        // numpy.quantile([1, 2, 3, 4], [0.025, 0.25, 0.5, 0.75, 0.975]) =
        // [1.075, 1.75, 2.5, 3.25, 3.925]
        let q = Quantiles::of(&[4.0, 1.0, 3.0, 2.0]);
        for (a, b) in [
            (q.q2_5, 1.075),
            (q.q25, 1.75),
            (q.median, 2.5),
            (q.q75, 3.25),
            (q.q97_5, 3.925),
        ] {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }
}
