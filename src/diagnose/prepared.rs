//! A study prepared for evaluating its posteriors outside a run: the structural model, the
//! measured data of every level and the likelihood's FRF engine, built exactly as a run builds
//! them (same ROM, same measurement-model grid, same declared effects), so that
//! [`Prepared::posterior`] is the density the run's samplers see. Used by the Python binding
//! (`study.posterior(model, level)`) so that external samplers (emcee, nutpie, blackjax, PyMC)
//! can sample rfmlab's likelihood.
//!
//! The posterior is over the unconstrained coordinates `x` of [`crate::inference::Posterior`]:
//! `log p(x | data) = log prior(x) + log L(theta(x)) - log Z`, where `theta(x)` is the priors'
//! transform (log, or a logit of the log for bounded priors) and the prior density includes
//! its log-Jacobian.
//!
//! With the H1 measurement model (a declared `[measurements.estimator]`), a run's samplers see
//! the measurement bias linearised at the MAP (`inference.measurement = "linearised"`, the
//! default) and, with `inference.noise.channel_correlation`, the channels' correlation
//! estimated at the MAP. [`Prepared::posterior`] reproduces both when given the point `at`
//! (physical values of every coordinate, e.g. the MAP of the run); without it the
//! measurement model is the exact kernel operator, and a channel correlation cannot be formed.

use super::params::key_error;
use crate::frf::FrfEngine;
use crate::inference::likelihood::FrfPosterior;
use crate::material::ConstitutiveModel;
use crate::stage::{LevelData, RunError};
use crate::study::Study;
use std::path::Path;

/// A study with its data and likelihood engine built (see the module documentation).
pub struct Prepared {
    study: Study,
    levels: Vec<LevelData>,
    laws: Vec<Box<dyn ConstitutiveModel>>,
    /// The likelihood's engine, with the term ROM of the declared effects that need matrices
    /// of their own (degraded bonds, base springs, adherend damping) when the study has any.
    engine: Box<dyn FrfEngine>,
    /// One line on the engine (ROM size and certificate, or the full model).
    pub engine_note: String,
}

impl Prepared {
    /// Build the model, load the data and build the engines as `rfmlab run` does, reusing
    /// certified ROMs from `rom_cache` when given (see [`crate::stage::rom_cache_dir`]).
    pub fn new(study: &Study, rom_cache: Option<&Path>) -> Result<Prepared, RunError> {
        let crate::stage::setup::Setup {
            laws,
            built,
            levels,
            engines,
            ..
        } = crate::stage::setup::setup(
            study,
            crate::stage::engine::LikelihoodInputs::of(study),
            rom_cache,
        )?;
        let mut engine_note = engines.note;
        let engine = engines.likelihood.unwrap_or(engines.engine);
        // Declared effects with matrices of their own: the term ROM over the likelihood's
        // engine, as a run builds it (cached beside the ROM).
        let declared = super::with_declared(&study.declared_effects, &[]);
        let engine: Box<dyn FrfEngine> = if declared.is_empty() {
            engine
        } else {
            let mut terms = super::TermParams::of(study);
            if let Some(dir) = rom_cache {
                terms.cache = dir.to_path_buf();
            }
            match super::terms::term_rom_for(
                &terms,
                &built,
                engine.as_ref(),
                &declared,
                super::band_of(&levels),
            )? {
                Some((rom, c)) => {
                    engine_note += &format!(
                        "; term ROM of the declared effects: n_r {}, certificate {:.2e} of the peak",
                        c.basis_size, c.max_rel_error
                    );
                    Box::new(
                        crate::rom::WithTerms::owning(engine, rom)
                            .map_err(|e| RunError::Engine(e.to_string()))?,
                    )
                }
                None => engine,
            }
        };
        Ok(Prepared {
            study: study.clone(),
            levels,
            laws,
            engine,
            engine_note,
        })
    }

    /// The study as validated.
    pub fn study(&self) -> &Study {
        &self.study
    }

    /// The measured data of every level, reduced to the band and the structure's points.
    pub fn levels(&self) -> &[LevelData] {
        &self.levels
    }

