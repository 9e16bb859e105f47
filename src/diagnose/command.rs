//! `rfmlab diagnose`: a study's closed loop into a results folder of its own
//! (`<output_dir>.diagnose/`). The model, the data and the engine are built as a run builds
//! them, with every measured point an engine input (the point-mass candidates), then the stage
//! runs ([`super::loop_stage`]) and writes its tables, figures and markdown.
//!
//! These are the entry points of the CLI and the Python binding: they take the study, make the
//! stage's params from it ([`DiagnoseParams::of`]) and build the engine with the run's
//! functions ([`crate::stage::setup::setup`]).

use super::mesh;
use super::of_study::{no_inference, wants_sensor_mass, StudyPosterior};
use super::params::{DiagnoseParams, LoopInputs};
use super::summary::DiagnoseSummary;
use crate::closed_loop::{ClosedLoopParams, StartingFit};
use crate::output::{Manifest, Replace, ResultsDir};
use crate::stage::setup::{LevelGrid, Setup};
use crate::stage::RunError;
use crate::study::Study;
use std::path::Path;

/// Run the loop on `study` (model `model`, else the first of `[inference] models`); results in
/// `<output_dir>.diagnose/`.
pub fn diagnose_study(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
) -> Result<DiagnoseSummary, RunError> {
    let out = crate::stage::sibling(&study.output_dir, "diagnose");
    let parent = out.parent().unwrap_or(Path::new("."));
    let dir_name = out
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "diagnose".into());
    diagnose_into(study, model, params, parent, &dir_name, true)
}

/// [`diagnose_study`] into `<parent>/<dir_name>/`, with the residual figures when `figures`.
/// The folder is replaced as a whole when rfmlab wrote it, it is empty or absent; another is
/// refused before anything is computed ([`diagnose_into_as`] to force).
pub fn diagnose_into(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
    parent: &Path,
    dir_name: &str,
    figures: bool,
) -> Result<DiagnoseSummary, RunError> {
    diagnose_into_as(
        study,
        model,
        params,
        parent,
        dir_name,
        figures,
        Replace::IfOurs,
    )
}

