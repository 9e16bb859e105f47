//! The public entry point of the FE layer: a validated bonded-joint specification ->
//! [`StructuralModel`] (M, K_b, S, optional C_b, D_b, observation points).
//!
//! Z(w) = -w^2 M + K_b + j w C_b + j D_b + E*(w) S (method.md, "Dynamic stiffness"), with
//! S the adhesive stiffness at E = 1 Pa and the adhesive's nu (K_adhesive(E) = E S exactly),
//! C_b = alpha M + beta K_b (Rayleigh) and D_b = g K_b (structural), each only when non-zero.

use super::assembly::{Assembler, DofMap};
use super::cost::{available_memory_bytes, check_memory, format_seconds, joint_cost, CostEstimate};
use super::element::Integration;
use super::error::FeError;
use super::geometry::Elasticity;
use super::mesh::{
    box_mesh, joint_mesh_on, segment_divisions, ClampedFace, HexMesh, JointDivisions, JointGrid,
    JointLayout, Region,
};
use super::model::{SpMat, StructuralModel};
use super::points::{map_point, PointMapping};
use crate::common::Direction;
use std::time::Instant;

/// Isotropic linear elastic material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IsoMaterial {
    /// Young's modulus E (Pa).
    pub e_pa: f64,
    /// Poisson's ratio, -1 < nu < 0.5.
    pub nu: f64,
    /// Density (kg/m^3).
    pub rho_kg_m3: f64,
}

/// Adherend damping: C_b = alpha M + beta K_b, D_b = g K_b. Default: all zero (none).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AdherendDamping {
    pub rayleigh_alpha_per_s: f64,
    pub rayleigh_beta_s: f64,
    pub structural_loss_factor: f64,
}

/// Geometry of the joint (m): beam [0, L] x [0, t_b] x [0, w]; adhesive
/// [x0, x0 + L_a] x [-t_a, 0] x [0, w].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointGeometry {
    pub beam_length_m: f64,
    pub beam_thickness_m: f64,
    pub beam_width_m: f64,
    pub adhesive_length_m: f64,
    pub adhesive_thickness_m: f64,
    pub adhesive_x_start_m: f64,
}

impl JointGeometry {
    /// The paper's structure (method.md): 300 x 10 x 20 mm beam on a 50 x 10 x 20 mm adhesive
    /// block at x in [0, 50] mm.
    pub fn paper() -> Self {
        JointGeometry {
            beam_length_m: 0.3,
            beam_thickness_m: 0.01,
            beam_width_m: 0.02,
            adhesive_length_m: 0.05,
            adhesive_thickness_m: 0.01,
            adhesive_x_start_m: 0.0,
        }
    }
}

/// Explicit divisions. `x_outside` is spread over the beam segments outside the adhesive in
/// proportion to their length (at least 1 each when non-empty).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Divisions {
    pub x_adhesive: usize,
    pub x_outside: usize,
    pub y_beam: usize,
    pub y_adhesive: usize,
    pub z: usize,
}

/// Mesh size: a target element size (m; every segment divided into ceil(len / size) equal
/// parts) or explicit divisions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeshSize {
    ElementSize(f64),
    Divisions(Divisions),
}

/// Mesh parameters. Default: 5 mm elements, full 3 x 3 x 3 integration, interpolated points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshParams {
    pub size: MeshSize,
    /// Growth ratio of a mesh graded towards the bond line's edges ([`JointGrid::graded`]),
    /// with an element size only; None: equal cells per segment.
    pub grading: Option<f64>,
    /// Cells at the bond line's edges of a graded mesh (m); None: [`GRADED_EDGE_FRACTION`] of
    /// its thickness.
    pub edge_m: Option<f64>,
    pub integration: Integration,
    pub point_mapping: PointMapping,
}

impl Default for MeshParams {
    fn default() -> Self {
        MeshParams {
            size: MeshSize::ElementSize(0.005),
            grading: None,
            edge_m: None,
            integration: Integration::Full,
            point_mapping: PointMapping::Interpolate,
        }
    }
}

/// A measurement/excitation point on the beam surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointSpec {
    pub id: u32,
    pub position_m: [f64; 3],
    pub direction: Direction,
}