    /// The posterior of `model` at `level` (names as in the study file, case-insensitive for
    /// the model), with the measurement bias linearised and the channel correlation formed at
    /// `at` (physical values of every coordinate, in the order of the posterior's names) when
    /// given; see the module documentation.
    pub fn posterior(
        &self,
        model: &str,
        level: &str,
        at: Option<&[f64]>,
    ) -> Result<FrfPosterior<'_>, RunError> {
        let study = &self.study;
        let inf = study.inference.as_ref().ok_or_else(|| {
            key_error(
                &study.file,
                "inference",
                "no [inference] section: add one (models, levels, noise model and priors) to evaluate a posterior",
            )
        })?;
        let Some((mi, spec)) = study
            .models
            .iter()
            .enumerate()
            .find(|(_, m)| m.name.eq_ignore_ascii_case(model))
        else {
            let names: Vec<&str> = study.models.iter().map(|m| m.name.as_str()).collect();
            return Err(key_error(
                &study.file,
                "models",
                format!("no model named {model:?}; the study has {names:?}"),
            ));
        };
        let Some(lv) = self.levels.iter().find(|l| l.name == level) else {
            let names: Vec<&str> = self.levels.iter().map(|l| l.name.as_str()).collect();
            return Err(key_error(
                &study.file,
                "measurements.levels",
                format!("no level named {level:?}; the study has {names:?}"),
            ));
        };
        let engine = self.engine.as_ref();
        let mut post = super::of_study::build_posterior(
            study,
            inf,
            engine,
            lv,
            self.laws[mi].as_ref(),
            &spec.name,
        )?;
        let bad_at = |m: String| RunError::Analysis {
            analysis: format!("posterior of {model} at {level}"),
            message: m,
        };
        match at {
            Some(p) => {
                let names = crate::inference::Posterior::names(&post);
                if p.len() != names.len() {
                    return Err(bad_at(format!(
                        "`at` has {} values; the posterior's coordinates are {names:?}",
                        p.len()
                    )));
                }
                let nl = post.n_law();
                if inf.linearised_measurement && post.likelihood.forward.obs.measurement.is_some() {
                    post.likelihood
                        .forward
                        .linearise_measurement(&p[..nl])
                        .map_err(|e| bad_at(e.to_string()))?;
                }
                if let Some((kind, window)) = inf.channel_correlation {
                    let c = crate::inference::refine::correlation_at(
                        &post,
                        p,
                        kind,
                        window,
                        &lv.freq_hz,
                    )
                    .map_err(|e| bad_at(e.to_string()))?;
                    post.likelihood
                        .set_channel_correlation(Some(c))
                        .map_err(|e| bad_at(e.to_string()))?;
                }
            }
            None => {
                if inf.channel_correlation.is_some() {
                    return Err(bad_at(
                        "the study models correlated channels (inference.noise.channel_correlation), which are estimated at a point: give `at` (e.g. the MAP)".into(),
                    ));
                }
            }
        }
        Ok(post)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inference::Posterior;

    /// studies/bayes.toml with Model 4 only and `effects` (TOML) before `[measurements]`,
    /// written into `dir`.
    fn bayes_model4(dir: &Path, effects: &str) -> Study {
        let path = dir.join("s.toml");
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
        let text = std::fs::read_to_string(root.join("bayes.toml"))
            .unwrap()
            .replace("\"data/", &format!("\"{}/data/", root.display()))
            .replace(
                "models = [\"model3\", \"model4\", \"model5\"]",
                "models = [\"model4\"]",
            )
            .replace("[measurements]", &format!("{effects}[measurements]"));
        std::fs::write(&path, text).unwrap();
        crate::study::load(&path).unwrap()
    }

    /// The ROM cache a run with results in `dir` uses: under cargo the one folder every test
    /// shares (`RFMLAB_ROM_CACHE`), so that both tests here, which prepare the same study's
    /// engine, build its certified ROM once (the second waits for the first's entry) and the
    /// integration tests' runs of that study read it.
    fn shared_cache(dir: &Path) -> std::path::PathBuf {
        crate::stage::rom_cache_dir(&dir.join("results"))
    }

