//! Measurement point -> DOF map.
//!
//! A point p on the beam surface, direction +-e_c, observes u_p = sign sum_a N_a(xi_p) u_(a,c)
//! where xi_p are p's natural coordinates in the beam element containing it (the shape
//! functions of nodes off the face vanish, so only the face's 8 nodes enter). By reciprocity
//! the same weights distribute a point force f e_c (f_(a,c) = sign N_a(xi_p) f): the map is
//! consistent. A point on a node uses that node's DOF alone (weight = sign); with
//! [`PointMapping::Snap`] a point between nodes is moved to the nearest node and the
//! [`ObservationPoint::note`] says so.

use super::assembly::DofMap;
use super::element::{shape_values, NODE_XI, N_NODES};
use super::error::FeError;
use super::mesh::{HexMesh, Region};
use super::model::ObservationPoint;
use crate::common::Direction;

/// How a point that is not on a node is mapped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum PointMapping {
    /// Shape-function interpolation on the element face (default).
    #[default]
    Interpolate,
    /// Move the point to the nearest node of its element face.
    Snap,
}

/// Tolerance on "on the surface" and "on the beam" (m).
pub const SURFACE_TOL_M: f64 = 1e-6;
/// Relative tolerance (to the smallest element size) for "on a node".
pub const NODE_TOL_REL: f64 = 1e-9;

fn key(index: usize, field: &str) -> String {
    format!("structure.points[{index}].{field}")
}

/// Map point number `index` (its position in the study's list, for error keys) to free DOFs.
///
/// `beam_lo`, `beam_hi`: the beam's bounding box (m); the point must be on its surface.
#[allow(clippy::too_many_arguments)]
pub fn map_point(
    mesh: &HexMesh,
    dofs: &DofMap,
    beam_lo: [f64; 3],
    beam_hi: [f64; 3],
    index: usize,
    id: u32,
    position_m: [f64; 3],
    direction: Direction,
    mapping: PointMapping,
) -> Result<ObservationPoint, FeError> {
    if direction.sign != 1 && direction.sign != -1 {
        return Err(FeError::InvalidPointDirection {
            key: key(index, "direction"),
            detail: format!(
                "point {id}: direction sign {} is not +1 or -1",
                direction.sign
            ),
        });
    }
    let p = position_m;
    let off_err = |d: f64| FeError::PointOffBeam {
        key: key(index, "position"),
        id,
        x: p[0],
        y: p[1],
        z: p[2],
        distance_m: d,
    };
    if p.iter().any(|v| !v.is_finite()) {
        return Err(off_err(f64::INFINITY));
    }
    // distance outside the box
    let mut out2 = 0.0;
    let mut q = p;
    for d in 0..3 {
        let o = (beam_lo[d] - p[d]).max(p[d] - beam_hi[d]).max(0.0);
        out2 += o * o;
        q[d] = p[d].clamp(beam_lo[d], beam_hi[d]);
    }
    if out2.sqrt() > SURFACE_TOL_M {
        return Err(off_err(out2.sqrt()));
    }
    // nearest face; project onto it
    let mut best = (f64::INFINITY, 0usize, 0.0f64);
    for d in 0..3 {
        for v in [beam_lo[d], beam_hi[d]] {
            let dist = (q[d] - v).abs();
            if dist < best.0 {
                best = (dist, d, v);
            }
        }
    }
    if best.0 > SURFACE_TOL_M {
        return Err(FeError::PointNotOnSurface {
            key: key(index, "position"),
            id,
            x: p[0],
            y: p[1],
            z: p[2],
            distance_m: best.0,
        });
    }
    q[best.1] = best.2;

    // containing beam element via the structured grid
    let g = &mesh.grid;
    let axes = [&g.xs, &g.ys, &g.zs];
    let cells = |d: usize| -> Vec<usize> {
        let v = axes[d];
        let n = v.len() - 1;
        (0..n)
            .filter(|&i| q[d] >= v[i] - SURFACE_TOL_M && q[d] <= v[i + 1] + SURFACE_TOL_M)
            .collect()
    };
    let (ci, cj, ck) = (cells(0), cells(1), cells(2));
    let mut found = None;
    'search: for &i in &ci {
        for &j in &cj {
            for &k in &ck {
                if let Some(e) = g.element_at(i, j, k) {
                    if mesh.regions[e] == Region::Beam {
                        found = Some((e, [i, j, k]));
                        break 'search;
                    }
                }
            }
        }
    }
    let (e, cell) = found.ok_or_else(|| off_err(0.0))?;
    let mut xi = [0.0; 3];
    for d in 0..3 {
        let (a, b) = (axes[d][cell[d]], axes[d][cell[d] + 1]);
        xi[d] = (2.0 * (q[d] - a) / (b - a) - 1.0).clamp(-1.0, 1.0);
    }
    let conn = &mesh.elements[e];
    let c = direction.axis.index();
    let sign = direction.sign as f64;
    let tol = NODE_TOL_REL * mesh.min_cell_size();
    // nearest node of the element (in natural coordinates' physical scale)
    let mut near = (f64::INFINITY, 0usize);
    for (a, &n) in conn.iter().enumerate() {
        let x = mesh.nodes[n];
        let dist = ((x[0] - q[0]).powi(2) + (x[1] - q[1]).powi(2) + (x[2] - q[2]).powi(2)).sqrt();
        // only nodes on the projected face (xi of that axis equal)
        if NODE_XI[a][best.1] != xi[best.1] {
            continue;
        }
        if dist < near.0 {
            near = (dist, a);
        }
    }
    let single = |node: usize, note: String| ObservationPoint {
        id,
        position: Some(position_m),
        direction,
        dofs: dofs
            .dof(node, c)
            .map(|d| vec![(d, sign)])
            .unwrap_or_default(),
        note,
    };
    if near.0 <= tol {
        let node = conn[near.1];
        let note = if dofs.dof(node, c).is_none() {
            format!("on node {node}, which is fixed")
        } else {
            String::new()
        };
        return Ok(single(node, note));
    }
    match mapping {
        PointMapping::Snap => {
            let node = conn[near.1];
            Ok(single(
                node,
                format!("snapped to node {node} ({:.3} mm away)", near.0 * 1e3),
            ))
        }
        PointMapping::Interpolate => {
            let mut n = [0.0; N_NODES];
            shape_values(xi, &mut n);
            let mut list = Vec::new();
            for (a, &na) in n.iter().enumerate() {
                if na.abs() <= 1e-14 {
                    continue;
                }
                if let Some(d) = dofs.dof(conn[a], c) {
                    list.push((d, sign * na));
                }
            }
            list.sort_by_key(|x| x.0);
            Ok(ObservationPoint {
                id,
                position: Some(position_m),
                direction,
                dofs: list,
                note: format!(
                    "interpolated in element {e} at natural coordinates ({:.4}, {:.4}, {:.4})",
                    xi[0], xi[1], xi[2]
                ),
            })
        }
    }
}