/// [`diagnose_into`] under the output contract's choice `replace`
/// ([`crate::output::contract`]).
pub fn diagnose_into_as(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
    parent: &Path,
    dir_name: &str,
    figures: bool,
    replace: Replace,
) -> Result<DiagnoseSummary, RunError> {
    let t0 = std::time::Instant::now();
    let target = parent.join(dir_name);
    crate::output::claim_folder(&target, replace)?;
    if study.inference.is_none() {
        return Err(no_inference(study));
    }
    // The pre-flight before anything is built: the model asked for, a writable folder (the
    // data are checked as the model is set up).
    DiagnoseParams::of(study, model)?;
    crate::stage::preflight::check_settings(&study.models, &parent.join(dir_name), &study.file)?;
    let joint = crate::study::build::joint_spec(&study.structure).is_some();
    // A sensor's mass acts in x, y and z: when `[closed_loop] candidates` names the
    // sensor-mass candidate, the other two directions of every measured point of a meshed
    // joint become model points (and engine inputs) for it. This triples the engine's inputs
    // and its reduced basis (about 30 s to build and certify on the paper's joint, cached).
    let asked = joint && wants_sensor_mass(study);
    let defaults = super::candidates::default_candidates(study.closed_loop.as_ref());
    let (mut outcome, first) = loop_once(study, model, params, asked, &[], None, &[])?;
    // Every pass's steps for the manifest: the first pass's as they are, a later pass's
    // under its name.
    let mut steps = outcome.timings.clone();
    let mut add_steps = |pass: &str, o: &super::summary::LoopOutcome| {
        steps.extend(o.timings.iter().map(|(s, t)| (format!("{pass}: {s}"), *t)));
    };
    // Whether the later passes put every point's three directions in the model, and the
    // sections that say why a pass was run again (appended to the final pass's report).
    let mut three = asked;
    let mut sections = String::new();
    // With the default candidates the loop runs on the measured directions first; when it
    // accepts a point mass, it runs again with every point's x, y and z directions, so that the
    // three-direction sensor mass competes with the measured-direction one. A study whose
    // candidates leave the sensor mass out is not rerun.
    let admitted = study
        .closed_loop
        .as_ref()
        .is_none_or(|c| c.admits("sensor_mass", "sensor_mass"));
    let masses = accepted_of(&outcome, "point_mass");
    // Every point's three directions, not only the accepted masses' points: with the x and z
    // directions of one point only, the basis certified no better than 1.4e-6 after 527
    // vectors (250 s); with all twelve directions, 127 vectors certify at 8.3e-7 (30 s).
    // With base springs accepted too, the springs' term ROM on every point's three directions
    // (12 inputs) would cost several times more per line: the pass keeps the measured
    // directions as inputs, and the three-direction mass at each accepted mass's point joins
    // the springs' term ROM as a term of its own (`-w^2 m G`, its basis enriched with the full
    // model's responses with the mass on).
    let springs = accepted_of(&outcome, "base_springs");
    // The points (ids) whose three-direction mass is a term of the term ROM, in every later
    // pass.
    let mut sensor_terms: Vec<u32> = Vec::new();
    if joint && !asked && admitted && !masses.is_empty() {
        let on_springs = !springs.is_empty();
        params.progress.say(&format!(
            "{} accepted: a sensor's mass acts in x, y and z, so the loop runs again {}",
            masses.join(", "),
            if on_springs {
                "with the three-direction mass of those points as terms of the springs' reduced model"
            } else {
                "with every point's three directions"
            }
        ));
        // The two passes model the same data, so the one with the larger evidence (summed over
        // the levels) is kept.
        // Its starting MAP searches from the first pass's starting fit (the same model on
        // another basis), not from space-filling starts again; it keeps the first pass's
        // measurement grids, and what lies in the measured directions (its starting model,
        // the measured-direction candidates, the null level) is swept on the first pass's
        // basis (built for those points, a third of the cost per sweep).
        let ids = if on_springs {
            accepted_mass_points(&outcome)
        } else {
            Vec::new()
        };
        let (second, _) = if on_springs {
            // The same candidates (base springs among them), the measured directions.
            loop_once(
                study,
                model,
                params,
                false,
                &starting_fits(&outcome),
                Some(&first),
                &ids,
            )?
        } else {
            // Base springs left out (their term ROM on every point's three directions would
            // have 12 inputs).
            loop_once(
                &without_springs(study, defaults),
                model,
                params,
                true,
                &starting_fits(&outcome),
                Some(&first),
                &[],
            )?
        };
        add_steps("three directions", &second);
        // A difference within the evidences' rounding (1e-9 of their size) is none: the two
        // passes then end at the same model (the second sweeps the measured directions on
        // the first's basis), and the tie keeps the second pass, which tried the
        // three-direction masses too.
        let (second_ev, first_ev) = (final_evidence(&second), final_evidence(&outcome));
        let gain = match second_ev - first_ev {
            g if g.abs() <= 1e-9 * (second_ev.abs() + first_ev.abs()) => 0.0,
            g => g,
        };
        let keep_second = !(gain < 0.0);
        params.progress.say(&format!(
            "three directions: evidence {gain:+.1} nats against the first pass: {}",
            if keep_second {
                "the second pass is kept"
            } else {
                "the first pass is kept"
            }
        ));
        let how = if on_springs {
            format!(
                "together with {}. A sensor's mass acts in x, y and z, so the loop ran again with the three-direction mass of {} (`mass3_ptN`) among the candidates: a term of the springs' reduced model (`-w^2 m` times the point's x, y and z mass matrix, its basis enriched with the full model's responses with the mass on; the springs' reduced model with every point's three directions as inputs would cost several times more per line), in place of the measured-direction mass there",
                springs.join(", "),
                if ids.len() == 1 { "that point" } else { "those points" }
            )
        } else {
            "A sensor's mass acts in x, y and z, so the loop ran again with every measured point's x, y and z directions in the model and the three-direction sensor masses (`mass3_ptN`) among the candidates (base springs left out: their reduced model on twelve inputs costs too much)".to_string()
        };
        sections += &format!(
            "\n## Three directions\n\nA first pass on the measured directions accepted {}{}{how}. The two passes explain the same data; the second's final model has {gain:+.1} nats of evidence against the first's (summed over the levels), so {}.\n",
            masses.join(", "),
            if on_springs { " " } else { ". " },
            if keep_second {
                "the results above are the second pass's"
            } else {
                "the results above are the first pass's"
            }
        );
        if keep_second {
            outcome = second;
            // The later passes keep the three directions (or the sensor terms) only when a
            // three-direction mass was accepted.
            let kept = !accepted_of(&outcome, "sensor_mass").is_empty();
            if on_springs {
                if kept {
                    sensor_terms = ids;
                }
            } else {
                three = kept;
            }
        }
    }
    // The first pass's engines are not needed further.
    drop(first);
    // The FE model's own discretisation error: a level left unexplained is tried on the mesh
    // refined twice per direction (module `mesh`); when it gains the loop's evidence threshold
    // at the starting fit, the loop runs again there and that pass is reported.
    let mut mesh_comparison = None;
    let mesh_admitted = study
        .closed_loop
        .as_ref()
        .is_none_or(|c| c.admits(mesh::DISCRETISATION, mesh::DISCRETISATION));
    let allowance = study.closed_loop.as_ref().is_some_and(|c| c.mesh_allowance);
    let unexplained = unexplained_levels(&outcome);
    // Only a level left unexplained lets the refined mesh replace the study's; a mesh allowance
    // alone compares the meshes.
    let for_residual = mesh_admitted && !unexplained.is_empty();
    if allowance || for_residual {
        if let Some((structure, words)) = joint
            .then(|| mesh::refined_twice(&study.structure))
            .flatten()
        {
            params.progress.say(&format!(
                "{}: the model on its mesh refined twice per direction ({words})",
                if unexplained.is_empty() {
                    "mesh allowance".to_string()
                } else {
                    format!("{} unexplained", unexplained.join(", "))
                }
            ));
            let mut fine = study.clone();
            fine.structure = structure;
            // The starting fit only (no rounds): the same parameters on both meshes. It has no
            // effects, so the measured directions suffice (a refined mesh with every point's
            // three directions would need a 12-input basis on 8 times the DOFs).
            let start_only = ClosedLoopParams {
                max_rounds: 0,
                ..params.clone()
            };
            // No candidates are tried there, so none with matrices of their own is built (a
            // term ROM on the refined mesh's 8 times the DOFs).
            // Its MAP searches from the study mesh's starting fit (the same parameters, a
            // little off), and the rerun's from the refined mesh's.
            let cmp = match loop_once(
                &without_springs(&fine, true),
                model,
                &start_only,
                false,
                &starting_fits(&outcome),
                None,
                &[],
            ) {
                Ok((start, _)) => {
                    add_steps("refined mesh, starting fit", &start);
                    let cmp =
                        mesh::compare(&outcome, &start, words, params.threshold_nats, for_residual);
                    params.progress.say(&format!(
                        "refined mesh: evidence gain {:.1} nats at the starting fit (threshold {:.1}): {}",
                        cmp.gain,
                        cmp.threshold,
                        if cmp.accepted {
                            "the study's mesh was too coarse; the loop runs again on the refined mesh".to_string()
                        } else if cmp.behind_the_effects() {
                            format!(
                                "{:.1} nats behind the accepted effects: the mesh does not explain the residual",
                                -cmp.gain_over_effects
                            )
                        } else {
                            "the mesh does not explain the residual".to_string()
                        }
                    ));
                    if cmp.accepted {
                        // On the refined mesh the candidates with matrices of their own are
                        // kept only when the study mesh's pass accepted one (a term ROM on 8
                        // times the DOFs; a kept three-direction pass has none).
                        let rerun = if !accepted_of(&outcome, "base_springs").is_empty() {
                            fine.clone()
                        } else {
                            without_springs(&fine, defaults)
                        };
                        let (mut refined, _) = loop_once(
                            &rerun,
                            model,
                            params,
                            three,
                            &starting_fits(&start),
                            None,
                            &sensor_terms,
                        )?;
                        add_steps("refined mesh", &refined);
                        mesh::name_in(&mut refined, &cmp, mesh::element_size(&fine.structure));
                        outcome = refined;
                    }
                    cmp
                }
                // A refined mesh beyond the machine, or one its solver cannot resolve, leaves
                // the study mesh's results, with the reason in the report.
                Err(e) => {
                    mesh::not_evaluated(words, params.threshold_nats, for_residual, e.to_string())
                }
            };
            sections += &mesh::section(&cmp);
            mesh_comparison = Some(cmp);
        }
    }
    if let Some(cmp) = mesh_comparison
        .as_ref()
        .filter(|c| allowance && c.failed.is_none())
    {
        sections += &mesh::apply_allowance(&mut outcome, cmp, mesh::order(&study.structure));
    }
    outcome.markdown += &sections;
    outcome.mesh = mesh_comparison;
    let t_write = std::time::Instant::now();
    // The folder is filled as a temporary sibling and swapped in whole, with a manifest that
    // marks it as rfmlab's.
    crate::output::replace_dir_as(&target, replace, |tmp| {
        let tmp_parent = tmp.parent().map(Path::to_path_buf).unwrap_or_default();
        let tmp_name = tmp
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut dir = ResultsDir::create(tmp_parent, &tmp_name).map_err(RunError::Output)?;
        super::write_loop(&mut dir, &outcome, &study.name, figures)?;
        let mut manifest = Manifest::new(&study.file, Some(study.seed));
        // The parts first, indented, then the whole (as `rfmlab run` lists a step's parts).
        for (step, seconds) in &steps {
            manifest.add_timing(format!("  {step}"), *seconds);
        }
        manifest.add_timing("  write results", t_write.elapsed().as_secs_f64());
        manifest.add_timing("closed loop", t0.elapsed().as_secs_f64());
        dir.write_manifest(&mut manifest)
            .map_err(RunError::Output)?;
        Ok::<_, RunError>(())
    })?;
    outcome.summary.output_dir = target;
    outcome.summary.seconds = t0.elapsed().as_secs_f64();
    Ok(outcome.summary)
}

