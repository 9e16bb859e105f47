//! `rfmlab diagnose STUDY.toml`: the closed loop ([`crate::closed_loop`]) at every level of the
//! study's `[inference]` section, for its first model (or the one asked for), with the default
//! candidates: a point mass at every measured point, a gain and a delay per channel, the beam
//! modulus factor (left out when the adherend has viscous damping `C_b`, where its exact
//! scaling does not hold), the Maxwell branches, and the fractional Zener law as an alternative
//! law ([`crate::closed_loop::alternative`]; opt-out in `[closed_loop] candidates`); on a
//! meshed joint, when `candidates` names it, also a sensor mass (x, y and z) at every measured
//! point. Each level ends with a
//! verdict ([`crate::closed_loop::verdict`]) against a null level calibrated on replicates of
//! the fitted model. Writes the parquet tables `residuals`, `candidates`, `closed_loop`,
//! `verdict`, `signatures` and a markdown summary `closed_loop.md` (its first line the status
//! per level) into `<output_dir>.diagnose/`.

use super::{posterior, RunError};
use crate::closed_loop::{
    default_candidates, run_closed_loop_with_laws, ClosedLoopParams, ClosedLoopResult, Residuals,
};
use crate::output::{ResultsDir, Table};
use crate::study::Study;
use std::fmt::Write as _;
use std::path::PathBuf;

/// What `diagnose` found, per level.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DiagnoseSummary {
    pub study: String,
    pub model: String,
    pub output_dir: PathBuf,
    pub levels: Vec<DiagnoseLevel>,
    pub seconds: f64,
    /// The term ROM's certificate and modulus box, when a candidate or a declared effect
    /// needed one (degraded bond, adherend damping; src/runner/terms.rs).
    pub term_rom: Option<(crate::rom::TermCertificate, crate::rom::ModulusRange)>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct DiagnoseLevel {
    pub level: String,
    /// `nothing_missing`, `explained`, `unexplained` or `confounded`
    /// ([`crate::closed_loop::verdict`]).
    pub status: String,
    /// The verdict behind the status (null level, where the residual is, tentative effects).
    pub verdict: crate::closed_loop::verdict::Verdict,
    /// The calibrated null level of the normalised chi-square.
    pub null: crate::closed_loop::null::NullCalibration,
    pub conclusion: String,
    pub chi2_normalised_before: f64,
    pub chi2_normalised_after: f64,
    pub relative_norm_before: f64,
    pub relative_norm_after: f64,
    pub frac_before: Vec<f64>,
    pub frac_after: Vec<f64>,
    /// Wall time (s) of the loop at this level (MAP, score tests, refits, evidence).
    pub loop_seconds: f64,
    /// Accepted effects in order: name, type, size (SI) and posterior sd.
    pub accepted: Vec<(String, String, f64, f64)>,
    /// Score-test ranking of the first round: candidate names, best first.
    pub first_ranking: Vec<String>,
    /// The model's parameters (law, then accepted effects), before and after.
    pub parameters: Vec<ParameterChange>,
    /// Candidates the law's parameters absorb (not identifiable), a sentence each.
    pub confounded: Vec<String>,
    /// With a term ROM: the factor by which the law's modulus at the final MAP leaves the term
    /// ROM's certified box over the level's lines (1: inside).
    pub term_box_factor: Option<f64>,
}

/// One parameter before and after the loop (SI), with the truth when simulated.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ParameterChange {
    pub name: String,
    pub before: Option<f64>,
    pub before_sd: Option<f64>,
    pub after: f64,
    pub after_sd: f64,
    pub truth: Option<f64>,
}

fn out_err(e: crate::output::OutputError) -> RunError {
    RunError::Output(e)
}

/// Whether the likelihood's engine needs every measured point as an input: the study runs the
/// loop (`[closed_loop]`, or `rfmlab diagnose`, which sets it) or declares a point mass (the
/// Sherman-Morrison-Woodbury update needs the receptances at the mass's point).
pub fn needs_all_inputs(study: &Study) -> bool {
    study.closed_loop.as_ref().is_some_and(|c| c.enabled)
        || study.declared_effects.iter().any(|d| {
            matches!(
                d.kind,
                crate::study::effects::DeclaredKind::PointMass { .. }
            )
        })
}

/// The loop's settings from the study's `[closed_loop]` section (defaults without one).
pub fn params_of(study: &Study) -> ClosedLoopParams {
    let d = ClosedLoopParams::default();
    match &study.closed_loop {
        None => d,
        Some(s) => ClosedLoopParams {
            threshold_nats: s.evidence_threshold_nats,
            top: s.top,
            max_rounds: s.max_effects + 1,
            p_threshold: s.p_threshold,
            ..d
        },
    }
}

/// Whether `[closed_loop] candidates` names the three-direction sensor mass (its type
/// `sensor_mass` or a name `mass3_pt<id>`): it is not among `candidates = "all"`.
pub fn wants_sensor_mass(study: &Study) -> bool {
    study
        .closed_loop
        .as_ref()
        .is_some_and(|c| c.names(|n| n == "sensor_mass" || n.starts_with("mass3_pt")))
}

/// Run the loop on `study` (model `model`, else the first of `[inference] models`); results in
/// `<output_dir>.diagnose/`.
pub fn diagnose_study(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
) -> Result<DiagnoseSummary, RunError> {
    let out = super::sibling(&study.output_dir, "diagnose");
    let parent = out.parent().unwrap_or(std::path::Path::new("."));
    let dir_name = out
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "diagnose".into());
    diagnose_into(study, model, params, parent, &dir_name, true)
}

/// The loop's markdown as a section of the run's report: its headings one level down, its
/// figures under `sub/`.
pub(crate) fn report_section(md: &str, sub: &str) -> String {
    let mut text = String::from("## Closed loop (`[closed_loop]`)\n");
    for line in md.lines().skip(1) {
        let line = line.replace("](residuals_", &format!("]({sub}/residuals_"));
        if line.starts_with('#') {
            let _ = writeln!(text, "#{line}");
        } else {
            let _ = writeln!(text, "{line}");
        }
    }
    text
}

