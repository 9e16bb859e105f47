//! The discretisation candidate: the FE model's own mesh error as a model-form effect.
//!
//! A mesh that is too coarse makes the joint too stiff: every mode sits a little high, and the
//! loop's effects (a beam modulus factor, a channel's gain or delay) cannot take that shape, so
//! the level ends `unexplained` with tentative effects that are not there. The candidate
//! re-evaluates the study's model on its mesh refined twice per direction (element size halved,
//! or every division doubled) and compares the Laplace evidence at the starting model, without
//! effects, on both meshes: the same parameters, so the gain needs no Occam factor of its own.
//! When the gain reaches the loop's threshold, the loop runs again on the refined mesh and its
//! results replace the study mesh's; the report says the mesh was too coarse and gives the
//! adhesive's parameters on both meshes. Otherwise the study mesh's results stand and the report
//! says how much the refinement changed.

use super::summary::{DiagnoseLevel, LevelResult, LoopOutcome};
use crate::closed_loop::verdict::Status;
use crate::output::Table;
use crate::stage::RunError;
use crate::study::{MeshSize, Structure, StructureSource};
use std::fmt::Write as _;

/// The effect type and name of the candidate (`[closed_loop] candidates`).
pub const DISCRETISATION: &str = "discretisation";

/// `structure` on its mesh refined twice per direction, and the two meshes in words; `None`
/// for a structure the mesher does not build (imported matrices, lap joints).
pub(crate) fn refined_twice(structure: &Structure) -> Option<(Structure, String)> {
    let StructureSource::Mesher(j) = &structure.source else {
        return None;
    };
    let mut fine = j.clone();
    let words = match j.mesh {
        MeshSize::ElementSize(h) => {
            fine.mesh = MeshSize::ElementSize(0.5 * h);
            format!("element size {:.3} mm -> {:.3} mm", 1e3 * h, 0.5 * 1e3 * h)
        }
        MeshSize::Divisions {
            x_adhesive,
            x_outside,
            y_beam,
            y_adhesive,
            z,
        } => {
            fine.mesh = MeshSize::Divisions {
                x_adhesive: 2 * x_adhesive,
                x_outside: 2 * x_outside,
                y_beam: 2 * y_beam,
                y_adhesive: 2 * y_adhesive,
                z: 2 * z,
            };
            format!(
                "divisions (x_adhesive, x_outside, y_beam, y_adhesive, z) ({x_adhesive}, {x_outside}, {y_beam}, {y_adhesive}, {z}) -> ({}, {}, {}, {}, {})",
                2 * x_adhesive,
                2 * x_outside,
                2 * y_beam,
                2 * y_adhesive,
                2 * z
            )
        }
    };
    Some((
        Structure {
            source: StructureSource::Mesher(fine),
            ..structure.clone()
        },
        words,
    ))
}

/// One level on the two meshes, at the starting model (no effects).
#[derive(Clone, Debug)]
pub struct MeshLevel {
    pub level: String,
    pub log_evidence_coarse: f64,
    pub log_evidence_refined: f64,
    pub chi2_coarse: f64,
    pub chi2_refined: f64,
    /// The law's parameters: name, value and sd on the study's mesh, then on the refined one.
    pub law: Vec<(String, f64, f64, f64, f64)>,
}

/// What the discretisation candidate found.
#[derive(Clone, Debug)]
pub struct MeshComparison {
    /// The two meshes in words.
    pub meshes: String,
    pub levels: Vec<MeshLevel>,
    /// The evidence gain of the refined mesh over the study's, summed over the levels (nats).
    pub gain: f64,
    /// The refined mesh's starting model against the study mesh's final model (with the
    /// effects its loop accepted), summed over the levels (nats): the refined mesh explains the
    /// residual only when it is not behind the effects (it is when a large effect's shape is
    /// partly a softer joint's, which a finer mesh imitates).
    pub gain_over_effects: f64,
    pub threshold: f64,
    /// The refined mesh explains the residual: its loop's results are reported.
    pub accepted: bool,
    /// Why the refined mesh could not be evaluated (then `levels` is empty).
    pub failed: Option<String>,
    /// Tried because a level stayed unexplained (else for the mesh allowance alone).
    pub for_residual: bool,
}

