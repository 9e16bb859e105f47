//! The single-lap joint: two adherend strips bonded over an overlap.
//!
//! Layout (m), width w along z for all three parts:
//!
//! ```text
//!   lower strip  x in [0, L],            y in [0, t1]
//!   adhesive     x in [L - l_o, L],      y in [t1, t1 + t_a]
//!   upper strip  x in [L - l_o, 2L - l_o], y in [t1 + t_a, t1 + t_a + t2]
//! ```
//!
//! Support: `Clamped` fixes every node of the lower strip's end face x = 0; `Free` fixes
//! nothing (free-free: six rigid-body modes at 0 Hz; FRFs at w > 0 are finite).
//!
//! Model: Z(w) = -w^2 M + K_b + j w C_b + j D_b + E*(w) S with K_b the strips' stiffness, S
//! the adhesive's at E = 1 Pa and its nu, M of all three parts (method.md, "Dynamic stiffness").
//!
//! Mesh: structured 20-node hexahedra, nodes merged on both bond faces (perfect bond).
//! Through the thickness: `y_adhesive` equal elements in the bond line (at least 2 quadratic
//! elements, so the bond line's shear and peel are resolved) and `y_strip` in each strip.
//! Along x the mesh is graded towards the two overlap ends, where the adhesive's stresses
//! peak: the element there is `end_aspect` times the bond line's element thickness (capped by
//! the element size), and sizes grow by `grading_ratio` per element away from the ends up to
//! the element size; inside the overlap no adhesive element is longer than `max_aspect` times
//! its thickness. Bond lines of 0.5-3 mm under a 5 mm mesh thus keep the adhesive elements'
//! aspect ratio (x : y) at `end_aspect` at the overlap ends and at most `max_aspect` anywhere.
//! Across the width (z) the elements follow the element size (the fields vary slowly there).

use super::assembly::{Assembler, DofMap};
use super::element::Integration;
use super::error::FeError;
use super::joint::{
    assemble_joint_matrices, AdherendDamping, IsoMaterial, JointMatrices, MeshInfo, PointSpec,
};
use super::mesh::{segment_divisions, segment_divisions_f64, structured_mesh, HexMesh, Region};
use super::model::StructuralModel;
use super::points::{map_point, PointMapping, SURFACE_TOL_M};
use std::time::Instant;

/// Geometry of the single-lap joint (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LapGeometry {
    /// Length of each strip, L.
    pub strip_length_m: f64,
    /// Thickness of the lower strip t1 (the one at x = 0).
    pub lower_thickness_m: f64,
    /// Thickness of the upper strip t2.
    pub upper_thickness_m: f64,
    pub width_m: f64,
    /// Overlap length l_o (< L).
    pub overlap_m: f64,
    /// Bond-line thickness t_a.
    pub adhesive_thickness_m: f64,
}

/// Boundary condition of the lap joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LapSupport {
    /// The lower strip's end face x = 0 fixed.
    Clamped,
    /// Nothing fixed.
    Free,
}

/// Mesh parameters of the lap joint. Defaults: 5 mm elements, 2 elements through the bond
/// line and through each strip, z divisions from the element size, end elements 4 bond-line
/// elements long, overlap elements at most 10 bond-line elements long, growth 1.5, full
/// integration, interpolated points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LapMeshParams {
    pub element_size_m: f64,
    pub y_adhesive: usize,
    pub y_strip: usize,
    /// Elements across the width; None: ceil(w / element size).
    pub z: Option<usize>,
    pub end_aspect: f64,
    /// Longest x : y ratio of the adhesive's elements anywhere in the overlap.
    pub max_aspect: f64,
    pub grading_ratio: f64,
    pub integration: Integration,
    pub point_mapping: PointMapping,
}

impl Default for LapMeshParams {
    fn default() -> Self {
        LapMeshParams {
            element_size_m: 0.005,
            y_adhesive: 2,
            y_strip: 2,
            z: None,
            end_aspect: 4.0,
            max_aspect: 10.0,
            grading_ratio: 1.5,
            integration: Integration::Full,
            point_mapping: PointMapping::Interpolate,
        }
    }
}

