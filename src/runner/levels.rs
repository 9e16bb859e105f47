//! Across excitation levels: the level-to-level change of E' and E'' with
//! credible intervals, and whether the law's parameters differ between levels at all.
//!
//! 1. **Change**: at the first two bending modes of the joint (from the lower level's MAP: the
//!    modal frequency `f_r` solves `(2 pi f_r)^2 = Re lambda_r(E*(2 pi f_r))`, a fixed point on
//!    the ROM's complex modes) and at chosen frequencies, `Delta E' = E'_high(f) - E'_low(f)`
//!    over pairs of posterior draws of the two levels (independent posteriors: draw `i` of one
//!    with draw `i` of the other is a draw of the pair), with its 50 % and 95 % intervals and
//!    `P(E'_high < E'_low)`, the probability that the adhesive is softer at the higher level.
//! 2. **Shared or separate** (evidence): a posterior whose law parameters are shared by both
//!    levels (likelihood = product of the levels' likelihoods, noise coordinates per level,
//!    [`crate::inference::joint::JointPosterior`]) against separate parameters per level
//!    (`log Z_low + log Z_high`). Laplace always (TMCMC when asked). `log B = log Z_separate -
//!    log Z_shared > 0` favours a level-dependent (amplitude-dependent) law.

use super::bayes::PosteriorResult;
use super::posterior::build_posterior;
use super::{LevelData, LevelResults, RunError};
use crate::common::quantile_sorted;
use crate::frf::FrfEngine;
use crate::inference::joint::JointPosterior;
use crate::inference::map::{find_map, MapParams, MapResult};
use crate::inference::Posterior;
use crate::inference::Sampler;
use crate::material::ConstitutiveModel;
use crate::study::inference::Inference;
use crate::study::Study;
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

/// Shared against separate law parameters.
#[derive(Clone, Debug)]
pub struct SharedEvidence {
    pub model: String,
    /// "laplace" or "tmcmc".
    pub method: &'static str,
    pub log_z_shared: f64,
    pub se_shared: f64,
    pub log_z_separate: f64,
    pub se_separate: f64,
    /// Law parameters at the shared posterior's MAP (SI).
    pub shared_map: Vec<f64>,
    pub names: Vec<String>,
    pub seconds: f64,
}

impl SharedEvidence {
    /// `log Z_separate - log Z_shared` (> 0 favours separate parameters per level).
    pub fn log_bayes_factor(&self) -> f64 {
        self.log_z_separate - self.log_z_shared
    }
}

/// Modal frequencies used for one model.
#[derive(Clone, Debug)]
pub struct ModalPoint {
    pub model: String,
    pub freq_hz: Vec<f64>,
}