    /// The prepared posterior of the default data is the run's: its log likelihood at the
    /// truth beats the one at a parameter set 10 % off, and its gradient matches central
    /// differences (the binding relies on both).
    #[test]
    fn prepared_posterior_prefers_the_truth_and_has_a_consistent_gradient() {
        let dir = tempfile::tempdir().unwrap();
        let study = bayes_model4(dir.path(), "");
        let prep = Prepared::new(&study, Some(&shared_cache(dir.path()))).unwrap();
        let post = prep.posterior("model4", "L1", None).unwrap();
        assert_eq!(post.n_law(), 4);
        let truth = prep.levels()[0].truth.as_ref().unwrap().params.clone();
        let mut p = truth.clone();
        p.extend(std::iter::repeat_n(0.01, post.dim() - 4));
        let x = post.unconstrained(&p);
        let off: Vec<f64> = p
            .iter()
            .enumerate()
            .map(|(i, v)| if i < 4 { v * 1.1 } else { *v })
            .collect();
        let l_true = post.log_likelihood(&x, None).unwrap();
        let l_off = post
            .log_likelihood(&post.unconstrained(&off), None)
            .unwrap();
        assert!(l_true > l_off + 100.0, "{l_true} vs {l_off}");
        // The gradient against central differences: exact for the density the samplers see
        // (the measurement bias linearised at a point, here the truth); within 1 % for the
        // exact measurement operator, whose Jacobian holds a shaker's force weights fixed
        // (measured: 0.1 % on E0 with the study's shaker).
        let lin = prep.posterior("model4", "L1", Some(&p)).unwrap();
        let check = |post: &FrfPosterior<'_>, tol: f64| -> f64 {
            let mut g = vec![0.0; post.dim()];
            let lp = post.log_posterior(&x, Some(&mut g)).unwrap();
            for i in 0..post.dim() {
                let h = 1e-6;
                let mut a = x.clone();
                a[i] += h;
                let mut b = x.clone();
                b[i] -= h;
                let fd = (post.log_posterior(&a, None).unwrap()
                    - post.log_posterior(&b, None).unwrap())
                    / (2.0 * h);
                assert!(
                    (fd - g[i]).abs() <= tol * (1.0 + g[i].abs()),
                    "coordinate {i}: {fd} vs {} (tolerance {tol})",
                    g[i]
                );
            }
            lp
        };
        let lp = check(&lin, 1e-4);
        check(&post, 1e-2);
        assert!(lp.is_finite());
        // A misspelt model names the key.
        let e = prep.posterior("model9", "L1", None).err().unwrap();
        assert!(e.to_string().contains("models"), "{e}");
    }

    /// A declared effect with matrices of its own (the adherend's structural loss factor, free)
    /// gets its term ROM: the posterior has the effect as a coordinate, and its density changes
    /// with it (without the term ROM the engine could not evaluate it at all).
    #[test]
    fn prepared_posterior_of_a_declared_term_effect_has_its_term_rom() {
        let dir = tempfile::tempdir().unwrap();
        let study = bayes_model4(
            dir.path(),
            "[[structure.effects]]\ntype = \"adherend_damping\"\nvalue = 0.001\nfree = true\n\n",
        );
        let prep = Prepared::new(&study, Some(&shared_cache(dir.path()))).unwrap();
        assert!(
            prep.engine_note.contains("term ROM"),
            "{}",
            prep.engine_note
        );
        let post = prep.posterior("model4", "L1", None).unwrap();
        let names = post.names();
        let k = names
            .iter()
            .position(|n| n == "adherend_damping")
            .expect("the declared effect is a coordinate");
        let truth = prep.levels()[0].truth.as_ref().unwrap().params.clone();
        let mut p = truth.clone();
        p.extend(std::iter::repeat_n(0.01, post.dim() - 4));
        p[k] = 1e-4;
        let a = post.log_likelihood(&post.unconstrained(&p), None).unwrap();
        p[k] = 5e-3;
        let b = post.log_likelihood(&post.unconstrained(&p), None).unwrap();
        assert!(
            a.is_finite() && b.is_finite() && (a - b).abs() > 1.0,
            "{a} vs {b}"
        );
    }
}