/// Everything needed to build a lap-joint model.
#[derive(Clone, Debug, PartialEq)]
pub struct LapSpec {
    pub geometry: LapGeometry,
    pub support: LapSupport,
    pub adherend: IsoMaterial,
    pub adhesive_nu: f64,
    pub adhesive_rho_kg_m3: f64,
    pub damping: AdherendDamping,
    pub mesh: LapMeshParams,
    /// Points on a strip's outer surface (any face of either strip).
    pub points: Vec<PointSpec>,
}

impl LapSpec {
    /// A reference lap joint: aluminium strips 100 x 3 x 25 mm, 25 mm overlap, a 1 mm
    /// Sikaflex-like bond line (nu 0.44, rho 1160), the lower strip clamped; points 1-4 on the
    /// upper faces at x = 40, 70 mm (lower strip) and 120, 160 mm (upper strip), +y.
    pub fn reference() -> Self {
        let g = LapGeometry {
            strip_length_m: 0.100,
            lower_thickness_m: 0.003,
            upper_thickness_m: 0.003,
            width_m: 0.025,
            overlap_m: 0.025,
            adhesive_thickness_m: 0.001,
        };
        let top2 = g.lower_thickness_m + g.adhesive_thickness_m + g.upper_thickness_m;
        LapSpec {
            geometry: g,
            support: LapSupport::Clamped,
            adherend: IsoMaterial {
                e_pa: 70e9,
                nu: 0.33,
                rho_kg_m3: 2700.0,
            },
            adhesive_nu: 0.44,
            adhesive_rho_kg_m3: 1160.0,
            damping: AdherendDamping::default(),
            mesh: LapMeshParams::default(),
            points: [
                (0.040, g.lower_thickness_m),
                (0.070, g.lower_thickness_m),
                (0.120, top2),
                (0.160, top2),
            ]
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| PointSpec {
                id: i as u32 + 1,
                position_m: [x, y, 0.5 * g.width_m],
                direction: crate::common::Direction::PY,
            })
            .collect(),
        }
    }
}

const KEY: &str = "structure.lap";

fn positive(key: &str, v: f64) -> Result<(), FeError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(FeError::InvalidDimension {
            key: format!("{KEY}.{key}"),
            value: v,
        })
    }
}

pub use super::mesh::graded_partition;

/// Cell boundaries of the lap mesh along x, y, z, and the index ranges of the overlap cells
/// along x and of the three layers along y.
struct LapGrid {
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    /// x cells [0, ov.0) lower strip only, [ov.0, ov.1) overlap, [ov.1, nx) upper strip only.
    ov: (usize, usize),
    /// y cells [0, ly.0) lower strip, [ly.0, ly.1) adhesive, [ly.1, ny) upper strip.
    ly: (usize, usize),
}