/// Everything needed to build the joint model.
#[derive(Clone, Debug, PartialEq)]
pub struct JointSpec {
    pub geometry: JointGeometry,
    pub beam: IsoMaterial,
    pub adhesive_nu: f64,
    pub adhesive_rho_kg_m3: f64,
    pub damping: AdherendDamping,
    pub mesh: MeshParams,
    pub points: Vec<PointSpec>,
}

impl JointSpec {
    /// The paper's joint (method.md): steel E = 198 GPa, nu = 0.3, rho = 7800; Sikaflex-252
    /// nu = 0.44, rho = 1160; points 1-4 at x = 100, 150, 200, 250 mm on the upper face
    /// centreline, direction +y; 5 mm elements.
    pub fn paper() -> Self {
        JointSpec {
            geometry: JointGeometry::paper(),
            beam: IsoMaterial {
                e_pa: 198e9,
                nu: 0.3,
                rho_kg_m3: 7800.0,
            },
            adhesive_nu: 0.44,
            adhesive_rho_kg_m3: 1160.0,
            damping: AdherendDamping::default(),
            mesh: MeshParams::default(),
            points: [0.10, 0.15, 0.20, 0.25]
                .iter()
                .enumerate()
                .map(|(i, &x)| PointSpec {
                    id: i as u32 + 1,
                    position_m: [x, 0.01, 0.01],
                    direction: Direction::PY,
                })
                .collect(),
        }
    }
}

/// Size and timing of a built model.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshInfo {
    pub n_elements: usize,
    pub n_adhesive_elements: usize,
    pub n_nodes: usize,
    /// Free DOFs (fixed ones eliminated).
    pub n_dof: usize,
    /// Largest element edge per direction (m).
    pub element_size_m: [f64; 3],
    /// Wall time of DOF numbering, patterns and assembly of M, K_b, S, C_b, D_b (s).
    pub assembly_seconds: f64,
}

fn dim(key: &str, v: f64) -> Result<(), FeError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(FeError::InvalidDimension {
            key: key.into(),
            value: v,
        })
    }
}

fn material(prefix: &str, e: Option<f64>, nu: f64, rho: f64) -> Result<(), FeError> {
    if let Some(e) = e {
        if !(e.is_finite() && e > 0.0) {
            return Err(FeError::InvalidMaterial {
                key: format!("{prefix}.E"),
                value: e,
                requirement: "Young's modulus must be positive and finite (Pa)".into(),
            });
        }
    }
    if !(nu.is_finite() && nu > -1.0 && nu < 0.5) {
        return Err(FeError::InvalidMaterial {
            key: format!("{prefix}.nu"),
            value: nu,
            requirement: "Poisson's ratio must satisfy -1 < nu < 0.5".into(),
        });
    }
    if !(rho.is_finite() && rho > 0.0) {
        return Err(FeError::InvalidMaterial {
            key: format!("{prefix}.rho"),
            value: rho,
            requirement: "density must be positive and finite (kg/m^3)".into(),
        });
    }
    Ok(())
}