impl MeshComparison {
    /// The refined mesh gained the threshold at the starting fit but stayed behind the study
    /// mesh's model with the accepted effects, so it was not taken.
    pub fn behind_the_effects(&self) -> bool {
        self.gain >= self.threshold && self.gain_over_effects < 0.0
    }
}

/// Compare the starting fits of `coarse` and of `refined` (the same levels, the loop run on
/// the refined mesh, or only its start). The refined mesh is accepted when it was tried for the
/// residual (`for_residual`), gains at least `threshold` and its starting model is not behind
/// the study mesh's final model with the effects its loop accepted (`gain_over_effects`).
pub(crate) fn compare(
    coarse: &LoopOutcome,
    refined: &LoopOutcome,
    meshes: String,
    threshold: f64,
    for_residual: bool,
) -> MeshComparison {
    let levels: Vec<MeshLevel> = coarse
        .levels
        .iter()
        .zip(&refined.levels)
        .map(|(c, r)| {
            let (a, b) = (&c.3.before, &r.3.before);
            MeshLevel {
                level: c.0.clone(),
                log_evidence_coarse: a.log_evidence,
                log_evidence_refined: b.log_evidence,
                chi2_coarse: a.residuals.chi2_normalised,
                chi2_refined: b.residuals.chi2_normalised,
                law: (0..a.n_law.min(b.n_law))
                    .map(|i| {
                        (
                            a.names[i].clone(),
                            a.values[i],
                            a.sd[i],
                            b.values[i],
                            b.sd[i],
                        )
                    })
                    .collect(),
            }
        })
        .collect();
    let gain = levels
        .iter()
        .map(|l| l.log_evidence_refined - l.log_evidence_coarse)
        .sum::<f64>();
    let gain_over_effects = coarse
        .levels
        .iter()
        .zip(&refined.levels)
        .map(|(c, r)| r.3.before.log_evidence - c.3.after.log_evidence)
        .sum::<f64>();
    MeshComparison {
        meshes,
        gain,
        gain_over_effects,
        threshold,
        accepted: for_residual
            && gain.is_finite()
            && gain >= threshold
            && gain_over_effects.is_finite()
            && gain_over_effects >= 0.0,
        levels,
        failed: None,
        for_residual,
    }
}

/// A comparison that could not be made: the refined mesh failed with `why` (beyond the machine,
/// or a solver that cannot resolve it).
pub(crate) fn not_evaluated(
    meshes: String,
    threshold: f64,
    for_residual: bool,
    why: String,
) -> MeshComparison {
    MeshComparison {
        meshes,
        levels: Vec::new(),
        gain: f64::NAN,
        gain_over_effects: f64::NAN,
        threshold,
        accepted: false,
        failed: Some(why),
        for_residual,
    }
}

/// Name the refined mesh among the accepted effects of every level of `outcome` (the refined
/// mesh's loop): first in each level's list, with the refined element size as its size; a
/// level that needed nothing else is `explained` now.
pub(crate) fn name_in(outcome: &mut LoopOutcome, cmp: &MeshComparison, refined_size_m: f64) {
    for ((l, r), m) in per_level(outcome, cmp) {
        l.accepted.insert(
            0,
            (
                DISCRETISATION.to_string(),
                DISCRETISATION.to_string(),
                refined_size_m,
                0.0,
            ),
        );
        let words = format!(
            "the study's mesh was too coarse: refined twice per direction ({}), the starting model gains {:.1} nats (normalised chi-square {:.3} -> {:.3})",
            cmp.meshes,
            m.log_evidence_refined - m.log_evidence_coarse,
            m.chi2_coarse,
            m.chi2_refined
        );
        l.conclusion = format!("{words}; {}", l.conclusion);
        r.3.conclusion = format!("{words}; {}", r.3.conclusion);
        if l.verdict.status == Status::NothingMissing {
            l.verdict.status = Status::Explained;
            l.status = Status::Explained.to_string();
            l.verdict.sentence = format!("explained by the mesh: {words}");
        } else {
            l.verdict.sentence = format!("{}; {words}", l.verdict.sentence);
        }
    }
    outcome.remake_markdown();
}

/// Every level of `outcome`: its summary, its result and its comparison in `cmp`.
fn per_level<'a>(
    outcome: &'a mut LoopOutcome,
    cmp: &'a MeshComparison,
) -> impl Iterator<Item = ((&'a mut DiagnoseLevel, &'a mut LevelResult), &'a MeshLevel)> {
    outcome
        .summary
        .levels
        .iter_mut()
        .zip(outcome.levels.iter_mut())
        .zip(&cmp.levels)
}