fn validate(spec: &LapSpec) -> Result<(), FeError> {
    let g = &spec.geometry;
    positive("length", g.strip_length_m)?;
    positive("thickness_lower", g.lower_thickness_m)?;
    positive("thickness_upper", g.upper_thickness_m)?;
    positive("width", g.width_m)?;
    positive("overlap", g.overlap_m)?;
    positive("adhesive.thickness", g.adhesive_thickness_m)?;
    if g.overlap_m >= g.strip_length_m {
        return Err(FeError::AdhesiveOutsideBeam {
            key: format!("{KEY}.overlap"),
            detail: format!(
                "the overlap ({} m) must be shorter than the strips ({} m)",
                g.overlap_m, g.strip_length_m
            ),
        });
    }
    let m = &spec.adherend;
    if !(m.e_pa.is_finite() && m.e_pa > 0.0) {
        return Err(FeError::InvalidMaterial {
            key: format!("{KEY}.material.E"),
            value: m.e_pa,
            requirement: "Young's modulus must be positive and finite (Pa)".into(),
        });
    }
    for (k, nu) in [("material.nu", m.nu), ("adhesive.nu", spec.adhesive_nu)] {
        if !(nu.is_finite() && nu > -1.0 && nu < 0.5) {
            return Err(FeError::InvalidMaterial {
                key: format!("{KEY}.{k}"),
                value: nu,
                requirement: "Poisson's ratio must satisfy -1 < nu < 0.5".into(),
            });
        }
    }
    for (k, rho) in [
        ("material.rho", m.rho_kg_m3),
        ("adhesive.rho", spec.adhesive_rho_kg_m3),
    ] {
        if !(rho.is_finite() && rho > 0.0) {
            return Err(FeError::InvalidMaterial {
                key: format!("{KEY}.{k}"),
                value: rho,
                requirement: "density must be positive and finite (kg/m^3)".into(),
            });
        }
    }
    let p = &spec.mesh;
    let mesh_err = |detail: String| FeError::InvalidMesh {
        key: format!("{KEY}.mesh"),
        detail,
    };
    if !(p.element_size_m.is_finite() && p.element_size_m > 0.0) {
        return Err(mesh_err(format!(
            "element_size = {} m: give a positive length in metres, e.g. 0.005",
            p.element_size_m
        )));
    }
    if p.y_adhesive < 2 {
        return Err(mesh_err(format!(
            "y_adhesive = {}: the bond line needs at least 2 elements through its thickness",
            p.y_adhesive
        )));
    }
    if p.y_strip == 0 || p.z == Some(0) {
        return Err(mesh_err("y_strip and z need at least one element".into()));
    }
    if !(p.max_aspect.is_finite() && p.max_aspect >= p.end_aspect) {
        return Err(mesh_err(format!(
            "max_aspect = {}: give a ratio >= end_aspect ({}), e.g. 10",
            p.max_aspect, p.end_aspect
        )));
    }
    if !(p.end_aspect.is_finite() && p.end_aspect > 0.0) {
        return Err(mesh_err(format!(
            "end_aspect = {}: give a positive ratio, e.g. 4",
            p.end_aspect
        )));
    }
    if !(p.grading_ratio.is_finite() && p.grading_ratio >= 1.0 && p.grading_ratio <= 3.0) {
        return Err(mesh_err(format!(
            "grading_ratio = {}: give a growth factor in [1, 3], e.g. 1.5",
            p.grading_ratio
        )));
    }
    Ok(())
}

/// Most elements of a lap joint's mesh.
const MAX_ELEMENTS: f64 = 2.0e6;

fn too_many_elements(n_el: f64) -> FeError {
    FeError::InvalidMesh {
        key: format!("{KEY}.mesh.element_size"),
        detail: format!(
            "about {n_el:.0} elements is beyond what this program can assemble: use a coarser mesh"
        ),
    }
}