/// Validate the geometry and return the layout with segment tolerances applied.
fn validate_geometry(g: &JointGeometry) -> Result<JointLayout, FeError> {
    dim("structure.beam.length", g.beam_length_m)?;
    dim("structure.beam.thickness", g.beam_thickness_m)?;
    dim("structure.beam.width", g.beam_width_m)?;
    if g.adhesive_length_m == 0.0 {
        return Err(FeError::Unconstrained {
            key: "structure.adhesive.length".into(),
            fix: "the adhesive's fixed lower face is the only support; give the adhesive a positive length".into(),
        });
    }
    dim("structure.adhesive.length", g.adhesive_length_m)?;
    dim("structure.adhesive.thickness", g.adhesive_thickness_m)?;
    let (l, la, x0) = (g.beam_length_m, g.adhesive_length_m, g.adhesive_x_start_m);
    if !x0.is_finite() {
        return Err(FeError::InvalidDimension {
            key: "structure.adhesive.x_start".into(),
            value: x0,
        });
    }
    if x0 < 0.0 {
        return Err(FeError::AdhesiveOutsideBeam {
            key: "structure.adhesive.x_start".into(),
            detail: format!(
                "the adhesive starts at x = {x0} m, before the beam's end x = 0: use x_start >= 0"
            ),
        });
    }
    let tol = 1e-12 * l;
    if la > l + tol {
        return Err(FeError::AdhesiveOutsideBeam {
            key: "structure.adhesive.length".into(),
            detail: format!(
                "the adhesive ({la} m from x = {x0}) is longer than the beam ({l} m): shorten it or move x_start"
            ),
        });
    }
    if x0 + la > l + tol {
        return Err(FeError::AdhesiveOutsideBeam {
            key: "structure.adhesive.x_start".into(),
            detail: format!(
                "the adhesive ends at x = {} m, beyond the beam's end ({l} m): use x_start <= {} m",
                x0 + la,
                l - la
            ),
        });
    }
    // snap near-empty outside segments to exactly empty
    let x0 = if x0 <= tol { 0.0 } else { x0 };
    let la = if (x0 + la - l).abs() <= tol {
        l - x0
    } else {
        la
    };
    Ok(JointLayout {
        beam_length_m: l,
        beam_thickness_m: g.beam_thickness_m,
        width_m: g.beam_width_m,
        adhesive_x_start_m: x0,
        adhesive_length_m: la,
        adhesive_thickness_m: g.adhesive_thickness_m,
    })
}

/// Resolve the mesh size into per-segment divisions.
fn resolve_divisions(l: &JointLayout, size: &MeshSize) -> Result<JointDivisions, FeError> {
    let seg = [
        l.adhesive_x_start_m,
        l.adhesive_length_m,
        l.beam_length_m - l.adhesive_x_start_m - l.adhesive_length_m,
    ];
    let div = match *size {
        MeshSize::ElementSize(h) => {
            if !(h.is_finite() && h > 0.0) {
                return Err(FeError::InvalidMesh {
                    key: "structure.mesh.element_size".into(),
                    detail: format!("{h} m is not a valid element size: give a positive length in metres, e.g. 0.005"),
                });
            }
            let n = |len: f64| {
                if len > 0.0 {
                    segment_divisions(len, h)
                } else {
                    0
                }
            };
            // a layer thinner than the element size gets MIN_LAYER_DIVISIONS quadratic
            // elements through its thickness (a layer at least one element thick keeps
            // ceil(t / h), so the paper's meshes are unchanged); under a thin bond line the
            // adhesive's x cells are shortened to keep their aspect ratio (length /
            // thickness) at most MAX_ADHESIVE_ASPECT
            let y_adhesive = layer_divisions(l.adhesive_thickness_m, h);
            let y_beam = layer_divisions(l.beam_thickness_m, h);
            let h_adh = h.min(MAX_ADHESIVE_ASPECT * l.adhesive_thickness_m / y_adhesive as f64);
            let x_adh = if seg[1] > 0.0 {
                segment_divisions(seg[1], h_adh)
            } else {
                0
            };
            JointDivisions {
                x: [n(seg[0]), x_adh, n(seg[2])],
                y_adhesive,
                y_beam,
                z: n(l.width_m),
            }
        }
        MeshSize::Divisions(d) => {
            let key = "structure.mesh.divisions";
            let outside = [seg[0], seg[2]];
            let n_nonempty = outside.iter().filter(|&&s| s > 0.0).count();
            for (name, v) in [
                ("x_adhesive", d.x_adhesive),
                ("y_beam", d.y_beam),
                ("y_adhesive", d.y_adhesive),
                ("z", d.z),
            ] {
                if v == 0 {
                    return Err(FeError::InvalidMesh {
                        key: key.into(),
                        detail: format!("{name} = 0: every direction needs at least one element"),
                    });
                }
            }
            if d.x_outside < n_nonempty {
                return Err(FeError::InvalidMesh {
                    key: key.into(),
                    detail: format!(
                        "x_outside = {} but the beam has {n_nonempty} segment(s) outside the adhesive: give at least one element each",
                        d.x_outside
                    ),
                });
            }
            let (n0, n2) = if n_nonempty == 2 {
                let f = seg[0] / (seg[0] + seg[2]);
                let n0 = ((d.x_outside as f64 * f).round() as usize).clamp(1, d.x_outside - 1);
                (n0, d.x_outside - n0)
            } else if seg[0] > 0.0 {
                (d.x_outside, 0)
            } else if seg[2] > 0.0 {
                (0, d.x_outside)
            } else {
                (0, 0)
            };
            JointDivisions {
                x: [n0, d.x_adhesive, n2],
                y_adhesive: d.y_adhesive,
                y_beam: d.y_beam,
                z: d.z,
            }
        }
    };
    let key = match size {
        MeshSize::ElementSize(_) => "structure.mesh.element_size",
        MeshSize::Divisions(_) => "structure.mesh.divisions",
    };
    let cost = divisions_cost(&div);
    if let Err(msg) = check_memory(cost.memory_bytes, available_memory_bytes()) {
        return Err(FeError::InvalidMesh {
            key: key.into(),
            detail: format!(
                "this mesh has {} elements and about {:.2e} free DOFs; building its FRF engine {msg} (and about {} per factorisation): use a coarser mesh",
                cost.n_elements,
                cost.n_dof as f64,
                format_seconds(cost.factor_seconds)
            ),
        });
    }
    Ok(div)
}