/// [`diagnose_study`] into `<parent>/<dir_name>/`, with the residual figures when `figures`.
pub fn diagnose_into(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
    parent: &std::path::Path,
    dir_name: &str,
    figures: bool,
) -> Result<DiagnoseSummary, RunError> {
    let t0 = std::time::Instant::now();
    // The loop needs every measured point as an engine input (point-mass candidates).
    let mut with_loop = study.clone();
    if !needs_all_inputs(&with_loop) {
        with_loop.closed_loop = Some(crate::study::effects::ClosedLoopSettings::default());
    }
    // A sensor's mass acts in x, y and z: when `[closed_loop] candidates` names the
    // sensor-mass candidate, the other two directions of every measured point of a meshed
    // joint become model points (and engine inputs) for it. Opt-in: the engine's inputs
    // triple, and its reduced basis with them (minutes to build on the paper's joint).
    if crate::study::build::joint_spec(&with_loop.structure).is_some() && wants_sensor_mass(study) {
        with_loop.structure.points = with_all_directions(&with_loop.structure.points);
    }
    let study = &with_loop;
    if study.inference.is_none() {
        return Err(no_inference(study));
    }
    let laws = super::model_laws(study)?;
    let built = super::build(study)?;
    let mut levels = super::load_levels(study, &built)?;
    let engines = super::build_engine(study, &built, &mut levels, &laws, None)?;
    let engine = engines
        .likelihood
        .as_deref()
        .unwrap_or(engines.engine.as_ref());
    let mut outcome = loop_stage(study, &built, &levels, &laws, engine, model, params)?;
    let mut dir = ResultsDir::create(parent, dir_name).map_err(out_err)?;
    write_loop(&mut dir, &outcome, &study.name, figures)?;
    outcome.summary.output_dir = dir.path().to_path_buf();
    outcome.summary.seconds = t0.elapsed().as_secs_f64();
    Ok(outcome.summary)
}

fn no_inference(study: &Study) -> RunError {
    super::study_err(
        study,
        "inference",
        "diagnose needs an [inference] section (its noise model and priors define the likelihood the loop tests); add one as in studies/bayes.toml",
    )
}

/// The loop's outcome (nothing written): per level its result, the summary and the markdown.
#[derive(Clone, Debug)]
pub struct LoopOutcome {
    /// The summary (`output_dir` empty until written).
    pub summary: DiagnoseSummary,
    /// Per level: name, lines (Hz), response ids, the loop's result and the truth of the
    /// final law when simulated.
    pub levels: Vec<LevelResult>,
    /// The loop's section of the report (markdown, its own level-1 heading).
    pub markdown: String,
}