fn lap_grid(spec: &LapSpec) -> Result<LapGrid, FeError> {
    validate(spec)?;
    let g = &spec.geometry;
    let p = &spec.mesh;
    let h = p.element_size_m;
    let (l, lo, ta) = (g.strip_length_m, g.overlap_m, g.adhesive_thickness_m);
    let h_end = (p.end_aspect * ta / p.y_adhesive as f64).min(h);
    let r = p.grading_ratio;
    let (x0, x1, x2) = (l - lo, l, 2.0 * l - lo);
    let (t1, t2) = (g.lower_thickness_m, g.upper_thickness_m);
    // the count before any coordinate is made: no element is longer than h, so the strips'
    // length gives at least (2 l - lo) / h of them along x, and the other axes' counts are exact
    let divisions = |len: f64| segment_divisions_f64(len, h);
    let across = |t: f64| (p.y_strip as f64).max(divisions(t));
    let ny_at_least = across(t1) + p.y_adhesive as f64 + across(t2);
    let nz_at_least = p.z.map_or_else(|| divisions(g.width_m), |z| z as f64);
    let n_el_at_least = divisions(x2) * ny_at_least * nz_at_least;
    if n_el_at_least > MAX_ELEMENTS {
        return Err(too_many_elements(n_el_at_least));
    }
    let mut xs = graded_partition(0.0, x0, None, Some(h_end), h, r);
    let nov0 = xs.len() - 1;
    let h_ov = (p.max_aspect * ta / p.y_adhesive as f64).min(h);
    let mid = graded_partition(x0, x1, Some(h_end), Some(h_end), h_ov, r);
    xs.extend_from_slice(&mid[1..]);
    let nov1 = xs.len() - 1;
    let right = graded_partition(x1, x2, Some(h_end), None, h, r);
    xs.extend_from_slice(&right[1..]);
    let uniform = |a: f64, b: f64, n: usize| -> Vec<f64> {
        (0..=n)
            .map(|i| {
                if i == n {
                    b
                } else {
                    a + (b - a) * i as f64 / n as f64
                }
            })
            .collect()
    };
    let ns1 = p.y_strip.max(segment_divisions(t1, h));
    let ns2 = p.y_strip.max(segment_divisions(t2, h));
    let mut ys = uniform(0.0, t1, ns1);
    let ly0 = ys.len() - 1;
    ys.extend_from_slice(&uniform(t1, t1 + ta, p.y_adhesive)[1..]);
    let ly1 = ys.len() - 1;
    ys.extend_from_slice(&uniform(t1 + ta, t1 + ta + t2, ns2)[1..]);
    let nz = p.z.unwrap_or_else(|| segment_divisions(g.width_m, h));
    let zs = uniform(0.0, g.width_m, nz);
    let n_el = (xs.len() - 1) as f64 * (ys.len() - 1) as f64 * nz as f64;
    if n_el > MAX_ELEMENTS {
        return Err(too_many_elements(n_el));
    }
    Ok(LapGrid {
        xs,
        ys,
        zs,
        ov: (nov0, nov1),
        ly: (ly0, ly1),
    })
}

/// The lap joint's mesh.
pub fn lap_mesh(spec: &LapSpec) -> Result<HexMesh, FeError> {
    let LapGrid { xs, ys, zs, ov, ly } = lap_grid(spec)?;
    let clamped = spec.support == LapSupport::Clamped;
    Ok(structured_mesh(
        xs,
        ys,
        zs,
        |i, j, _| {
            if j < ly.0 {
                (i < ov.1).then_some(Region::Beam)
            } else if j < ly.1 {
                (i >= ov.0 && i < ov.1).then_some(Region::Adhesive)
            } else {
                (i >= ov.0).then_some(Region::Beam)
            }
        },
        |a, _, _| clamped && a == 0,
    ))
}

/// Largest aspect ratios of the adhesive's elements: (x : y, longest : shortest edge).
pub fn adhesive_aspect_ratio(mesh: &HexMesh) -> (f64, f64) {
    let g = &mesh.grid;
    let [nx, ny, nz] = g.n_cells();
    let (mut xy, mut any): (f64, f64) = (0.0, 0.0);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if let Some(e) = g.element_at(i, j, k) {
                    if mesh.regions[e] != Region::Adhesive {
                        continue;
                    }
                    let d = [
                        g.xs[i + 1] - g.xs[i],
                        g.ys[j + 1] - g.ys[j],
                        g.zs[k + 1] - g.zs[k],
                    ];
                    let hi = d.iter().cloned().fold(0.0, f64::max);
                    let lo = d.iter().cloned().fold(f64::INFINITY, f64::min);
                    xy = xy.max(d[0] / d[1]);
                    any = any.max(hi / lo);
                }
            }
        }
    }
    (xy, any)
}

/// The lap joint's size and estimated cost (free DOFs, memory and time of the engine's
/// factorisation), from its mesh's nodes before any matrix is allocated.
pub fn lap_cost_estimate(spec: &LapSpec) -> Result<super::cost::CostEstimate, FeError> {
    let mesh = lap_mesh(spec)?;
    let n_free = mesh.fixed.iter().filter(|&&f| !f).count();
    let [_, ny, nz] = mesh.grid.n_cells();
    // one element slab: two lattice planes across the section
    let band = (3 * 2 * super::cost::serendipity_nodes([0, ny, nz])) as f64;
    Ok(super::cost::cost_of(3 * n_free, mesh.n_elements(), band))
}