/// The refined mesh's element size (m), or NaN for a mesh given by divisions.
pub(crate) fn element_size(structure: &Structure) -> f64 {
    match &structure.source {
        StructureSource::Mesher(j) => match j.mesh {
            MeshSize::ElementSize(h) => h,
            MeshSize::Divisions { .. } => f64::NAN,
        },
        _ => f64::NAN,
    }
}

/// The report's section on the candidate.
pub(crate) fn section(cmp: &MeshComparison) -> String {
    let mut s = String::from("\n## Mesh refinement\n\n");
    let why_tried = if cmp.for_residual {
        "The residual stayed above the null level, so the loop tried the FE model's own discretisation error"
    } else {
        "The study asks for a mesh allowance (`[closed_loop] mesh_allowance`), so the loop compared two meshes"
    };
    if let Some(why) = &cmp.failed {
        let _ = writeln!(
            s,
            "{why_tried}: the mesh refined twice per direction ({}) could not be evaluated: {why}. The mesh's discretisation error is not ruled out.",
            cmp.meshes
        );
        return s;
    }
    if cmp.accepted {
        let _ = writeln!(
            s,
            "The residual stayed above the null level on the study's mesh. The same model on the mesh refined twice per direction ({}) gains {:.1} nats of evidence at the starting fit (threshold {:.1}): **the study's mesh was too coarse**. The loop ran again on the refined mesh; the results above are that pass's, and `discretisation` is named among the accepted effects. Refine the study's mesh (`[structure.mesh]`) for later runs.\n",
            cmp.meshes, cmp.gain, cmp.threshold
        );
    } else if cmp.for_residual && cmp.behind_the_effects() {
        let _ = writeln!(
            s,
            "{why_tried}: the same model on the mesh refined twice per direction ({}) gains {:.1} nats of evidence at the starting fit (threshold {:.1}), but it stays {:.1} nats behind the study mesh's model with the effects the loop accepted: a finer mesh is a softer joint and takes up part of those effects' shape, so **the mesh does not explain the residual**. The results above are the study mesh's. The change of the adhesive's parameters below is not a discretisation uncertainty: the starting fits on both meshes lack the effects.\n",
            cmp.meshes,
            cmp.gain,
            cmp.threshold,
            -cmp.gain_over_effects
        );
    } else {
        let _ = writeln!(
            s,
            "{why_tried}: the same model on the mesh refined twice per direction ({}) changes the evidence at the starting fit by {:+.1} nats (threshold {:.1}).{} The results above are the study mesh's. The change of the adhesive's parameters below measures their discretisation uncertainty on the study's mesh.\n",
            cmp.meshes,
            cmp.gain,
            cmp.threshold,
            if cmp.for_residual {
                " The mesh does not explain the residual."
            } else {
                ""
            }
        );
    }
    let _ = writeln!(
        s,
        "| level | parameter | study mesh | refined mesh | change | change / sd |\n|---|---|---|---|---|---|"
    );
    for l in &cmp.levels {
        let _ = writeln!(
            s,
            "| {} | log evidence | {:.1} | {:.1} | {:+.1} | |",
            l.level,
            l.log_evidence_coarse,
            l.log_evidence_refined,
            l.log_evidence_refined - l.log_evidence_coarse
        );
        let _ = writeln!(
            s,
            "| {} | normalised chi-square | {:.3} | {:.3} | {:+.3} | |",
            l.level,
            l.chi2_coarse,
            l.chi2_refined,
            l.chi2_refined - l.chi2_coarse
        );
        for (n, a, sa, b, sb) in &l.law {
            let _ = writeln!(
                s,
                "| {} | {n} | {a:.5e} +- {sa:.2e} | {b:.5e} +- {sb:.2e} | {:+.3} % | {:+.1} |",
                l.level,
                100.0 * (b - a) / a,
                (b - a) / sa.max(*sb)
            );
        }
    }
    s
}

