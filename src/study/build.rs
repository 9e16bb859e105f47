//! Study -> structural model: the mesher's [`JointSpec`] from the validated structure section,
//! or the imported model (Matrix Market, Harwell-Boeing or Abaqus files).

use super::{MeshSize, Structure, StructureSource, StudyError};
use crate::fe::joint::{
    AdherendDamping, Divisions, IsoMaterial, JointGeometry, JointSpec, MeshInfo, MeshParams,
    PointSpec,
};
use crate::fe::points::PointMapping;
use crate::fe::StructuralModel;

/// The mesher's input for a validated structure section (None for imported models).
pub fn joint_spec(s: &Structure) -> Option<JointSpec> {
    let StructureSource::Mesher(j) = &s.source else {
        return None;
    };
    Some(JointSpec {
        geometry: JointGeometry {
            beam_length_m: j.beam_length_m,
            beam_thickness_m: j.beam_thickness_m,
            beam_width_m: j.beam_width_m,
            adhesive_length_m: j.adhesive_length_m,
            adhesive_thickness_m: j.adhesive_thickness_m,
            adhesive_x_start_m: j.adhesive_x_start_m,
        },
        beam: IsoMaterial {
            e_pa: j.beam_e_pa,
            nu: j.beam_nu,
            rho_kg_m3: j.beam_rho_kg_m3,
        },
        adhesive_nu: j.adhesive_nu,
        adhesive_rho_kg_m3: j.adhesive_rho_kg_m3,
        damping: AdherendDamping {
            rayleigh_alpha_per_s: j.damping.rayleigh_alpha_per_s,
            rayleigh_beta_s: j.damping.rayleigh_beta_s,
            structural_loss_factor: j.damping.structural_loss_factor,
        },
        mesh: MeshParams {
            size: match j.mesh {
                MeshSize::ElementSize(h) => crate::fe::joint::MeshSize::ElementSize(h),
                MeshSize::Divisions {
                    x_adhesive,
                    x_outside,
                    y_beam,
                    y_adhesive,
                    z,
                } => crate::fe::joint::MeshSize::Divisions(Divisions {
                    x_adhesive,
                    x_outside,
                    y_beam,
                    y_adhesive,
                    z,
                }),
            },
            grading: j.mesh_grading,
            edge_m: None,
            integration: if j.full_integration {
                crate::fe::element::Integration::Full
            } else {
                crate::fe::element::Integration::Reduced
            },
            point_mapping: if j.snap_points {
                PointMapping::Snap
            } else {
                PointMapping::Interpolate
            },
        },
        points: point_specs(s),
    })
}

/// The mesher's points of a study's structure.
pub fn point_specs(s: &Structure) -> Vec<PointSpec> {
    s.points
        .iter()
        .map(|p| PointSpec {
            id: p.id,
            position_m: p.position_m,
            direction: p.direction,
        })
        .collect()
}

/// A built model and, for meshed models, its size and timing.
pub struct BuiltModel {
    pub model: StructuralModel,
    pub mesh: Option<MeshInfo>,
    /// Index (into `model.points`) of the excitation point.
    pub excitation: usize,
    /// Axis (0 x, 1 y, 2 z) of each free DOF, for meshed models (the mesher numbers free
    /// DOFs node-major, three per free node).
    pub dof_axes: Option<Vec<u8>>,
    /// How the mesher's joint was discretised and the error it leaves (meshed joints only;
    /// [`crate::discretisation`]).
    pub discretisation: Option<crate::discretisation::Discretisation>,
}

/// The mesher's input of the mesh a study's joint is built on: the refined one of
/// `structure.mesh.refine` ([`crate::discretisation::select`], run once per process), else the
/// study's (None for imported models and lap joints).
pub fn chosen_spec(s: &Structure, file: &str) -> Result<Option<JointSpec>, StudyError> {
    let (Some(spec), StructureSource::Mesher(j)) = (joint_spec(s), &s.source) else {
        return Ok(None);
    };
    if !j.mesh_rule.refine {
        return Ok(Some(spec));
    }
    let chosen = crate::discretisation::select_spec(&spec, &refine_params(&j.mesh_rule), &|_| {})
        .map_err(|e| fe_error(file, e))?;
    Ok(Some(chosen))
}