/// The closed loop of `model` (else the first `[inference]` model) at every inference level,
/// on `engine` (inputs at every measured point).
pub(crate) fn loop_stage(
    study: &Study,
    built: &crate::study::build::BuiltModel,
    levels: &[super::LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
    engine: &dyn crate::frf::FrfEngine,
    model: Option<&str>,
    params: &ClosedLoopParams,
) -> Result<LoopOutcome, RunError> {
    let t0 = std::time::Instant::now();
    let Some(inf) = &study.inference else {
        return Err(no_inference(study));
    };
    let name = match model {
        Some(m) => m.to_string(),
        None => inf.models.first().cloned().ok_or_else(|| {
            super::study_err(study, "inference.models", "list at least one model")
        })?,
    };
    let Some((spec, law)) = study
        .models
        .iter()
        .zip(laws)
        .find(|(m, _)| m.name.eq_ignore_ascii_case(&name))
    else {
        return Err(super::study_err(
            study,
            "inference.models",
            format!("model {name} is not a model of the study"),
        ));
    };
    // Degraded-bond and adherend-damping candidates and declared ones need a ROM with their
    // terms.
    // Opt-in: only when `[closed_loop] candidates` names them ("degraded_bond" or a strip's
    // name). Each evaluation with a bond is a dense LU of the term ROM per line (on the paper's
    // 5 mm joint with both strips, 219 unknowns after the compression: 1-2 s per forward
    // evaluation on 2000 fine lines, against milliseconds on the pencil), and the term ROM is
    // built, certified and compressed per run (about 3 min there), so the default candidate
    // set ("all") leaves them out.
    // Base springs (a compliance term over the free-base joint) likewise.
    let mut term_candidates =
        super::terms::term_candidates(study, crate::forward::effects::DEFAULT_BOND_STRIP_M);
    if crate::study::build::joint_spec(&study.structure).is_some() {
        term_candidates.push(crate::forward::Effect::BaseSprings {
            normal_over_tangential: crate::forward::effects::DEFAULT_BASE_NORMAL_OVER_TANGENTIAL,
        });
    }
    let bonds: Vec<crate::forward::Effect> = term_candidates
        .into_iter()
        .filter(|e| {
            study
                .closed_loop
                .as_ref()
                .is_some_and(|c| c.names(|n| n == e.kind() || n == e.name()))
        })
        .collect();
    let term_cache = super::rom_cache_dir(study);
    if !bonds.is_empty() {
        let names: Vec<String> = bonds.iter().map(|e| e.name()).collect();
        params.progress.say(&format!(
            "the term ROM ({}): from the cache {} or built and certified",
            names.join(", "),
            term_cache.display()
        ));
    }
    let t_terms = std::time::Instant::now();
    let term_rom = super::terms::term_rom_for(
        study,
        built,
        engine,
        &super::terms::with_declared(study, &bonds),
        super::terms::band_of(levels),
        Some(&term_cache),
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
    let wrapped = match &term_rom {
        Some((t, _)) => Some(
            crate::rom::WithTerms::new(engine, t).map_err(|e| RunError::Engine(e.to_string()))?,
        ),
        None => None,
    };
    let engine: &dyn crate::frf::FrfEngine = match &wrapped {
        Some(w) => w,
        None => engine,
    };
    // The alternative law: the fractional Zener, unless `[closed_loop] candidates`
    // leaves it out (names "fractional_zener" / type "alternative_law").
    let fractional = crate::material::FractionalZener;
    let alt_laws: Vec<&dyn crate::material::ConstitutiveModel> =
        if study.closed_loop.as_ref().is_none_or(|c| {
            c.admits(
                crate::closed_loop::alternative::ALTERNATIVE_LAW,
                crate::closed_loop::alternative::FRACTIONAL_ZENER,
            )
        }) {
            vec![&fractional]
        } else {
            Vec::new()
        };
    let mut summary = Vec::new();
    let mut results = Vec::new();
    for level in levels.iter().filter(|l| inf.levels.contains(&l.name)) {
        let mut post = posterior::build_posterior(study, inf, engine, level, law.as_ref(), &name)?;
        let x0 = posterior::initial_x(&post, &spec.initial);
        let col = &level.column;
        let mass_points: Vec<(usize, u32)> = col
            .outputs
            .iter()
            .zip(&level.response_ids)
            .filter(|(o, _)| engine.inputs().contains(o))
            .map(|(o, id)| (*o, *id))
            .collect();
        let mut candidates = default_candidates(&level.response_ids, &mass_points);
        candidates.extend(sensor_mass_candidates(
            &built.model.points,
            engine.inputs(),
            &level.response_ids,
        ));
        let band = (
            level.freq_hz.first().copied().unwrap_or(0.0),
            level.freq_hz.last().copied().unwrap_or(0.0),
        );
        candidates.extend(crate::closed_loop::maxwell_candidates(band));
        candidates.extend(bonds.iter().cloned());
        // The beam factor's exact scaling needs an adherend without viscous damping C_b.
        if built.model.c_b.is_some() {
            candidates.retain(|c| !matches!(c, crate::forward::Effect::BeamModulus));
        }
        let candidates = super::declared::admitted(candidates, study.closed_loop.as_ref());
        let t_loop = std::time::Instant::now();
        params
            .progress
            .say(&format!("{}: {} candidates", level.name, candidates.len()));
        let x0 = match inf.channel_correlation {
            Some((kind, window)) => {
                set_correlation(&mut post, &x0, &params.map, kind, window, level)?
            }
            None => x0,
        };
        let res = run_closed_loop_with_laws(&mut post, &x0, &candidates, &alt_laws, params)
            .map_err(|e| RunError::Analysis {
                analysis: format!("closed loop of {name} at {}", level.name),
                message: e.to_string(),
            })?;
        let (res, verdict, null) = verdict_of(study, level, &mut post, res, params)?;
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
            term_box_factor: term_rom.as_ref().map(|_| {
                let n = law.param_names().len();
                super::terms::outside_box(
                    law.as_ref(),
                    &res.after.values[..n.min(res.after.values.len())],
                    &level.freq_hz,
                    &super::terms::term_modulus_range(study, super::terms::band_of(levels)),
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
    let markdown = markdown(
        &study.name,
        &name,
        &results,
        &summary,
        term_rom.as_ref().map(|(t, c)| (t.names.as_slice(), c)),
    );
    Ok(LoopOutcome {
        summary: DiagnoseSummary {
            study: study.name.clone(),
            model: name,
            output_dir: PathBuf::new(),
            levels: summary,
            seconds: t0.elapsed().as_secs_f64(),
            term_rom: term_rom.map(|(_, c)| {
                (
                    c,
                    super::terms::term_modulus_range(study, super::terms::band_of(levels)),
                )
            }),
        },
        levels: results,
        markdown,
    })
}

/// The loop's tables: `residuals`, `candidates`, `closed_loop`, `verdict`, `signatures`.
pub(crate) fn loop_tables(o: &LoopOutcome) -> Result<Vec<Table>, RunError> {
    Ok(vec![
        residuals_table(&o.levels)?,
        candidates_table(&o.levels)?,
        closed_loop_table(&o.levels, &o.summary.levels)?,
        verdict_table(&o.levels, &o.summary.levels)?,
        signatures_table(&o.levels)?,
    ])
}

/// Write the loop's tables, residual figures (when `figures`) and `closed_loop.md` into `dir`.
pub(crate) fn write_loop(
    dir: &mut ResultsDir,
    o: &LoopOutcome,
    study_name: &str,
    figures: bool,
) -> Result<(), RunError> {
    for t in loop_tables(o)? {
        dir.write_table(&t).map_err(out_err)?;
    }
    if figures {
        for (level, freq, ids, res, _) in &o.levels {
            crate::plot::closed_loop::residual_figure(
                dir.file_path(&format!("residuals_{level}")),
                &format!(
                    "{study_name}: standardised residuals of {} at {level}, before and after",
                    o.summary.model
                ),
                freq,
                ids,
                &res.before.residuals.z,
                &res.after.residuals.z,
            )?;
        }
    }
    dir.write_bytes("closed_loop.md", o.markdown.as_bytes())
        .map_err(out_err)?;
    Ok(())
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
    level: &super::LevelData,
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

/// Accepted effects and laws in the order the loop accepted them: name, type, size and sd
/// (NaN for a law, which has no size).
fn accepted_in_order(res: &ClosedLoopResult) -> Vec<(String, String, f64, f64)> {
    let mut v: Vec<(usize, String, String, f64, f64)> = res
        .candidates
        .iter()
        .filter_map(|c| {
            let r = c.refit.as_ref().filter(|r| r.accepted)?;
            Some((
                c.round,
                c.effect.name(),
                c.effect.kind().to_string(),
                r.size,
                r.sd,
            ))
        })
        .chain(
            res.law_candidates
                .iter()
                .filter(|c| c.refit.accepted)
                .map(|c| {
                    (
                        c.round,
                        c.law.clone(),
                        crate::closed_loop::alternative::ALTERNATIVE_LAW.to_string(),
                        f64::NAN,
                        f64::NAN,
                    )
                }),
        )
        .collect();
    v.sort_by_key(|x| x.0);
    v.into_iter().map(|(_, n, k, a, b)| (n, k, a, b)).collect()
}

/// The parameters before and after: the final model's (matched by name to the starting
/// model's; when the law was replaced, the new law's parameters have no "before"), then, when
/// the law was replaced, the old law's parameters as `<law>.<name>` with no "after" (NaN).
/// `truth` is the final law's true parameters.
fn parameter_changes(res: &ClosedLoopResult, truth: Option<&[f64]>) -> Vec<ParameterChange> {
    let (b, a) = (&res.before, &res.after);
    let replaced = b.law != a.law;
    let mut v: Vec<ParameterChange> = a
        .names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let j = b
                .names
                .iter()
                .enumerate()
                .position(|(j, m)| m == n && !(replaced && (i < a.n_law || j < b.n_law)));
            ParameterChange {
                name: n.clone(),
                before: j.map(|j| b.values[j]),
                before_sd: j.map(|j| b.sd[j]),
                after: a.values[i],
                after_sd: a.sd[i],
                truth: truth.and_then(|t| t.get(i).copied()),
            }
        })
        .collect();
    if replaced {
        for j in 0..b.n_law {
            v.push(ParameterChange {
                name: format!("{}.{}", b.law, b.names[j]),
                before: Some(b.values[j]),
                before_sd: Some(b.sd[j]),
                after: f64::NAN,
                after_sd: f64::NAN,
                truth: None,
            });
        }
    }
    v
}

/// One level of the loop: name, lines (Hz), response ids, result, truth of the final law.
pub type LevelResult = (
    String,
    Vec<f64>,
    Vec<u32>,
    ClosedLoopResult,
    Option<Vec<f64>>,
);

/// `residuals`: level, stage ("before"/"after"), freq_hz, channel, standardised residual.
fn residuals_table(results: &[LevelResult]) -> Result<Table, RunError> {
    let (mut lv, mut st, mut f, mut ch, mut re, mut im) = (
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
    );
    for (level, freq, ids, res, _) in results {
        for (stage, r) in [
            ("before", &res.before.residuals),
            ("after", &res.after.residuals),
        ] {
            let n = ids.len();
            for (o, z) in r.z.iter().enumerate() {
                lv.push(level.clone());
                st.push(stage.to_string());
                f.push(freq[o / n]);
                ch.push(ids[o % n]);
                re.push(z.re);
                im.push(z.im);
            }
        }
    }
    let mut t = Table::new("residuals");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("stage", st))
        .and_then(|t| t.push_f64("freq_hz", "Hz", f))
        .and_then(|t| t.push_u32("channel", "", ch))
        .and_then(|t| t.push_f64("z_re", "1", re))
        .and_then(|t| t.push_f64("z_im", "1", im))
        .map_err(out_err)?;
    Ok(t)
}

/// `signatures`: level, stage, one row per resonance of the prediction: its frequency and
/// loss factor, the data's relative frequency change and loss-factor change with sds.
fn signatures_table(results: &[LevelResult]) -> Result<Table, RunError> {
    let (mut lv, mut st) = (Vec::new(), Vec::new());
    let mut cols: [Vec<f64>; 6] = Default::default();
    for (level, _, _, res, _) in results {
        for (stage, r) in [
            ("before", &res.before.residuals),
            ("after", &res.after.residuals),
        ] {
            for x in &r.signatures.resonances {
                lv.push(level.clone());
                st.push(stage.to_string());
                for (c, v) in cols.iter_mut().zip([
                    x.freq_hz,
                    x.loss_factor,
                    x.freq_shift,
                    x.freq_shift_sd,
                    x.loss_change,
                    x.loss_change_sd,
                ]) {
                    c.push(v);
                }
            }
        }
    }
    let [f, eta, df, df_sd, de, de_sd] = cols;
    let mut t = Table::new("signatures");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("stage", st))
        .and_then(|t| t.push_f64("resonance_hz", "Hz", f))
        .and_then(|t| t.push_f64("loss_factor", "1", eta))
        .and_then(|t| t.push_f64("freq_shift", "1", df))
        .and_then(|t| t.push_f64("freq_shift_sd", "1", df_sd))
        .and_then(|t| t.push_f64("loss_change", "1", de))
        .and_then(|t| t.push_f64("loss_change_sd", "1", de_sd))
        .map_err(out_err)?;
    Ok(t)
}

/// `candidates`: one row per candidate and round.
fn candidates_table(results: &[LevelResult]) -> Result<Table, RunError> {
    let mut t = Table::new("candidates");
    let (mut c_level, mut c_round, mut c_rank, mut c_effect, mut c_kind) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut num: [Vec<f64>; 4] = Default::default();
    let mut refit: [Vec<Option<f64>>; 4] = Default::default();
    let (mut acc, mut verdict, mut unit) = (Vec::new(), Vec::new(), Vec::new());
    let (mut r2, mut absorbed, mut profile) = (Vec::new(), Vec::new(), Vec::new());
    for (level, _, _, res, _) in results {
        for c in &res.candidates {
            c_level.push(level.clone());
            c_round.push(c.round as i64);
            c_rank.push(c.rank as i64);
            c_effect.push(c.effect.name());
            c_kind.push(c.effect.kind().into());
            unit.push(c.effect.unit().to_string());
            num[0].push(c.score);
            num[1].push(c.p_value);
            num[2].push(c.one_step);
            num[3].push(c.one_step_sd);
            let r = c.refit.as_ref();
            refit[0].push(r.map(|r| r.evidence_gain));
            refit[1].push(r.map(|r| r.log_evidence));
            refit[2].push(r.map(|r| r.size));
            refit[3].push(r.map(|r| r.sd));
            acc.push(r.is_some_and(|r| r.accepted));
            verdict.push(r.map_or("not refitted".to_string(), |r| r.verdict.clone()));
            profile.push(c.profile_gain);
            r2.push(c.confounding.r2);
            absorbed.push(
                c.confounding
                    .absorbed
                    .iter()
                    .map(|(n, a)| format!("{n} {a:+.4e}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            );
        }
        // Alternative laws: no score test (not nested), no size.
        for c in &res.law_candidates {
            c_level.push(level.clone());
            c_round.push(c.round as i64);
            c_rank.push(0);
            c_effect.push(c.law.clone());
            c_kind.push(crate::closed_loop::alternative::ALTERNATIVE_LAW.into());
            unit.push(String::new());
            for x in num.iter_mut() {
                x.push(f64::NAN);
            }
            let r = &c.refit;
            refit[0].push(Some(r.evidence_gain).filter(|x| x.is_finite()));
            refit[1].push(Some(r.log_evidence).filter(|x| x.is_finite()));
            refit[2].push(None);
            refit[3].push(None);
            acc.push(r.accepted);
            verdict.push(r.verdict.clone());
            profile.push(None);
            // A whole law is not a column beside the law's own: no confounding measure.
            r2.push(f64::NAN);
            absorbed.push(String::new());
        }
    }
    let [score, p, est, est_sd] = num;
    let [gain, logz, size, sd] = refit;
    t.push_str("level", c_level)
        .and_then(|t| t.push_i64("round", "", c_round))
        .and_then(|t| t.push_i64("rank", "", c_rank))
        .and_then(|t| t.push_str("effect", c_effect))
        .and_then(|t| t.push_str("kind", c_kind))
        .and_then(|t| t.push_str("unit", unit))
        .and_then(|t| t.push_f64("score", "1", score))
        .and_then(|t| t.push_f64("p_value", "1", p))
        .and_then(|t| t.push_f64("one_step_size", "SI (see unit)", est))
        .and_then(|t| t.push_f64("one_step_sd", "SI (see unit)", est_sd))
        .and_then(|t| t.push_opt_f64("evidence_gain", "nat", gain))
        .and_then(|t| t.push_opt_f64("log_evidence", "nat", logz))
        .and_then(|t| t.push_opt_f64("size", "SI (see unit)", size))
        .and_then(|t| t.push_opt_f64("size_sd", "SI (see unit)", sd))
        .and_then(|t| t.push_bool("accepted", acc))
        .and_then(|t| t.push_str("verdict", verdict))
        .and_then(|t| t.push_opt_f64("profile_gain", "nat", profile))
        .and_then(|t| t.push_f64("law_r2", "1", r2))
        .and_then(|t| t.push_str("absorbed_per_unit", absorbed))
        .map_err(out_err)?;
    Ok(t)
}

/// `closed_loop`: per level and quantity, before and after (parameters with sds, and the
/// residual statistics), and the truth where the data are simulated.
/// Every row carries the level's `status`; the law's parameters of an `unexplained` level
/// carry its warning, those of a `confounded` level their range over the effect's plausible
/// sizes.
fn closed_loop_table(
    results: &[LevelResult],
    summary: &[DiagnoseLevel],
) -> Result<Table, RunError> {
    let (mut lv, mut q) = (Vec::new(), Vec::new());
    let (mut b, mut bs, mut a, mut as_, mut tr) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut status, mut warning) = (Vec::new(), Vec::new());
    for ((level, _, ids, res, truth), l) in results.iter().zip(summary) {
        let v = &l.verdict;
        let n_rows = q.len();
        for pc in parameter_changes(res, truth.as_deref()) {
            let law_param = res.after.names[..res.after.n_law].contains(&pc.name);
            let range = v.confounded.first().and_then(|c| {
                c.ranges.iter().find(|r| r.0 == pc.name).map(|(_, lo, hi)| {
                    format!(
                        "confounded with {} (correlation {:.4}): range [{lo:.4e}, {hi:.4e}]",
                        c.effect, c.correlation
                    )
                })
            });
            warning.push(match (law_param, &v.warning, range) {
                (true, Some(w), _) => w.clone(),
                (true, None, Some(r)) => r,
                _ => String::new(),
            });
            lv.push(level.clone());
            q.push(pc.name);
            b.push(pc.before);
            bs.push(pc.before_sd);
            a.push(Some(pc.after).filter(|x| !x.is_nan()));
            as_.push(Some(pc.after_sd).filter(|x| !x.is_nan()));
            tr.push(pc.truth);
        }
        let stat = |r: &Residuals| -> Vec<(String, f64)> {
            let mut v = vec![
                ("chi2_normalised".to_string(), r.chi2_normalised),
                ("relative_residual_norm".to_string(), r.relative_norm),
                ("chi2_p_value".to_string(), r.p_value),
            ];
            for (k, id) in ids.iter().enumerate() {
                v.push((format!("frac_ch{id}"), r.frac[k]));
                v.push((format!("runs_z_ch{id}"), r.channels[k].runs_z));
            }
            v
        };
        for ((n, x), (_, y)) in stat(&res.before.residuals)
            .into_iter()
            .zip(stat(&res.after.residuals))
        {
            lv.push(level.clone());
            q.push(n);
            b.push(Some(x));
            bs.push(None);
            a.push(Some(y));
            as_.push(None);
            tr.push(None);
            warning.push(String::new());
        }
        status.extend(std::iter::repeat_n(v.status.to_string(), q.len() - n_rows));
    }
    let mut t = Table::new("closed_loop");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("status", status))
        .and_then(|t| t.push_str("quantity", q))
        .and_then(|t| t.push_opt_f64("before", "SI", b))
        .and_then(|t| t.push_opt_f64("before_sd", "SI", bs))
        .and_then(|t| t.push_opt_f64("after", "SI", a))
        .and_then(|t| t.push_opt_f64("after_sd", "SI", as_))
        .and_then(|t| t.push_opt_f64("truth", "SI", tr))
        .and_then(|t| t.push_str("warning", warning))
        .map_err(out_err)?;
    Ok(t)
}

/// The status of every level, `L1 `explained`, L2 `unexplained``: the first line of the
/// loop's markdown and of the run's report.
pub fn status_line(levels: &[DiagnoseLevel]) -> String {
    levels
        .iter()
        .map(|l| format!("{} `{}`", l.level, l.status))
        .collect::<Vec<_>>()
        .join(", ")
}

fn markdown(
    study: &str,
    model: &str,
    results: &[LevelResult],
    summary: &[DiagnoseLevel],
    term: Option<(&[String], &crate::rom::TermCertificate)>,
) -> String {
    let mut s = String::new();
    // The first line: the status of every level.
    let _ = writeln!(
        s,
        "# Closed loop: {study}, {model}: {}\n",
        status_line(summary)
    );
    let _ = writeln!(
        s,
        "Status per level: `nothing_missing` (the residual is consistent with noise, no effect needed), `explained` (effects accepted, the final residual consistent with noise), `unexplained` (the residual stays above the calibrated null level: the effects accepted on the way are tentative and the adhesive's parameters carry a warning), `confounded` (an effect the data cannot separate from the adhesive's parameters: they are given as a range). Consistent with noise: the normalised chi-square at most the threshold of its null level, calibrated on replicates of the fitted model through the same measurement chain.\n"
    );
    if let Some((names, c)) = term {
        let _ = writeln!(
            s,
            "Effects with matrices of their own ({}) are evaluated by a reduced model with their terms: {} basis vectors ({} before the POD compression), {} against the full model with each term on to {:.2e} of each FRF's peak ({} moduli x {} lines per case).\n",
            names.join(", "),
            c.basis_size,
            c.enriched_basis_size,
            if c.passed { "certified" } else { "NOT certified" },
            c.max_rel_error,
            c.n_moduli,
            c.n_lines
        );
    }
    for ((level, _, ids, res, truth), l) in results.iter().zip(summary) {
        let v = &l.verdict;
        let _ = writeln!(
            s,
            "## Level {level}: `{}`\n\n**{}**\n\n{}\n",
            v.status, v.sentence, res.conclusion
        );
        if let Some(w) = &v.warning {
            let _ = writeln!(s, "**Warning on the adhesive's parameters:** {w}.\n");
        }
        for d in &v.drop_one {
            let _ = writeln!(
                s,
                "- drop-one check of {}: {:.1} nats in the final model, {:.1} once widened by kappa = {:.2}: {}",
                d.effect,
                d.gain,
                d.scaled_gain,
                d.kappa,
                if d.kept { "kept (tentative)" } else { "dropped" }
            );
        }
        for d in &v.not_needed {
            let _ = writeln!(
                s,
                "- {} = {:.4e} {} left out: the final model refitted without it reads a normalised chi-square of {:.3}, within the noise (threshold {:.3}); its evidence gain came from a difference it stands in for",
                d.effect, d.size, d.unit, d.chi2_without, v.threshold
            );
        }
        if !v.drop_one.is_empty() || !v.not_needed.is_empty() {
            s.push('\n');
        }
        let _ = writeln!(
            s,
            "| round | rank | effect | score T | p | evidence gain (nat) | size +- sd | 95 % interval | verdict |\n|---|---|---|---|---|---|---|---|---|"
        );
        for c in res
            .candidates
            .iter()
            .filter(|c| c.rank <= 5 || c.refit.is_some() || c.profile_gain.is_some())
        {
            let (g, sz, iv, v) = match &c.refit {
                Some(r) => (
                    format!("{:.1}", r.evidence_gain),
                    format!("{:.4e} +- {:.1e} {}", r.size, r.sd, c.effect.unit()),
                    format!(
                        "[{:.4e}, {:.4e}]",
                        r.size - 1.96 * r.sd,
                        r.size + 1.96 * r.sd
                    ),
                    r.verdict.clone(),
                ),
                None => ("".into(), "".into(), "".into(), "not refitted".into()),
            };
            // Ranked by the profile (the residual far from noise): its gain beside the verdict.
            let v = match c.profile_gain {
                Some(pg) => format!("{v} (profile gain {pg:.1} nats)"),
                None => v,
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.1} | {:.2e} | {g} | {sz} | {iv} | {v} |",
                c.round,
                c.rank,
                c.effect.name(),
                c.score,
                c.p_value
            );
        }
        for c in &res.law_candidates {
            let _ = writeln!(
                s,
                "| {} | - | {} (alternative law) | - | - | {:.1} | - | - | {} |",
                c.round, c.law, c.refit.evidence_gain, c.refit.verdict
            );
        }
        for (e, _, _) in &res.accepted {
            let _ = writeln!(s, "\n- {}: {}", e.name(), e.physics());
        }
        if !res.confounded.is_empty() {
            let _ = writeln!(
                s,
                "\n**Not identifiable from these data** (the law's parameters absorb them; R^2 of the effect's Jacobian column on the law's, src/closed_loop/confounding.rs):\n"
            );
            for c in &res.confounded {
                let _ = writeln!(s, "- {c}");
            }
        }
        if res.before.law != res.after.law {
            let _ = writeln!(
                s,
                "\n- the law {} was replaced by {}: not nested, so no score test; the whole model was refitted with the new law (started from its fit to the previous MAP's E*(w)) and won by the Laplace evidence gain above. Parameters below: the new law's after, the old law's (`{}.*`) before.",
                res.before.law, res.after.law, res.before.law
            );
        }
        let _ = writeln!(s, "\n| | before | after |\n|---|---|---|");
        let (b, a) = (&res.before.residuals, &res.after.residuals);
        let _ = writeln!(
            s,
            "| normalised chi-square | {:.3} | {:.3} |",
            b.chi2_normalised, a.chi2_normalised
        );
        let _ = writeln!(
            s,
            "| relative residual norm | {:.4} | {:.4} |",
            b.relative_norm, a.relative_norm
        );
        for (k, id) in ids.iter().enumerate() {
            let _ = writeln!(s, "| FRAC ch{id} | {:.5} | {:.5} |", b.frac[k], a.frac[k]);
        }
        let _ = writeln!(
            s,
            "\n| parameter | before +- sd | after +- sd | truth |\n|---|---|---|---|"
        );
        for pc in parameter_changes(res, truth.as_deref()) {
            let before = match (pc.before, pc.before_sd) {
                (Some(v), Some(sd)) => format!("{v:.5e} +- {sd:.2e}"),
                _ => String::new(),
            };
            let after = if pc.after.is_nan() {
                String::new()
            } else {
                format!("{:.5e} +- {:.2e}", pc.after, pc.after_sd)
            };
            let t = pc.truth.map_or(String::new(), |v| format!("{v:.5e}"));
            let _ = writeln!(s, "| {} | {before} | {after} | {t} |", pc.name);
        }
        let _ = writeln!(
            s,
            "\n![standardised residuals before and after](residuals_{level}.png)\n\n|z| per channel and line; under a correct model |z|^2 has mean 1."
        );
        signatures_markdown(&mut s, b, a);
        s.push('\n');
    }
    s
}

/// The residual signatures per resonance before and after (`closed_loop::signatures`): the
/// data's frequency and loss-factor change against the model, in sds, and the findings.
fn signatures_markdown(
    s: &mut String,
    b: &crate::closed_loop::Residuals,
    a: &crate::closed_loop::Residuals,
) {
    use std::fmt::Write as _;
    let (rb, ra) = (&b.signatures.resonances, &a.signatures.resonances);
    if rb.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\nResidual signatures per resonance (a local modal fit of the data against the model's own modal terms; z in sds of the data's noise):\n\n| resonance (Hz) | df/f before (z) | df/f after (z) | d(loss factor) before (z) | after (z) |\n|---|---|---|---|---|"
    );
    for r in rb {
        let after = ra
            .iter()
            .min_by(|x, y| {
                (x.freq_hz - r.freq_hz)
                    .abs()
                    .total_cmp(&(y.freq_hz - r.freq_hz).abs())
            })
            .filter(|x| (x.freq_hz - r.freq_hz).abs() < 0.05 * r.freq_hz);
        let (fa, la) = after.map_or(("-".to_string(), "-".to_string()), |x| {
            (
                format!("{:+.3} % ({:.1})", 100.0 * x.freq_shift, x.freq_z()),
                format!("{:+.2e} ({:.1})", x.loss_change, x.loss_z()),
            )
        });
        let _ = writeln!(
            s,
            "| {:.1} | {:+.3} % ({:.1}) | {fa} | {:+.2e} ({:.1}) | {la} |",
            r.freq_hz,
            100.0 * r.freq_shift,
            r.freq_z(),
            r.loss_change,
            r.loss_z()
        );
    }
    for (when, res) in [("before", b), ("after", a)] {
        let f = res.signatures.findings(5.0);
        if !f.is_empty() {
            let _ = writeln!(s, "\nSignatures beyond 5 sd {when}: {}.", f.join("; "));
        }
    }
}

/// The null level of the level's measurement chain ([`crate::closed_loop::null`]: replicate
/// Welch experiments of the fitted model through the declared estimator, else the noise
/// model's own errors), then the drop-one check and the verdict
/// ([`crate::closed_loop::conclude`]).
fn verdict_of(
    study: &Study,
    level: &super::LevelData,
    post: &mut crate::inference::likelihood::FrfPosterior<'_>,
    res: ClosedLoopResult,
    params: &ClosedLoopParams,
) -> Result<
    (
        ClosedLoopResult,
        crate::closed_loop::verdict::Verdict,
        crate::closed_loop::null::NullCalibration,
    ),
    RunError,
> {
    use crate::closed_loop::null::{calibrate, Chain, NullParams};
    let fail = |m: String| RunError::Analysis {
        analysis: format!("verdict of the closed loop at {}", level.name),
        message: m,
    };
    let est = study
        .measurements
        .as_ref()
        .and_then(|m| m.estimator.as_ref());
    let chain = match est {
        Some(e) => {
            let nb = (e.fs_hz * e.block_s).round() as usize;
            let n_d = match &post.likelihood.noise.scale {
                crate::inference::likelihood::Scale::Coherence { n_averages, .. } => *n_averages,
                _ => 0.0,
            };
            // Blocks: the file's count, else the count whose Welch equivalent is n_d.
            let blocks = level.n_averages.map(|n| n as usize).unwrap_or_else(|| {
                (1..=20_000)
                    .min_by(|&a, &b| {
                        let f = |n| {
                            (crate::experiment::estimator::effective_averages(
                                e.window,
                                nb,
                                nb / 2,
                                n,
                            ) - n_d)
                                .abs()
                        };
                        f(a).total_cmp(&f(b))
                    })
                    .unwrap_or(200)
            });
            let spec = super::posterior::estimator_spec(e, &level.freq_hz);
            let force = study
                .measurements
                .as_ref()
                .and_then(|m| m.levels.iter().find(|l| l.name == level.name))
                .and_then(|l| l.force_rms_n)
                .unwrap_or(1.0);
            Chain::Welch(Box::new(crate::experiment::ChainParams {
                force_rms_n: force,
                band_hz: spec.force_band_hz,
                fs_hz: e.fs_hz,
                block_s: e.block_s,
                n_averages: blocks,
                window: e.window,
                shaker: e.shaker,
                lines_hz: level.freq_hz.clone(),
                mode: crate::experiment::Mode::FrequencyDomain,
                ..Default::default()
            }))
        }
        None => Chain::NoiseModel,
    };
    params
        .progress
        .say(&format!("{}: null level of the residual", level.name));
    let np = NullParams {
        seed: study.seed,
        ..NullParams::default()
    };
    let null = calibrate(post, &res.after.values, &chain, &level.response_ids, &np)
        .map_err(|e| fail(e.to_string()))?;
    let vp = crate::closed_loop::verdict::VerdictParams {
        threshold_nats: params.threshold_nats,
        p_threshold: params.p_threshold,
        ..Default::default()
    };
    let (res, v) = crate::closed_loop::conclude::conclude(
        post,
        res,
        &null,
        &level.freq_hz,
        &level.response_ids,
        params,
        &vp,
    )
    .map_err(|e| fail(e.to_string()))?;
    Ok((res, v, null))
}

/// `verdict`: one row per level: the status, the null level and threshold, where the residual
/// is, the tentative, dropped and confounded effects, and the sentence of the report.
fn verdict_table(results: &[LevelResult], summary: &[DiagnoseLevel]) -> Result<Table, RunError> {
    let verdicts: Vec<&crate::closed_loop::verdict::Verdict> =
        summary.iter().map(|l| &l.verdict).collect();
    let mut t = Table::new("verdict");
    let lv: Vec<String> = results.iter().map(|r| r.0.clone()).collect();
    let st: Vec<String> = verdicts.iter().map(|v| v.status.to_string()).collect();
    let f = |g: &dyn Fn(&crate::closed_loop::verdict::Verdict) -> f64| -> Vec<f64> {
        verdicts.iter().map(|v| g(v)).collect()
    };
    let text = |g: &dyn Fn(&crate::closed_loop::verdict::Verdict) -> String| -> Vec<String> {
        verdicts.iter().map(|v| g(v)).collect()
    };
    let join = |v: Vec<String>| v.join("; ");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("status", st))
        .and_then(|t| t.push_f64("chi2_before", "1", f(&|v| v.chi2_before)))
        .and_then(|t| t.push_f64("chi2_after", "1", f(&|v| v.chi2_after)))
        .and_then(|t| t.push_f64("null_mean", "1", f(&|v| v.null_mean)))
        .and_then(|t| t.push_f64("null_sd", "1", f(&|v| v.null_sd)))
        .and_then(|t| t.push_f64("threshold", "1", f(&|v| v.threshold)))
        .and_then(|t| t.push_f64("false_alarm", "1", f(&|v| v.false_alarm)))
        .and_then(|t| t.push_f64("excess", "1", f(&|v| v.excess)))
        .and_then(|t| {
            t.push_str(
                "null_method",
                summary.iter().map(|s| s.null.method.clone()).collect(),
            )
        })
        .and_then(|t| {
            t.push_str(
                "worst_bands",
                text(&|v| {
                    join(
                        v.bands
                            .iter()
                            .map(|b| {
                                format!(
                                    "{:.0}-{:.0} Hz: {:.3}",
                                    b.lo_hz, b.hi_hz, b.chi2_normalised
                                )
                            })
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| {
            t.push_str(
                "channels",
                text(&|v| {
                    join(
                        v.channels
                            .iter()
                            .map(|c| {
                                format!(
                                    "ch{}: {:.3} (null {:.3})",
                                    c.id, c.chi2_normalised, c.null_mean
                                )
                            })
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| {
            t.push_str(
                "closest",
                text(&|v| {
                    join(
                        v.closest
                            .iter()
                            .map(|c| format!("{}: {:.2} nats", c.name, c.gain))
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| t.push_str("tentative", text(&|v| join(v.tentative.clone()))))
        .and_then(|t| {
            t.push_str(
                "dropped",
                text(&|v| {
                    join(
                        v.drop_one
                            .iter()
                            .filter(|d| !d.kept)
                            .map(|d| d.effect.clone())
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| {
            t.push_str(
                "left_out",
                text(&|v| join(v.not_needed.iter().map(|d| d.entry()).collect())),
            )
        })
        .and_then(|t| {
            t.push_str(
                "confounded",
                text(&|v| {
                    join(
                        v.confounded
                            .iter()
                            .map(|c| format!("{} (correlation {:.4})", c.effect, c.correlation))
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| t.push_str("sentence", text(&|v| v.sentence.clone())))
        .map_err(out_err)?;
    Ok(t)
}

/// `points` with, for every point, the two other axes' directions at the same position (same
/// id, after the declared points so that a point's id still names its measured direction).
fn with_all_directions(points: &[crate::study::Point]) -> Vec<crate::study::Point> {
    use crate::common::{Axis, Direction};
    let mut out = points.to_vec();
    for p in points {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            if !out.iter().any(|q| q.id == p.id && q.direction.axis == axis) {
                out.push(crate::study::Point {
                    direction: Direction::new(axis, 1),
                    ..p.clone()
                });
            }
        }
    }
    out
}

/// A sensor-mass candidate (x, y and z) at every measured point whose three directions are
/// engine inputs.
fn sensor_mass_candidates(
    points: &[crate::fe::ObservationPoint],
    inputs: &[usize],
    ids: &[u32],
) -> Vec<crate::forward::Effect> {
    use crate::common::Axis;
    ids.iter()
        .filter_map(|&id| {
            let at = |axis: Axis| {
                points
                    .iter()
                    .position(|p| p.id == id && p.direction.axis == axis)
                    .filter(|k| inputs.contains(k))
            };
            Some(crate::forward::Effect::SensorMass {
                points: [at(Axis::X)?, at(Axis::Y)?, at(Axis::Z)?],
                id,
            })
        })
        .collect()
}