/// Cells of the graded mesh at the bond line's edges, as a fraction of its thickness.
pub const GRADED_EDGE_FRACTION: f64 = 0.125;

/// The joint's grid: [`resolve_divisions`]' equal cells, or with a grading ratio
/// (`structure.mesh.grading_ratio`) the cells graded towards the bond line's edges (edge cells
/// [`GRADED_EDGE_FRACTION`] of its thickness), its cost checked against the machine's memory.
fn resolve_grid(l: &JointLayout, mesh: &MeshParams) -> Result<JointGrid, FeError> {
    let Some(r) = mesh.grading else {
        let div = resolve_divisions(l, &mesh.size)?;
        return Ok(JointGrid::uniform(l, &div));
    };
    let key = "structure.mesh.grading_ratio";
    if !(r.is_finite() && r > 1.0 && r <= 3.0) {
        return Err(FeError::InvalidMesh {
            key: key.into(),
            detail: format!("{r} is not a growth ratio in (1, 3]: give e.g. 1.5"),
        });
    }
    let MeshSize::ElementSize(h) = mesh.size else {
        return Err(FeError::InvalidMesh {
            key: key.into(),
            detail:
                "a graded mesh needs structure.mesh.element_size (the largest cell), not divisions"
                    .into(),
        });
    };
    // the element size is validated (key `structure.mesh.element_size`) as for a uniform mesh
    resolve_divisions(l, &mesh.size)?;
    let grid = JointGrid::graded(
        l,
        h,
        mesh.edge_m
            .unwrap_or(GRADED_EDGE_FRACTION * l.adhesive_thickness_m),
        r,
        layer_divisions(l.beam_thickness_m, h),
    );
    let cost = divisions_cost(&grid.divisions());
    if let Err(msg) = check_memory(cost.memory_bytes, available_memory_bytes()) {
        return Err(FeError::InvalidMesh {
            key: key.into(),
            detail: format!(
                "this graded mesh has {} elements and about {:.2e} free DOFs; building its FRF engine {msg}: use a larger ratio or element_size",
                cost.n_elements, cost.n_dof as f64
            ),
        });
    }
    Ok(grid)
}

/// Fewest quadratic elements through the thickness of a layer (beam or adhesive) thinner than
/// the element size, when the mesh is given by an element size (one element cannot follow a
/// thin layer's shear and peel: a 3 mm bond line under 5 mm elements put the first mode 3 %
/// high). A layer at least one element size thick keeps ceil(t / h) elements.
pub const MIN_LAYER_DIVISIONS: usize = 2;

/// Elements through a layer of thickness `t` under an element size `h`: ceil(t / h), and at
/// least [`MIN_LAYER_DIVISIONS`] where the layer is thinner than `h`.
pub fn layer_divisions(t: f64, h: f64) -> usize {
    let n = segment_divisions(t, h);
    if t < h * (1.0 - 1e-9) {
        n.max(MIN_LAYER_DIVISIONS)
    } else {
        n
    }
}

