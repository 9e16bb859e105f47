//! A region of the adhesive (an x-range of the block) and its share of the adhesive
//! stiffness, for a degraded bond:
//!
//! ```text
//!   S = S_rest + S_region,    E* S -> E* (S - d S_region),   d in [0, 1) the loss fraction
//! ```
//!
//! `S_region` is assembled like S (unit modulus, the adhesive's nu) over the adhesive elements
//! whose centroid lies in the range, on S's own sparsity pattern (elements outside the range
//! get a zero modulus), so `S - d S_region` is an entry-wise update. The region is made of
//! whole elements: its effective x-range (reported) is the requested one rounded to the
//! mesh's element boundaries.

use super::assembly::{Assembler, DofMap};
use super::error::FeError;
use super::geometry::Elasticity;
use super::joint::{joint_mesh_from_spec, JointSpec};
use super::mesh::Region;
use super::model::{SpMat, StructuralModel};

/// `S_region` of an x-range of the adhesive.
#[derive(Clone, Debug)]
pub struct RegionStiffness {
    /// Adhesive stiffness of the region's elements at E = 1 Pa (m), on S's pattern.
    pub s_region: SpMat,
    /// Number of adhesive elements in the region.
    pub n_elements: usize,
    /// The x-range (m) the region's elements cover.
    pub x_range_m: (f64, f64),
}

/// Assemble `S_region` over the adhesive elements with centroid in `[x0, x1]` (m). `key`
/// names the input for errors: the range must lie within the adhesive block and hold at
/// least one element.
pub fn adhesive_region_stiffness(
    spec: &JointSpec,
    x0: f64,
    x1: f64,
    key: &str,
) -> Result<RegionStiffness, FeError> {
    region_stiffness(spec, x0, x1, key, false)
}

/// [`adhesive_region_stiffness`] on the DOFs of the joint with its base face free (the model
/// of [`super::base::base_spring_model`]).
pub fn adhesive_region_stiffness_free_base(
    spec: &JointSpec,
    x0: f64,
    x1: f64,
    key: &str,
) -> Result<RegionStiffness, FeError> {
    region_stiffness(spec, x0, x1, key, true)
}

fn region_stiffness(
    spec: &JointSpec,
    x0: f64,
    x1: f64,
    key: &str,
    free_base: bool,
) -> Result<RegionStiffness, FeError> {
    let g = &spec.geometry;
    let (a0, a1) = (
        g.adhesive_x_start_m,
        g.adhesive_x_start_m + g.adhesive_length_m,
    );
    let tol = 1e-9 * g.adhesive_length_m.max(1e-3);
    if !(x0.is_finite() && x1.is_finite() && x1 > x0 && x0 >= a0 - tol && x1 <= a1 + tol) {
        return Err(FeError::InvalidMesh {
            key: key.into(),
            detail: format!(
                "the region x = [{x0}, {x1}] m is not inside the adhesive block x = [{a0}, {a1}] m: give x_start >= {a0} and x_start + width <= {a1} with width > 0"
            ),
        });
    }
    let (mut mesh, _) = joint_mesh_from_spec(spec)?;
    if free_base {
        mesh.fixed.iter_mut().for_each(|f| *f = false);
    }
    let dofs = DofMap::new(&mesh);
    let asm = Assembler::new(&mesh, &dofs);
    let adh = mesh.elements_in(Region::Adhesive);
    let centroid_x = |e: usize| {
        let c = mesh.element_coords(e);
        // The 8 corner nodes come first in a 20-node hexahedron.
        c[..8].iter().map(|p| p[0]).sum::<f64>() / 8.0
    };
    let inside: Vec<bool> = (0..mesh.n_elements())
        .map(|e| mesh.regions[e] == Region::Adhesive && (x0..=x1).contains(&centroid_x(e)))
        .collect();
    let n_elements = inside.iter().filter(|&&b| b).count();
    if n_elements == 0 {
        return Err(FeError::InvalidMesh {
            key: key.into(),
            detail: format!(
                "the region x = [{x0}, {x1}] m holds no adhesive element centroid (element length {:.3e} m): widen it or refine structure.mesh",
                mesh.max_cell_size()[0]
            ),
        });
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (e, _) in inside.iter().enumerate().filter(|(_, &b)| b) {
        for p in &mesh.element_coords(e)[..8] {
            lo = lo.min(p[0]);
            hi = hi.max(p[0]);
        }
    }
    let nu = spec.adhesive_nu;
    let s_region = asm.stiffness(
        &asm.pattern(&adh),
        |e| Elasticity {
            e_pa: if inside[e] { 1.0 } else { 0.0 },
            nu,
        },
        spec.mesh.integration,
    )?;
    Ok(RegionStiffness {
        s_region,
        n_elements,
        x_range_m: (lo, hi),
    })
}

impl StructuralModel {
    /// A copy with the adhesive degraded over a region: `S' = S - d S_region` (`d` the loss
    /// fraction in [0, 1)); `s_region` must have S's pattern ([`adhesive_region_stiffness`]).
    pub fn with_degraded_region(
        &self,
        s_region: &SpMat,
        loss: f64,
    ) -> Result<StructuralModel, String> {
        if !(0.0..1.0).contains(&loss) {
            return Err(format!("bond loss fraction {loss} must be in [0, 1)"));
        }
        let same = s_region.nrows() == self.s.nrows()
            && s_region.symbolic().col_ptr() == self.s.symbolic().col_ptr()
            && s_region.symbolic().row_idx() == self.s.symbolic().row_idx();
        if !same {
            return Err(
                "S_region does not have the pattern of S (assemble it from the same structure)"
                    .into(),
            );
        }
        let mut out = self.clone();
        for (v, r) in out.s.val_mut().iter_mut().zip(s_region.val()) {
            *v -= loss * r;
        }
        out.description = format!("{} + adhesive region degraded by {loss}", self.description);
        Ok(out)
    }
}