fn refine_params(rule: &super::MeshRule) -> crate::discretisation::RefineParams {
    crate::discretisation::RefineParams {
        tolerance: rule.tolerance,
        allowance: rule.allowance,
        reference_modulus_pa: rule.reference_modulus_pa,
    }
}

/// A mesher's joint built by its mesh rule: refined to the tolerance, or as given with the
/// estimate of its error when the allowance asks for it; the model corrected by the allowance.
fn meshed<S: crate::discretisation::Meshed>(
    spec: &S,
    rule: &super::MeshRule,
    file: &str,
    progress: &dyn Fn(&str),
) -> Result<
    (
        StructuralModel,
        MeshInfo,
        Option<crate::discretisation::Discretisation>,
    ),
    StudyError,
> {
    let p = refine_params(rule);
    if rule.refine {
        let r = crate::discretisation::select(spec, &p, progress).map_err(|e| fe_error(file, e))?;
        return Ok((r.model, r.info, Some(r.discretisation)));
    }
    let (mut m, info) = spec.build().map_err(|e| fe_error(file, e))?;
    if !rule.allowance {
        return Ok((m, info, None));
    }
    progress("estimating the mesh's discretisation error (the mesh refined twice per direction)");
    let d = crate::discretisation::fixed(spec, &m, &p).map_err(|e| fe_error(file, e))?;
    crate::discretisation::correct(&mut m, &d);
    Ok((m, info, Some(d)))
}

fn fe_error(file: &str, e: crate::fe::FeError) -> StudyError {
    StudyError {
        file: file.to_string(),
        key: e.key().to_string(),
        message: e.detail(),
    }
}

/// Build the structural model of a study's structure section. `file` names the study in errors.
pub fn build_model(s: &Structure, file: &str) -> Result<BuiltModel, StudyError> {
    build_model_with(s, file, &|_| {})
}

/// [`build_model`] with a line per mesh of the refinement to `progress`.
pub fn build_model_with(
    s: &Structure,
    file: &str,
    progress: &dyn Fn(&str),
) -> Result<BuiltModel, StudyError> {
    let mut discretisation = None;
    let (model, mesh) = match &s.source {
        StructureSource::Mesher(j) => {
            let spec = joint_spec(s).expect("mesher source");
            let (m, info, d) = meshed(&spec, &j.mesh_rule, file, progress)?;
            discretisation = d;
            (m, Some(info))
        }
        StructureSource::Lap(spec, rule) => {
            let mut spec = spec.clone();
            spec.points = point_specs(s);
            let (m, info, d) = meshed(&spec, rule, file, progress)?;
            discretisation = d;
            (m, Some(info))
        }
        StructureSource::MatrixMarket(im) => {
            let files = crate::fe::foreign::ImportFiles {
                format: im.format,
                mass: im.mass.clone(),
                stiffness: im.stiffness.clone(),
                adhesive_sensitivity: im.adhesive_sensitivity.clone(),
                viscous_damping: im.viscous_damping.clone(),
                structural_damping: im.structural_damping.clone(),
                dof_map: Some(im.dof_map.clone()),
                mapping: im.mapping.clone(),
                units: im.units,
            };
            let m = crate::fe::foreign::import_model_files(&files).map_err(|e| StudyError {
                file: file.to_string(),
                key: "structure.import".into(),
                message: e.to_string(),
            })?;
            (m, None)
        }
    };
    let excitation = model
        .points
        .iter()
        .position(|p| p.id == s.excitation)
        .ok_or_else(|| StudyError {
            file: file.to_string(),
            key: "structure.excitation".into(),
            message: format!(
                "point {} is not in the model's observation points",
                s.excitation
            ),
        })?;
    for p in &s.points {
        if !model
            .points
            .iter()
            .any(|q| q.id == p.id && q.direction == p.direction)
        {
            return Err(StudyError {
                file: file.to_string(),
                key: "structure.points".into(),
                message: format!(
                    "point {} ({}) is not in the imported DOF map: add it to the dof_map file",
                    p.id, p.direction
                ),
            });
        }
    }
    let dof_axes = mesh
        .as_ref()
        .map(|_| (0..model.n_dof()).map(|k| (k % 3) as u8).collect());
    Ok(BuiltModel {
        model,
        mesh,
        excitation,
        dof_axes,
        discretisation,
    })
}

