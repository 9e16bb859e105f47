//! The closed loop as a stage of a run: at every level of `[inference]`, the loop's start (the
//! starting model's posterior and initial values, with the channels' correlation estimated
//! once at its MAP), the candidates and, when some need matrices of their own, the term ROM
//! around the run's engine; then the loop ([`crate::closed_loop::run_closed_loop_with_laws`]),
//! its verdict against the calibrated null level, and the summary and markdown of every level.

use super::candidates::{
    admits_alternative_law, level_candidates, opt_in_term_candidates, with_declared,
};
use super::conclude::verdict_of;
use super::params::{DiagnoseParams, LoopInputs};
use super::summary::{
    accepted_in_order, parameter_changes, DiagnoseLevel, DiagnoseSummary, LoopOutcome,
};
use super::term_box::{band_of, outside_box, term_modulus_range};
use super::terms::term_rom_for;
use crate::closed_loop::{run_closed_loop_with_laws, ClosedLoopParams};
use crate::frf::FrfEngine;
use crate::material::ConstitutiveModel;
use crate::stage::{LevelData, RunError};
use std::path::PathBuf;

/// The closed loop of the model of `p` at every level of `p.levels`, on `inputs.engine` (inputs
/// at every measured point), with the loop's settings `params`.
pub fn loop_stage(
    p: &DiagnoseParams,
    params: &ClosedLoopParams,
    inputs: &LoopInputs<'_>,
) -> Result<LoopOutcome, RunError> {
    let t0 = std::time::Instant::now();
    let LoopInputs {
        built,
        levels,
        laws,
        engine,
        posterior,
        starting_fits,
    } = *inputs;
    let name = &p.model;
    let law = &laws[p.model_index];
    // Degraded-bond, adherend-damping and base-spring candidates, and declared ones, need a
    // ROM with their terms.
    let mut bonds = opt_in_term_candidates(p.terms.joint.as_ref(), p.settings.as_ref());
    // Sensor masses in x, y and z as terms of the term ROM (the three-direction pass on base
    // springs).
    bonds.extend(
        p.terms
            .sensor_masses
            .iter()
            .map(|&id| crate::forward::Effect::SensorMassTerm { id }),
    );
    if !bonds.is_empty() {
        let names: Vec<String> = bonds.iter().map(|e| e.name()).collect();
        params.progress.say(&format!(
            "the term ROM ({}): from the cache {} or built and certified",
            names.join(", "),
            p.terms.cache.display()
        ));
    }
    let t_terms = std::time::Instant::now();
    let term_rom = term_rom_for(
        &p.terms,
        built,
        engine,
        &with_declared(&p.declared, &bonds),
        band_of(levels),
    )?;
    if let Some((_, c)) = &term_rom {
        params.progress.say(&format!(
            "term ROM: n_r {} (enriched {}), certificate {:.2e} of the peak{}, built in {:.0} s, here {:.1} s",
            c.basis_size,
            c.enriched_basis_size,
            c.max_rel_error,
            if c.passed { "" } else { " (NOT certified)" },
            c.seconds_basis + c.seconds_certify + c.seconds_compress,
            t_terms.elapsed().as_secs_f64()
        ));
    }
    let mut timings = Vec::new();
    if term_rom.is_some() {
        timings.push(("term ROM".to_string(), t_terms.elapsed().as_secs_f64()));
    }
    let term_range = term_rom
        .as_ref()
        .map(|_| term_modulus_range(&p.terms, band_of(levels)));
    let wrapped = match &term_rom {
        Some((t, _)) => Some(
            crate::rom::WithTerms::new(engine, t).map_err(|e| RunError::Engine(e.to_string()))?,
        ),
        None => None,
    };
    let engine: &dyn FrfEngine = match &wrapped {
        Some(w) => w,
        None => engine,
    };
    // The alternative law: the fractional Zener, unless `[closed_loop] candidates` leaves it
    // out.
    let fractional = crate::material::FractionalZener;
    let alt_laws: Vec<&dyn ConstitutiveModel> = if admits_alternative_law(p.settings.as_ref()) {
        vec![&fractional]
    } else {
        Vec::new()
    };
    let mut summary = Vec::new();
    let mut results = Vec::new();
    for level in levels.iter().filter(|l| p.levels.contains(&l.name)) {
        let mut post = posterior.posterior(engine, level, law.as_ref(), name)?;
        // An earlier pass's fit of the same starting model, else the study's initial values.
        let fit = starting_fits
            .iter()
            .find(|f| f.level == level.name && f.names == post.names);
        let x0 = match fit {
            Some(f) => post.unconstrained(&f.values),
            None => crate::bayes::posterior::initial_x(&post, &p.initial),
        };
        let mut candidates = level_candidates(level, engine, built, &bonds, p.settings.as_ref());
        // A point whose three-direction mass is a term: that mass stands in place of the
        // measured-direction one, which an earlier pass tried (the two at one point are
        // alternatives, and the first accepted would bar the other).
        candidates.retain(|c| {
            !matches!(c, crate::forward::Effect::PointMass { id, .. } if p.terms.sensor_masses.contains(id))
        });
        let t_loop = std::time::Instant::now();
        params
            .progress
            .say(&format!("{}: {} candidates", level.name, candidates.len()));
        // With the channels' correlation, its estimate's MAP is the loop's start; from an
        // earlier pass's fit, that MAP searches from the fit alone.
        let t_correlation = std::time::Instant::now();
        let x0 = match p.channel_correlation {
            Some((kind, window)) => {
                let map = crate::inference::map::MapParams {
                    n_starts: if fit.is_some() {
                        0
                    } else {
                        params.map.n_starts
                    },
                    ..params.map.clone()
                };
                set_correlation(&mut post, &x0, &map, kind, window, level)?
            }
            None => x0,
        };
        if p.channel_correlation.is_some() {
            timings.push((
                format!("{}: channel correlation", level.name),
                t_correlation.elapsed().as_secs_f64(),
            ));
        }
        // A start that is a fit already is searched from alone.
        let warm;
        let params = if fit.is_some() || p.channel_correlation.is_some() {
            warm = ClosedLoopParams {
                start_is_fit: true,
                ..params.clone()
            };
            &warm
        } else {
            params
        };
        let res = run_closed_loop_with_laws(&mut post, &x0, &candidates, &alt_laws, params)
            .map_err(|e| RunError::Analysis {
                analysis: format!("closed loop of {name} at {}", level.name),
                message: e.to_string(),
            })?;
        let (res, verdict, null) = verdict_of(&p.null, level, &mut post, res, params)?;
        timings.extend(
            res.timings
                .iter()
                .map(|(step, s)| (format!("{}: {step}", level.name), *s)),
        );
        params.progress.say(&format!(
            "{}: {} (null level {:.3}, threshold {:.3}, {:.1} s)",
            level.name, verdict.status, null.mean, null.threshold, null.seconds
        ));
        // The truth of the final law (the study's, or the alternative that replaced it).
        let truth = level
            .truth
            .as_ref()
            .filter(|t| t.model.name() == res.after.law)
            .map(|t| t.params.clone());
        summary.push(DiagnoseLevel {
            level: level.name.clone(),
            status: verdict.status.to_string(),
            verdict,
            null,
            conclusion: res.conclusion.clone(),
            chi2_normalised_before: res.before.residuals.chi2_normalised,
            chi2_normalised_after: res.after.residuals.chi2_normalised,
            relative_norm_before: res.before.residuals.relative_norm,
            relative_norm_after: res.after.residuals.relative_norm,
            frac_before: res.before.residuals.frac.clone(),
            frac_after: res.after.residuals.frac.clone(),
            loop_seconds: t_loop.elapsed().as_secs_f64(),
            accepted: accepted_in_order(&res),
            first_ranking: res
                .candidates
                .iter()
                .filter(|c| c.round == 0)
                .map(|c| c.effect.name())
                .collect(),
            confounded: res.confounded.clone(),
            parameters: parameter_changes(&res, truth.as_deref()),
            term_box_factor: term_range.as_ref().map(|range| {
                let n = law.param_names().len();
                outside_box(
                    law.as_ref(),
                    &res.after.values[..n.min(res.after.values.len())],
                    &level.freq_hz,
                    range,
                )
            }),
        });
        results.push((
            level.name.clone(),
            level.freq_hz.clone(),
            level.response_ids.clone(),
            res,
            truth,
        ));
    }
    // (The wrapped engine borrows the term ROM, which the summary takes next.)
    drop(wrapped);
    let term_names = term_rom
        .as_ref()
        .map(|(t, _)| t.names.clone())
        .unwrap_or_default();
    let mut outcome = LoopOutcome {
        term_names,
        mesh: None,
        summary: DiagnoseSummary {
            study: p.study_name.clone(),
            model: name.clone(),
            output_dir: PathBuf::new(),
            levels: summary,
            seconds: t0.elapsed().as_secs_f64(),
            term_rom: term_rom.map(|(_, c)| c).zip(term_range),
        },
        levels: results,
        markdown: String::new(),
        timings,
    };
    outcome.remake_markdown();
    Ok(outcome)
}

/// Correlated channels (`inference.noise.channel_correlation`): the starting model's MAP, then
/// the inference's channel-correlation fixed point at it
/// ([`crate::inference::refine::correlation_fixed_point`]); the MAP is returned, unconstrained,
/// as the loop's start and the correlation is held fixed during the loop (with a missing
/// effect the residuals hold it too, so it is estimated once, before, not per candidate).
fn set_correlation(
    post: &mut crate::inference::likelihood::FrfPosterior<'_>,
    x0: &[f64],
    map: &crate::inference::map::MapParams,
    kind: crate::inference::refine::CorrelationKind,
    window: usize,
    level: &LevelData,
) -> Result<Vec<f64>, RunError> {
    let fail = |m: String| RunError::Analysis {
        analysis: format!("channel correlation for the closed loop at {}", level.name),
        message: m,
    };
    let mut r = crate::inference::map::find_map(&*post, Some(x0), map, &|| ())
        .map_err(|e| fail(e.to_string()))?;
    crate::inference::refine::correlation_fixed_point(
        post,
        &mut r,
        map,
        kind,
        window,
        &level.freq_hz,
        false,
    )
    .map_err(|e| fail(e.to_string()))?;
    Ok(r.map_x)
}