/// `mesh`: one row per level and parameter (the log evidence and the normalised chi-square
/// first): the value on the study's mesh and on the refined one, whether the refined mesh was
/// accepted.
pub(crate) fn table(cmp: &MeshComparison) -> Result<Table, RunError> {
    let (mut lv, mut q, mut a, mut sa, mut b, mut sb, mut acc) = (
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
    );
    for l in &cmp.levels {
        let rows = [
            (
                "log_evidence".to_string(),
                l.log_evidence_coarse,
                None,
                l.log_evidence_refined,
                None,
            ),
            (
                "chi2_normalised".to_string(),
                l.chi2_coarse,
                None,
                l.chi2_refined,
                None,
            ),
        ];
        let law = l
            .law
            .iter()
            .map(|(n, x, sx, y, sy)| (n.clone(), *x, Some(*sx), *y, Some(*sy)));
        for (n, x, sx, y, sy) in rows.into_iter().chain(law) {
            lv.push(l.level.clone());
            q.push(n);
            a.push(x);
            sa.push(sx);
            b.push(y);
            sb.push(sy);
            acc.push(cmp.accepted);
        }
    }
    let mut t = Table::new("mesh");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("quantity", q))
        .and_then(|t| t.push_f64("study_mesh", "SI", a))
        .and_then(|t| t.push_opt_f64("study_mesh_sd", "SI", sa))
        .and_then(|t| t.push_f64("refined_mesh", "SI", b))
        .and_then(|t| t.push_opt_f64("refined_mesh_sd", "SI", sb))
        .and_then(|t| t.push_bool("refined_accepted", acc))
        .map_err(RunError::Output)?;
    Ok(t)
}

/// The Richardson order the loop's discretisation candidate assumes between the study's mesh
/// and the mesh refined twice per direction: 2 when the cells are no larger than the bond
/// line's thickness in its plane (the pre-asymptotic range those two meshes are in: the paper's
/// block 10 -> 5 -> 2.5 mm converges at an observed 2.1), else 1.
pub(crate) fn order(structure: &Structure) -> f64 {
    let StructureSource::Mesher(j) = &structure.source else {
        return 1.0;
    };
    let cell = match j.mesh {
        MeshSize::ElementSize(h) => h,
        MeshSize::Divisions { x_adhesive, z, .. } => {
            (j.adhesive_length_m / x_adhesive as f64).max(j.beam_width_m / z as f64)
        }
    };
    if cell > j.adhesive_thickness_m * (1.0 + 1e-9) {
        1.0
    } else {
        2.0
    }
}

/// The mesh allowance (`[closed_loop] mesh_allowance`): every law parameter's sd in `outcome`
/// becomes sqrt(sd^2 + b^2), with b its discretisation error on the mesh `outcome` was
/// identified on. From the starting fits on both meshes (difference d, Richardson order p):
/// b = |d| 2^p / (2^p - 1) on the study's mesh, |d| / (2^p - 1) on the refined one. Returns the
/// report's paragraph and table.
pub(crate) fn apply_allowance(outcome: &mut LoopOutcome, cmp: &MeshComparison, p: f64) -> String {
    let g = 2f64.powf(p);
    let factor = if cmp.accepted {
        1.0 / (g - 1.0)
    } else {
        g / (g - 1.0)
    };
    let mut s = format!(
        "\n### Mesh allowance\n\n`mesh_allowance = true`: the adhesive's parameters carry the discretisation error of the mesh they were identified on ({}), estimated from their starting fits on both meshes (difference d, Richardson order {p}): b = |d| x {factor:.3}. Their sds above are sqrt(sd^2 + b^2).\n\n| level | parameter | value | posterior sd | discretisation b | sd with the allowance |\n|---|---|---|---|---|---|\n",
        if cmp.accepted { "the refined mesh" } else { "the study's mesh" }
    );
    for ((l, r), m) in per_level(outcome, cmp) {
        for (name, a, _, b, _) in &m.law {
            let bias = factor * (b - a).abs();
            let fit = &mut r.3.after;
            let Some(i) = fit.names[..fit.n_law].iter().position(|n| n == name) else {
                continue;
            };
            let sd = fit.sd[i];
            let wide = sd.hypot(bias);
            fit.sd[i] = wide;
            if let Some(c) = l.parameters.iter_mut().find(|c| &c.name == name) {
                c.after_sd = wide;
            }
            let _ = writeln!(
                s,
                "| {} | {name} | {:.5e} | {sd:.2e} | {bias:.2e} | {wide:.2e} |",
                l.level, fit.values[i]
            );
        }
    }
    outcome.remake_markdown();
    s
}