/// The effects of type `kind` accepted in `outcome`, as "name at level".
fn accepted_of(outcome: &super::summary::LoopOutcome, kind: &str) -> Vec<String> {
    outcome
        .summary
        .levels
        .iter()
        .flat_map(|l| {
            l.accepted
                .iter()
                .filter(|a| a.1 == kind)
                .map(move |a| format!("{} at {}", a.0, l.level))
        })
        .collect()
}

/// The final models' log evidence of `outcome`, summed over its levels (NaN when one is not
/// finite).
fn final_evidence(outcome: &super::summary::LoopOutcome) -> f64 {
    outcome.levels.iter().map(|l| l.3.after.log_evidence).sum()
}

/// The levels of `outcome` whose status is `unexplained`.
fn unexplained_levels(outcome: &super::summary::LoopOutcome) -> Vec<String> {
    outcome
        .summary
        .levels
        .iter()
        .filter(|l| l.verdict.status == crate::closed_loop::verdict::Status::Unexplained)
        .map(|l| l.level.clone())
        .collect()
}

/// `study` with the default candidates less base springs (the three-direction sensor mass and
/// the refined mesh kept) when `defaults`; as it is otherwise.
fn without_springs(study: &Study, defaults: bool) -> Study {
    let mut out = study.clone();
    if defaults {
        let mut types: Vec<String> = crate::study::effects::EFFECT_TYPES
            .iter()
            .filter(|t| !matches!(**t, "degraded_bond" | "adherend_damping" | "base_springs"))
            .map(|t| t.to_string())
            .collect();
        types.push(crate::closed_loop::alternative::ALTERNATIVE_LAW.to_string());
        types.push("sensor_mass".to_string());
        types.push(mesh::DISCRETISATION.to_string());
        let mut settings = out.closed_loop.clone().unwrap_or_default();
        settings.candidates = Some(types);
        out.closed_loop = Some(settings);
    }
    out
}