/// The comparison of two levels.
#[derive(Clone, Debug)]
pub struct LevelComparison {
    pub low: String,
    pub high: String,
    pub force_low_n: Option<f64>,
    pub force_high_n: Option<f64>,
    pub rows: Vec<ChangeRow>,
    pub evidence: Vec<SharedEvidence>,
    pub modes: Vec<ModalPoint>,
    /// Problems met (a model skipped and why).
    pub notes: Vec<String>,
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

/// The comparison of the first two `[inference]` levels (ordered by force when the study
/// gives it), or `None` with fewer than two levels.
pub fn compare(
    study: &Study,
    inf: &Inference,
    engine: &dyn FrfEngine,
    levels: &[LevelData],
    laws: &[Box<dyn ConstitutiveModel>],
    results: &[LevelResults],
) -> Result<Option<LevelComparison>, RunError> {
    let force = |name: &str| {
        study
            .measurements
            .as_ref()
            .and_then(|m| m.levels.iter().find(|l| l.name == name))
            .and_then(|l| l.force_rms_n)
    };
    let mut names: Vec<&String> = inf
        .levels
        .iter()
        .filter(|n| {
            results
                .iter()
                .any(|r| &r.level == *n && !r.posteriors.is_empty())
        })
        .collect();
    if names.len() < 2 {
        return Ok(None);
    }
    names.sort_by(|a, b| {
        force(a)
            .unwrap_or(f64::NAN)
            .total_cmp(&force(b).unwrap_or(f64::NAN))
    });
    let (ln, hn) = (names[0].clone(), names[1].clone());
    let (Some(low), Some(high)) = (
        levels.iter().find(|l| l.name == ln),
        levels.iter().find(|l| l.name == hn),
    ) else {
        return Ok(None);
    };
    let rl = results
        .iter()
        .find(|r| r.level == ln)
        .map(|r| &r.posteriors);
    let rh = results
        .iter()
        .find(|r| r.level == hn)
        .map(|r| &r.posteriors);
    let (Some(rl), Some(rh)) = (rl, rh) else {
        return Ok(None);
    };
    let settings = &inf.level_change;
    let band = (
        low.freq_hz.first().copied().unwrap_or(0.0),
        low.freq_hz.last().copied().unwrap_or(f64::INFINITY),
    );
    let mut out = LevelComparison {
        low: ln.clone(),
        high: hn.clone(),
        force_low_n: force(&ln),
        force_high_n: force(&hn),
        rows: Vec::new(),
        evidence: Vec::new(),
        modes: Vec::new(),
        notes: Vec::new(),
    };
    for (mi, pl) in rl.iter().enumerate() {
        let Some(ph) = rh.iter().find(|p| p.model == pl.model) else {
            continue;
        };
        let Some((_, law)) = study
            .models
            .iter()
            .zip(laws)
            .find(|(m, _)| m.name.eq_ignore_ascii_case(&pl.model))
        else {
            continue;
        };
        let law = law.as_ref();
        let nl = law.n_params();
        let modes = modal_frequencies(engine, law, &pl.map.map_physical[..nl], band, 2);
        out.modes.push(ModalPoint {
            model: pl.model.clone(),
            freq_hz: modes.clone(),
        });
        let mut points: Vec<(String, f64)> = modes
            .iter()
            .enumerate()
            .map(|(r, f)| (format!("mode {}", r + 1), *f))
            .collect();
        points.extend(settings.freq_hz.iter().map(|f| ("chosen".to_string(), *f)));
        for (point, f) in points {
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
                out.rows.push(ChangeRow {
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
        if settings.shared {
            match shared_evidence(study, inf, engine, low, high, law, pl, ph, mi) {
                Ok(ev) => out.evidence.extend(ev),
                Err(e) => out.notes.push(format!(
                    "shared-parameter evidence of {} not computed: {e}",
                    pl.model
                )),
            }
        }
    }
    Ok(Some(out))
}

fn fail(model: &str, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: format!("shared-parameter posterior of {model}"),
        message: e.to_string(),
    }
}

/// Laplace (and TMCMC when asked) evidence of the law's parameters shared by `low` and `high`.
#[allow(clippy::too_many_arguments)]
fn shared_evidence(
    study: &Study,
    inf: &Inference,
    engine: &dyn FrfEngine,
    low: &LevelData,
    high: &LevelData,
    law: &dyn ConstitutiveModel,
    pl: &PosteriorResult,
    ph: &PosteriorResult,
    mi: usize,
) -> Result<Vec<SharedEvidence>, RunError> {
    let t0 = std::time::Instant::now();
    let model = pl.model.as_str();
    let nl = law.n_params();
    let mut post_a = build_posterior(study, inf, engine, low, law, model)?;
    let mut post_b = build_posterior(study, inf, engine, high, law, model)?;
    let linearised = inf.linearised_measurement
        && post_a.likelihood.forward.obs.measurement.is_some()
        && post_b.likelihood.forward.obs.measurement.is_some();
    let (da, db) = (post_a.dim(), post_b.dim());
    let map_a: Vec<usize> = (0..da).collect();
    let map_b: Vec<usize> = (0..nl)
        .chain((da..da + db - nl).collect::<Vec<_>>())
        .collect();
    let mut priors = post_a.priors.clone();
    priors.extend(post_b.priors[nl..].iter().cloned());
    let mut names: Vec<String> = post_a.names[..nl].to_vec();
    names.extend(
        post_a.names[nl..]
            .iter()
            .map(|n| format!("{n}_{}", low.name)),
    );
    names.extend(
        post_b.names[nl..]
            .iter()
            .map(|n| format!("{n}_{}", high.name)),
    );
    // Start: the two MAPs' law coordinates averaged, each level's noise coordinates.
    let mut x0: Vec<f64> = (0..nl)
        .map(|k| 0.5 * (pl.map.map_x[k] + ph.map.map_x[k]))
        .collect();
    x0.extend(pl.map.map_x[nl..].iter().copied());
    x0.extend(ph.map.map_x[nl..].iter().copied());
    let seed = study.seed ^ 0x5A4E_D000 ^ ((mi as u64 + 1) << 36);
    let params = MapParams {
        n_starts: inf.map_starts,
        max_iters: inf.map_max_iterations,
        seed,
        ..MapParams::default()
    };
    if linearised {
        let p0 = post_a.physical(&x0)[..nl].to_vec();
        post_a
            .likelihood
            .forward
            .linearise_measurement(&p0)
            .map_err(|e| fail(model, e))?;
        post_b
            .likelihood
            .forward
            .linearise_measurement(&p0)
            .map_err(|e| fail(model, e))?;
    }
    let search = |a: &crate::inference::likelihood::FrfPosterior<'_>,
                  b: &crate::inference::likelihood::FrfPosterior<'_>,
                  x: &[f64],
                  params: &MapParams|
     -> Result<MapResult, RunError> {
        let joint = JointPosterior::new(
            vec![a as &dyn Posterior, b as &dyn Posterior],
            vec![map_a.clone(), map_b.clone()],
            priors.clone(),
            names.clone(),
        )
        .map_err(|e| fail(model, e))?;
        find_map(&joint, Some(x), params, &|| ()).map_err(|e| fail(model, e))
    };
    let mut map = search(&post_a, &post_b, &x0, &params)?;
    if linearised {
        // Re-linearise at the shared MAP until it stops moving (as the per-level search does).
        for _ in 0..6 {
            let p_lin = map.map_physical[..nl].to_vec();
            post_a
                .likelihood
                .forward
                .linearise_measurement(&p_lin)
                .map_err(|e| fail(model, e))?;
            post_b
                .likelihood
                .forward
                .linearise_measurement(&p_lin)
                .map_err(|e| fail(model, e))?;
            let again = search(
                &post_a,
                &post_b,
                &map.map_x,
                &MapParams {
                    n_starts: 0,
                    ..params.clone()
                },
            )?;
            let moved = again.map_physical[..nl]
                .iter()
                .zip(&p_lin)
                .map(|(a, b)| ((a - b) / b).abs())
                .fold(0.0, f64::max);
            map = again;
            if moved < 1e-7 {
                break;
            }
        }
    }
    let mut out = vec![SharedEvidence {
        model: model.to_string(),
        method: "laplace",
        log_z_shared: map.laplace.log_evidence,
        se_shared: 0.0,
        log_z_separate: pl.map.laplace.log_evidence + ph.map.laplace.log_evidence,
        se_separate: 0.0,
        shared_map: map.map_physical[..nl].to_vec(),
        names: names[..nl].to_vec(),
        seconds: t0.elapsed().as_secs_f64(),
    }];
    if inf.level_change.tmcmc {
        let sep = |p: &PosteriorResult| {
            p.samplers
                .iter()
                .find(|s| s.sampler == Sampler::Tmcmc)
                .and_then(|s| s.log_evidence)
        };
        if let (Some((za, sa)), Some((zb, sb)), Some(particles)) =
            (sep(pl), sep(ph), inf.tmcmc_particles)
        {
            let t1 = std::time::Instant::now();
            let joint = JointPosterior::new(
                vec![&post_a as &dyn Posterior, &post_b as &dyn Posterior],
                vec![map_a.clone(), map_b.clone()],
                priors.clone(),
                names.clone(),
            )
            .map_err(|e| fail(model, e))?;
            let run = crate::inference::sample_tmcmc(
                &joint,
                &crate::inference::TmcmcParams {
                    particles,
                    seed: seed ^ 0x746d_636d_6300,
                    ..Default::default()
                },
                None,
                &crate::inference::no_progress,
            )
            .map_err(|e| fail(model, e))?;
            out.push(SharedEvidence {
                model: model.to_string(),
                method: "tmcmc",
                log_z_shared: run.log_evidence,
                se_shared: run.log_evidence_se,
                log_z_separate: za + zb,
                se_separate: (sa * sa + sb * sb).sqrt(),
                shared_map: map.map_physical[..nl].to_vec(),
                names: names[..nl].to_vec(),
                seconds: t1.elapsed().as_secs_f64(),
            });
        }
    }
    Ok(out)
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

/// The default study end to end with the comparison parts (minutes: `cargo test --release
/// --lib bayes_study_with_comparison -- --ignored --nocapture`); results in
/// `results/bayes_compare/`, timings printed.
#[cfg(test)]
mod study_run {
    #[test]
    #[ignore]
    fn bayes_study_with_comparison() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let study = crate::study::load(&root.join("studies/bayes_compare.toml")).unwrap();
        let opts = crate::pipeline::RunOptions {
            output_dir: Some(root.join("results/bayes_compare")),
            ..Default::default()
        };
        let s = crate::report::run_study(&study, &opts, &|_| ()).unwrap();
        println!("total {:.1} s, files {:?}", s.seconds, s.files);
        let m = std::fs::read_to_string(root.join("results/bayes_compare/manifest.json")).unwrap();
        println!("{m}");
    }
}