/// Largest length-to-thickness ratio of the adhesive's elements along the beam when the mesh
/// is given by an element size (thin bond lines get shorter elements under the adhesive).
pub const MAX_ADHESIVE_ASPECT: f64 = 10.0;

fn divisions_cost(div: &JointDivisions) -> CostEstimate {
    joint_cost(
        div.x.iter().sum(),
        div.x[1],
        div.y_beam,
        div.y_adhesive,
        div.z,
    )
}

/// The joint's size and estimated cost (free DOFs, memory and time of the engine's
/// factorisation) from its specification, before anything is allocated.
pub fn joint_cost_estimate(spec: &JointSpec) -> Result<CostEstimate, FeError> {
    let layout = validate_geometry(&spec.geometry)?;
    let grid = resolve_grid(&layout, &spec.mesh)?;
    Ok(divisions_cost(&grid.divisions()))
}

/// The joint's model on its mesh with every cell split into `factor` equal parts per
/// direction (a uniformly refined mesh, for a Richardson estimate of the discretisation
/// error), its cost checked against the machine's memory first.
pub fn build_joint_model_refined(
    spec: &JointSpec,
    factor: usize,
) -> Result<(StructuralModel, MeshInfo), FeError> {
    let layout = validate_geometry(&spec.geometry)?;
    let f = factor.max(1);
    let fine = resolve_grid(&layout, &spec.mesh)?.split(f);
    let cost = divisions_cost(&fine.divisions());
    if let Err(msg) = check_memory(cost.memory_bytes, available_memory_bytes()) {
        return Err(FeError::InvalidMesh {
            key: "structure.mesh".into(),
            detail: format!(
                "the mesh refined {f} times for the discretisation-error estimate ({:.2e} DOFs) {msg}",
                cost.n_dof as f64
            ),
        });
    }
    let mesh = joint_mesh_on(fine);
    let (model, info, _) = assemble_joint(spec, &mesh, &layout)?;
    Ok((model, info))
}

/// Validate a joint spec and build its mesh (no assembly): for plots and point checks.
pub fn joint_mesh_from_spec(spec: &JointSpec) -> Result<(HexMesh, JointLayout), FeError> {
    let layout = validate_geometry(&spec.geometry)?;
    material(
        "structure.beam.material",
        Some(spec.beam.e_pa),
        spec.beam.nu,
        spec.beam.rho_kg_m3,
    )?;
    material(
        "structure.adhesive",
        None,
        spec.adhesive_nu,
        spec.adhesive_rho_kg_m3,
    )?;
    let grid = resolve_grid(&layout, &spec.mesh)?;
    Ok((joint_mesh_on(grid), layout))
}

fn check_damping(d: &AdherendDamping) -> Result<(), FeError> {
    for (k, v) in [
        (
            "structure.beam.damping.rayleigh_alpha",
            d.rayleigh_alpha_per_s,
        ),
        ("structure.beam.damping.rayleigh_beta", d.rayleigh_beta_s),
        (
            "structure.beam.damping.structural_loss_factor",
            d.structural_loss_factor,
        ),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(FeError::InvalidMaterial {
                key: k.into(),
                value: v,
                requirement: "damping coefficients must be finite and >= 0".into(),
            });
        }
    }
    Ok(())
}

fn scaled(a: &SpMat, s: f64) -> SpMat {
    let mut b = a.clone();
    for v in b.val_mut() {
        *v *= s;
    }
    b
}

fn lin_comb(
    a: &SpMat,
    alpha: f64,
    b: &SpMat,
    beta: f64,
    key: &str,
    what: &str,
) -> Result<SpMat, FeError> {
    faer::sparse::ops::binary_op(
        a.as_ref(),
        b.as_ref(),
        |x: Option<&f64>, y: Option<&f64>| {
            alpha * x.copied().unwrap_or(0.0) + beta * y.copied().unwrap_or(0.0)
        },
    )
    .map_err(|_| FeError::OutOfMemory {
        key: key.into(),
        what: what.into(),
    })
}