/// The lap joint's model with its element size and width divisions divided by `factor` and its
/// elements through the bond line and the strips multiplied by it (a uniformly refined mesh,
/// for the estimate of the discretisation error), its cost checked against the machine's
/// memory first (as [`super::joint::build_joint_model_refined`] does for the beam on a block).
pub fn build_lap_model_refined(
    spec: &LapSpec,
    factor: usize,
) -> Result<(StructuralModel, MeshInfo), FeError> {
    let f = factor.max(1);
    let mut s = spec.clone();
    let h = spec.mesh.element_size_m;
    s.mesh.z = Some(
        f * spec
            .mesh
            .z
            .unwrap_or_else(|| segment_divisions(spec.geometry.width_m, h)),
    );
    s.mesh.element_size_m = h / f as f64;
    s.mesh.y_adhesive *= f;
    s.mesh.y_strip *= f;
    let cost = lap_cost_estimate(&s)?;
    if let Err(msg) =
        super::cost::check_memory(cost.memory_bytes, super::cost::available_memory_bytes())
    {
        return Err(FeError::InvalidMesh {
            key: format!("{KEY}.mesh"),
            detail: format!(
                "the mesh refined {f} times for the discretisation-error estimate ({:.2e} DOFs) {msg}",
                cost.n_dof as f64
            ),
        });
    }
    build_lap_model(&s)
}