/// The ids of the points where `outcome` accepted a point mass (at any level), in order.
fn accepted_mass_points(outcome: &super::summary::LoopOutcome) -> Vec<u32> {
    let mut ids = Vec::new();
    for l in &outcome.levels {
        for (e, _, _) in &l.3.accepted {
            if let crate::forward::Effect::PointMass { id, .. } = e {
                if !ids.contains(id) {
                    ids.push(*id);
                }
            }
        }
    }
    ids
}

/// Set up the study's model, data and engines (with every measured point's x, y and z
/// directions when `all_directions`) and run the loop, with the three-direction masses of the
/// points `sensor_terms` as terms of the term ROM ([`super::TermParams::sensor_masses`]). With
/// the setup of an `earlier` pass on the same structure and data (the measured directions'
/// pass), its measurement grids are kept and its engine sweeps what lies in the measured
/// directions ([`super::directions::ThreeDirections`]). The outcome's timings start with the
/// setup's (`engine`); the setup is returned beside it (a later pass may build on it).
fn loop_once(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
    all_directions: bool,
    starting_fits: &[StartingFit],
    earlier: Option<&Setup>,
    sensor_terms: &[u32],
) -> Result<(super::summary::LoopOutcome, Setup), RunError> {
    let mut with_loop = study.clone();
    if all_directions {
        with_loop.structure.points =
            crate::study::build::points_in_all_directions(&with_loop.structure.points);
    }
    let study = &with_loop;
    let t_engine = std::time::Instant::now();
    let n_points = study.structure.points.len();
    params.progress.say(&format!(
        "building the model and its certified reduced basis ({n_points} point directions; cached after the first run)"
    ));
    // An earlier pass's measurement grids: the same structure and data (choosing them again
    // on the twelve-input basis cost 3 s).
    let grids: Vec<LevelGrid> = earlier.map_or_else(Vec::new, |e| {
        e.levels
            .iter()
            .filter_map(|l| l.measurement.clone().map(|m| (l.name.clone(), m)))
            .collect()
    });
    let setup = crate::stage::setup::setup_with_grids(
        study,
        // The loop's candidate masses act at every measured point.
        Some(crate::stage::engine::LikelihoodInputs::EveryMeasuredPoint),
        // The certified ROM is cached beside the results, as `rfmlab run` caches it.
        Some(&crate::stage::rom_cache_dir(&study.output_dir)),
        &grids,
    )?;
    if starting_fits.is_empty() {
        for w in &setup.warnings {
            params.progress.say(&format!("warning: {w}"));
        }
    }
    let engine = setup
        .engines
        .likelihood
        .as_deref()
        .unwrap_or(setup.engines.engine.as_ref());
    params.progress.say(&setup.engines.note);
    // The measured directions on the earlier pass's engine.
    let on_earlier = earlier.and_then(|e| {
        super::directions::ThreeDirections::new(
            engine,
            &setup.built.model.points,
            e.engines
                .likelihood
                .as_deref()
                .unwrap_or(e.engines.engine.as_ref()),
            &e.built.model.points,
        )
    });
    let engine: &dyn crate::frf::FrfEngine = match &on_earlier {
        Some(t) => t,
        None => engine,
    };
    let mut p = DiagnoseParams::of(study, model)?;
    p.terms.sensor_masses = sensor_terms.to_vec();
    let inputs = LoopInputs {
        built: &setup.built,
        levels: &setup.levels,
        laws: &setup.laws,
        engine,
        posterior: &StudyPosterior(study),
        starting_fits,
    };
    let engine_seconds = t_engine.elapsed().as_secs_f64();
    let mut outcome = super::loop_stage(&p, params, &inputs)?;
    outcome.timings.insert(0, ("engine".into(), engine_seconds));
    drop(on_earlier);
    Ok((outcome, setup))
}

/// The starting fit of every level of `outcome` (see [`LoopInputs::starting_fits`]).
fn starting_fits(outcome: &super::summary::LoopOutcome) -> Vec<StartingFit> {
    outcome
        .levels
        .iter()
        .map(|l| StartingFit {
            level: l.0.clone(),
            names: l.3.before.names.clone(),
            values: l.3.before.values.clone(),
        })
        .collect()
}