/// The matrices of a mesh of adherend (`Region::Beam`) and adhesive elements.
pub(crate) struct JointMatrices {
    pub m: SpMat,
    pub k_b: SpMat,
    pub s: SpMat,
    pub c_b: Option<SpMat>,
    pub d_b: Option<SpMat>,
}

/// M (all elements at their region's density), K_b (adherend elements at the adherend's E,
/// nu), S (adhesive elements at E = 1 Pa and the adhesive's nu), C_b = alpha M + beta K_b and
/// D_b = eta K_b when non-zero. `mesh_key` is the study key an out-of-memory error names.
#[allow(clippy::too_many_arguments)]
pub(crate) fn assemble_joint_matrices(
    asm: &Assembler,
    mesh: &HexMesh,
    adherend: &IsoMaterial,
    adhesive_nu: f64,
    adhesive_rho_kg_m3: f64,
    rule: Integration,
    damping: &AdherendDamping,
    mesh_key: &str,
) -> Result<JointMatrices, FeError> {
    let all: Vec<usize> = (0..mesh.n_elements()).collect();
    let adherend_el = mesh.elements_in(Region::Beam);
    let adh_el = mesh.elements_in(Region::Adhesive);
    let (rho_b, rho_a) = (adherend.rho_kg_m3, adhesive_rho_kg_m3);
    let regions = &mesh.regions;
    let m = asm.mass(&asm.pattern(&all), |e| {
        if regions[e] == Region::Beam {
            rho_b
        } else {
            rho_a
        }
    })?;
    let mat = Elasticity {
        e_pa: adherend.e_pa,
        nu: adherend.nu,
    };
    let k_b = asm.stiffness(&asm.pattern(&adherend_el), |_| mat, rule)?;
    let unit = Elasticity {
        e_pa: 1.0,
        nu: adhesive_nu,
    };
    let s = asm.stiffness(&asm.pattern(&adh_el), |_| unit, rule)?;
    let d = damping;
    let c_b = if d.rayleigh_alpha_per_s != 0.0 || d.rayleigh_beta_s != 0.0 {
        Some(lin_comb(
            &m,
            d.rayleigh_alpha_per_s,
            &k_b,
            d.rayleigh_beta_s,
            mesh_key,
            "C_b = alpha M + beta K_b",
        )?)
    } else {
        None
    };
    let d_b = (d.structural_loss_factor != 0.0).then(|| scaled(&k_b, d.structural_loss_factor));
    Ok(JointMatrices {
        m,
        k_b,
        s,
        c_b,
        d_b,
    })
}

/// Build the joint's structural model: mesh, M (all elements), K_b (beam elements at the
/// beam's E, nu), S (adhesive elements at E = 1 Pa, adhesive nu), damping, points.
pub fn build_joint_model(spec: &JointSpec) -> Result<(StructuralModel, MeshInfo), FeError> {
    let (mesh, layout) = joint_mesh_from_spec(spec)?;
    if !mesh.fixed.iter().any(|&f| f) {
        return Err(FeError::Unconstrained {
            key: "structure.adhesive.length".into(),
            fix: "no node of the adhesive's lower face exists: give the adhesive a positive length and thickness".into(),
        });
    }
    let (model, info, _) = assemble_joint(spec, &mesh, &layout)?;
    Ok((model, info))
}