/// `points` with, for every point, the two other axes' directions at the same position (same
/// id, after the declared points so that a point's id still names its measured direction).
pub fn points_in_all_directions(points: &[super::Point]) -> Vec<super::Point> {
    use crate::common::{Axis, Direction};
    let mut out = points.to_vec();
    for p in points {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            if !out.iter().any(|q| q.id == p.id && q.direction.axis == axis) {
                // a direction of the model only: the data need not measure it
                out.push(super::Point {
                    direction: Direction::new(axis, 1),
                    optional: true,
                    ..p.clone()
                });
            }
        }
    }
    out
}

/// `model` (built from `structure`, or with the same DOF numbering) with the sensors' masses in
/// its mass matrix: in the point's measured direction, or in x, y and z (located on the same
/// mesh through the points' other two directions). `file` names the experiment in errors.
pub fn with_sensor_masses(
    model: &StructuralModel,
    structure: &Structure,
    sensors: &[super::experiment::Sensor],
    file: &str,
) -> Result<StructuralModel, StudyError> {
    with_sensor_masses_on(model, structure, sensors, None, file)
}

/// [`with_sensor_masses`] for `model` built from `structure` with its base face free on
/// `base_springs` when given ([`crate::fe::base::joint_model_on_springs`]): a three-direction
/// sensor is then located on that model's DOFs (the free base face numbers its own).
pub fn with_sensor_masses_on(
    model: &StructuralModel,
    structure: &Structure,
    sensors: &[super::experiment::Sensor],
    base_springs: Option<&crate::fe::base::BaseSprings>,
    file: &str,
) -> Result<StructuralModel, StudyError> {
    if sensors.is_empty() {
        return Ok(model.clone());
    }
    let err = |message: String| StudyError {
        file: file.to_string(),
        key: "sensors".into(),
        message,
    };
    // The model with every point's three directions located on the same mesh when a sensor
    // acts in x, y and z (the DOFs do not depend on the points); else the model itself.
    let located = if sensors.iter().any(|s| s.all_directions) {
        let mut all = structure.clone();
        all.points = points_in_all_directions(&structure.points);
        let built = match base_springs {
            None => build_model(&all, file)?.model,
            Some(springs) => {
                let spec = joint_spec(&all).ok_or_else(|| {
                    err("base springs need the mesher's structure (source = \"mesher\")".into())
                })?;
                crate::fe::base::joint_model_on_springs(&spec, springs, "base_springs")
                    .map_err(|e| err(format!("the model on base springs: {e}")))?
            }
        };
        if built.n_dof() != model.n_dof() {
            return Err(err(format!(
                "directions = \"xyz\" needs the DOFs of the model the masses go into ({} here against {} for the points' other directions){}",
                model.n_dof(),
                built.n_dof(),
                if base_springs.is_some() {
                    ""
                } else {
                    ": a model on base springs has a free base face with DOFs of its own; locate the sensors with `with_sensor_masses_on` and its springs"
                }
            )));
        }
        StructuralModel {
            points: built.points,
            ..model.clone()
        }
    } else {
        model.clone()
    };
    // Each sensor's mass at all three directions of its point, or at its (first) measured one.
    let measured = |p: &crate::fe::ObservationPoint| {
        structure
            .points
            .iter()
            .any(|q| q.id == p.id && q.direction.axis == p.direction.axis)
    };
    let mut points = Vec::new();
    for s in sensors {
        let mut at = located
            .points
            .iter()
            .enumerate()
            .filter(|(_, p)| p.id == s.point && (s.all_directions || measured(p)))
            .map(|(i, _)| (i, s.mass_kg))
            .peekable();
        if at.peek().is_none() {
            return Err(err(format!(
                "point {} is not a point of the model",
                s.point
            )));
        }
        if s.all_directions {
            points.extend(at);
        } else {
            points.extend(at.take(1));
        }
    }
    let mut out = located
        .with_point_masses(&points)
        .map_err(|e| err(format!("sensor masses: {e}")))?;
    out.points = model.points.clone();
    Ok(out)
}