/// Build the lap joint's structural model.
pub fn build_lap_model(spec: &LapSpec) -> Result<(StructuralModel, MeshInfo), FeError> {
    let mesh = lap_mesh(spec)?;
    let t0 = Instant::now();
    let d = &spec.damping;
    for (k, v) in [
        ("rayleigh_alpha", d.rayleigh_alpha_per_s),
        ("rayleigh_beta", d.rayleigh_beta_s),
        ("structural", d.structural_loss_factor),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(FeError::InvalidMaterial {
                key: format!("{KEY}.damping.{k}"),
                value: v,
                requirement: "damping coefficients must be finite and >= 0".into(),
            });
        }
    }
    let dofs = DofMap::new(&mesh);
    let asm = Assembler::new(&mesh, &dofs);
    let JointMatrices {
        m,
        k_b,
        s,
        c_b,
        d_b,
    } = assemble_joint_matrices(
        &asm,
        &mesh,
        &spec.adherend,
        spec.adhesive_nu,
        spec.adhesive_rho_kg_m3,
        spec.mesh.integration,
        &spec.damping,
        &format!("{KEY}.mesh"),
    )?;
    let assembly_seconds = t0.elapsed().as_secs_f64();

    // points: on the surface of either strip (the first whose box holds the point)
    let g = &spec.geometry;
    let (l, lo) = (g.strip_length_m, g.overlap_m);
    let y2 = g.lower_thickness_m + g.adhesive_thickness_m;
    let boxes = [
        ([0.0, 0.0, 0.0], [l, g.lower_thickness_m, g.width_m]),
        (
            [l - lo, y2, 0.0],
            [2.0 * l - lo, y2 + g.upper_thickness_m, g.width_m],
        ),
    ];
    let mut points = Vec::with_capacity(spec.points.len());
    for (i, p) in spec.points.iter().enumerate() {
        let inside = |b: &([f64; 3], [f64; 3])| {
            (0..3).all(|d| {
                p.position_m[d] >= b.0[d] - SURFACE_TOL_M
                    && p.position_m[d] <= b.1[d] + SURFACE_TOL_M
            })
        };
        // the lower strip's box when the point is in it, else the upper's (the error then
        // names the distance to the upper strip)
        let b = boxes.iter().find(|b| inside(b)).unwrap_or(&boxes[1]);
        let mut op = map_point(
            &mesh,
            &dofs,
            b.0,
            b.1,
            i,
            p.id,
            p.position_m,
            p.direction,
            spec.mesh.point_mapping,
        )?;
        if op.dofs.is_empty() {
            op.note = format!("{} (on the clamped face: no free DOF)", op.note);
        }
        points.push(op);
    }
    let info = MeshInfo {
        n_elements: mesh.n_elements(),
        n_adhesive_elements: mesh.elements_in(Region::Adhesive).len(),
        n_nodes: mesh.n_nodes(),
        n_dof: dofs.n_free,
        element_size_m: mesh.max_cell_size(),
        assembly_seconds,
    };
    let description = format!(
        "single-lap joint ({}), structured 20-node hexahedra: {} elements ({} adhesive, {} through \
         the bond line, aspect x:y <= {:.1}, any <= {:.1}), {} nodes, {} free DOFs, {:?} \
         integration",
        match spec.support {
            LapSupport::Clamped => "lower strip clamped at x = 0",
            LapSupport::Free => "free-free",
        },
        info.n_elements,
        info.n_adhesive_elements,
        spec.mesh.y_adhesive,
        adhesive_aspect_ratio(&mesh).0,
        adhesive_aspect_ratio(&mesh).1,
        info.n_nodes,
        info.n_dof,
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
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_partition_fits_and_grades() {
        let x = graded_partition(0.0, 0.075, None, Some(0.002), 0.005, 1.5);
        assert_eq!(x[0], 0.0);
        assert_eq!(*x.last().unwrap(), 0.075);
        let s: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
        // smallest at the graded end, largest near the element size, monotone
        assert!(s.last().unwrap() < &0.0025, "{s:?}");
        assert!(s[0] > 0.004 && s[0] < 0.0056, "{s:?}");
        for w in s.windows(2) {
            assert!(w[1] <= w[0] * 1.0001, "{s:?}");
            assert!(w[0] / w[1] < 1.6, "{s:?}");
        }
        let y = graded_partition(0.0, 0.025, Some(0.001), Some(0.001), 0.005, 1.5);
        let s: Vec<f64> = y.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(s[0] < 0.0012 && s[s.len() - 1] < 0.0012, "{s:?}");
    }

    /// A mesh far beyond the element limit is refused from its counts, before any of its
    /// coordinates are made: 1e-9 m elements would need about 1e8 x coordinates (800 MB made,
    /// then refused, before the count came first), and 2^40 bond-line layers 8 TB of y
    /// coordinates, an allocation that aborts the process rather than return an error.
    #[test]
    fn a_nanometre_element_size_is_refused_from_the_counts() {
        let mut spec = LapSpec::reference();
        spec.mesh.element_size_m = 1e-9;
        let e = lap_mesh(&spec).unwrap_err();
        assert_eq!(e.key(), "structure.lap.mesh.element_size", "{e}");
        assert!(
            e.detail().contains("beyond what this program can assemble"),
            "{e}"
        );
        // many bond-line layers at a normal element size
        let mut spec = LapSpec::reference();
        spec.mesh.y_adhesive = 1 << 40;
        assert!(lap_mesh(&spec).is_err());
    }

    #[test]
    fn reference_lap_mesh_has_graded_bond_line() {
        let spec = LapSpec::reference();
        let mesh = lap_mesh(&spec).unwrap();
        let (xy, _) = adhesive_aspect_ratio(&mesh);
        // 1 mm bond line, 2 layers: 0.5 mm thick elements, 2 mm long at the ends, at most 5 mm
        assert!(xy <= 10.0 * 1.05, "aspect {xy}");
        let n_fixed = mesh.fixed.iter().filter(|&&f| f).count();
        assert!(n_fixed > 0);
        // every fixed node on x = 0
        for (n, &f) in mesh.fixed.iter().enumerate() {
            if f {
                assert_eq!(mesh.nodes[n][0], 0.0);
            }
        }
    }
}