/// The assembly behind [`build_joint_model`] on a given mesh (its fixed nodes eliminated),
/// with the DOF numbering (the base springs of [`super::base`] free the lower face).
pub(crate) fn assemble_joint(
    spec: &JointSpec,
    mesh: &HexMesh,
    layout: &JointLayout,
) -> Result<(StructuralModel, MeshInfo, DofMap), FeError> {
    check_damping(&spec.damping)?;
    // points: directions and duplicates first (cheap)
    for (i, p) in spec.points.iter().enumerate() {
        if let Some(j) = spec.points[..i]
            .iter()
            .position(|q| q.id == p.id && q.direction == p.direction)
        {
            return Err(FeError::InvalidPointDirection {
                key: format!("structure.points[{i}].direction"),
                detail: format!(
                    "point {} direction {} is given twice (also structure.points[{j}]): remove the duplicate",
                    p.id, p.direction
                ),
            });
        }
    }
    let t0 = Instant::now();
    let dofs = DofMap::new(mesh);
    let asm = Assembler::new(mesh, &dofs);
    let JointMatrices {
        m,
        k_b,
        s,
        c_b,
        d_b,
    } = assemble_joint_matrices(
        &asm,
        mesh,
        &spec.beam,
        spec.adhesive_nu,
        spec.adhesive_rho_kg_m3,
        spec.mesh.integration,
        &spec.damping,
        "structure.mesh",
    )?;
    let n_adhesive_elements = mesh.elements_in(Region::Adhesive).len();
    let assembly_seconds = t0.elapsed().as_secs_f64();

    let lo = [0.0, 0.0, 0.0];
    let hi = [
        layout.beam_length_m,
        layout.beam_thickness_m,
        layout.width_m,
    ];
    let mut points = Vec::with_capacity(spec.points.len());
    for (i, p) in spec.points.iter().enumerate() {
        points.push(map_point(
            mesh,
            &dofs,
            lo,
            hi,
            i,
            p.id,
            p.position_m,
            p.direction,
            spec.mesh.point_mapping,
        )?);
    }
    let info = MeshInfo {
        n_elements: mesh.n_elements(),
        n_adhesive_elements,
        n_nodes: mesh.n_nodes(),
        n_dof: dofs.n_free,
        element_size_m: mesh.max_cell_size(),
        assembly_seconds,
    };
    let h = info.element_size_m;
    let description = format!(
        "bonded joint, structured 20-node hexahedra: {} elements ({} adhesive), {} nodes, {} free DOFs, max element {:.2} x {:.2} x {:.2} mm, {:?} integration",
        info.n_elements,
        info.n_adhesive_elements,
        info.n_nodes,
        info.n_dof,
        h[0] * 1e3,
        h[1] * 1e3,
        h[2] * 1e3,
        spec.mesh.integration
    );
    Ok((
        StructuralModel {
            m,
            k_b,
            s,
            c_b,
            d_b,
            points,
            description,
        },
        info,
        dofs,
    ))
}

/// A clamped box (beam elements only, face x = 0 fixed), e.g. the steel cantilever check.
/// S is the empty n x n matrix; there are no points.
pub fn build_cantilever(
    size_m: [f64; 3],
    divisions: [usize; 3],
    material_: &IsoMaterial,
    rule: Integration,
) -> Result<(StructuralModel, HexMesh), FeError> {
    for (k, v) in [
        "structure.beam.length",
        "structure.beam.thickness",
        "structure.beam.width",
    ]
    .iter()
    .zip(size_m)
    {
        dim(k, v)?;
    }
    material(
        "structure.beam.material",
        Some(material_.e_pa),
        material_.nu,
        material_.rho_kg_m3,
    )?;
    if divisions.contains(&0) {
        return Err(FeError::InvalidMesh {
            key: "structure.mesh.divisions".into(),
            detail: "every direction needs at least one element".into(),
        });
    }
    let mesh = box_mesh(size_m, divisions, ClampedFace::XMin);
    let dofs = DofMap::new(&mesh);
    let asm = Assembler::new(&mesh, &dofs);
    let all: Vec<usize> = (0..mesh.n_elements()).collect();
    let pat = asm.pattern(&all);
    let m = asm.mass(&pat, |_| material_.rho_kg_m3)?;
    let k_b = asm.stiffness(
        &pat,
        |_| Elasticity {
            e_pa: material_.e_pa,
            nu: material_.nu,
        },
        rule,
    )?;
    let s = asm.pattern(&[]).fill(&mesh, &dofs, |_, _, _| Ok(()))?;
    let description = format!(
        "cantilever box {:?} m, {:?} divisions, {} free DOFs",
        size_m, divisions, dofs.n_free
    );
    Ok((
        StructuralModel {
            m,
            k_b,
            s,
            c_b: None,
            d_b: None,
            points: Vec::new(),
            description,
        },
        mesh,
    ))
}
