//! Global sparse assembly: the pattern is built once from connectivity and DOF numbering
//! (constrained DOFs eliminated), then values are filled for any element kernel.
//!
//! A = sum_e P_e^T A_e P_e over the chosen elements, with P_e the map from the element's 60
//! DOFs to the free global DOFs (rows/columns of fixed DOFs dropped: u = 0 there).
//! Element matrices are computed in parallel (rayon) in fixed-size chunks and summed
//! sequentially in element order, so the result is bit-identical for any thread count.

use super::element::{Integration, N_DOF, N_NODES};
use super::error::FeError;
use super::geometry::{
    element_mass_into, element_stiffness_into, Elasticity, ElementCoords, NonPositiveJacobian,
};
use super::mesh::HexMesh;
use super::model::SpMat;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

/// Marker for a fixed (eliminated) DOF in [`DofMap::dof_of`].
pub const FIXED: usize = usize::MAX;

/// Global DOF numbering: node-major (DOF of node n, component c at position 3 n + c), free
/// DOFs numbered consecutively in that order, fixed ones marked [`FIXED`].
#[derive(Clone, Debug, PartialEq)]
pub struct DofMap {
    pub dof_of: Vec<usize>,
    pub n_free: usize,
}

impl DofMap {
    /// Number the DOFs of a mesh, eliminating every DOF of its fixed nodes.
    pub fn new(mesh: &HexMesh) -> Self {
        Self::from_fixed(&mesh.fixed)
    }

    /// Number all DOFs (no constraint), e.g. to check the total mass.
    pub fn unconstrained(n_nodes: usize) -> Self {
        Self::from_fixed(&vec![false; n_nodes])
    }

    fn from_fixed(fixed: &[bool]) -> Self {
        let mut dof_of = Vec::with_capacity(3 * fixed.len());
        let mut n = 0;
        for &f in fixed {
            for _ in 0..3 {
                if f {
                    dof_of.push(FIXED);
                } else {
                    dof_of.push(n);
                    n += 1;
                }
            }
        }
        DofMap { dof_of, n_free: n }
    }

    /// Free DOF of (node, component), None when fixed.
    pub fn dof(&self, node: usize, component: usize) -> Option<usize> {
        let d = self.dof_of[3 * node + component];
        (d != FIXED).then_some(d)
    }
}

/// Column-compressed sparsity pattern of the free-DOF matrix assembled from a set of elements.
#[derive(Clone, Debug)]
pub struct Pattern {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    elements: Vec<usize>,
}

impl Pattern {
    /// Pattern of sum over `elements` of P_e^T A_e P_e (full symmetric storage, rows sorted).
    pub fn new(mesh: &HexMesh, dofs: &DofMap, elements: &[usize]) -> Self {
        let nn = mesh.n_nodes();
        // node -> elements (CSR)
        let mut cnt = vec![0usize; nn + 1];
        for &e in elements {
            for &n in &mesh.elements[e] {
                cnt[n + 1] += 1;
            }
        }
        for i in 0..nn {
            cnt[i + 1] += cnt[i];
        }
        let mut fill = cnt.clone();
        let mut n2e = vec![0usize; cnt[nn]];
        for &e in elements {
            for &n in &mesh.elements[e] {
                n2e[fill[n]] = e;
                fill[n] += 1;
            }
        }
        // inverse DOF map
        let mut owner = vec![(0usize, 0usize); dofs.n_free];
        for (g, &d) in dofs.dof_of.iter().enumerate() {
            if d != FIXED {
                owner[d] = (g / 3, g % 3);
            }
        }
        let mut col_ptr = Vec::with_capacity(dofs.n_free + 1);
        col_ptr.push(0);
        let mut row_idx = Vec::new();
        let mut nbr: Vec<usize> = Vec::new();
        let mut last_node = usize::MAX;
        for &(node, _) in &owner {
            if node != last_node {
                nbr.clear();
                for &e in &n2e[cnt[node]..cnt[node + 1]] {
                    nbr.extend_from_slice(&mesh.elements[e]);
                }
                nbr.sort_unstable();
                nbr.dedup();
                last_node = node;
            }
            for &m in &nbr {
                for c in 0..3 {
                    let d = dofs.dof_of[3 * m + c];
                    if d != FIXED {
                        row_idx.push(d);
                    }
                }
            }
            col_ptr.push(row_idx.len());
        }
        Pattern {
            n: dofs.n_free,
            col_ptr,
            row_idx,
            elements: elements.to_vec(),
        }
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// The elements this pattern assembles.
    pub fn elements(&self) -> &[usize] {
        &self.elements
    }

    /// Fill values with an element kernel `kernel(element, coords, out_60x60)` and return
    /// the sparse matrix. Kernels run in parallel; the sum is sequential in element order.
    pub fn fill<F>(&self, mesh: &HexMesh, dofs: &DofMap, kernel: F) -> Result<SpMat, FeError>
    where
        F: Fn(usize, &ElementCoords, &mut [f64]) -> Result<(), NonPositiveJacobian> + Sync,
    {
        const CHUNK: usize = 256;
        let mut val = vec![0.0; self.row_idx.len()];
        let mut bufs = vec![0.0; CHUNK * N_DOF * N_DOF];
        for chunk in self.elements.chunks(CHUNK) {
            let res: Vec<Result<(), FeError>> = chunk
                .par_iter()
                .zip(bufs.par_chunks_mut(N_DOF * N_DOF))
                .map(|(&e, buf)| {
                    kernel(e, &mesh.element_coords(e), buf).map_err(|err| {
                        FeError::DegenerateElement {
                            key: "structure.mesh".into(),
                            element: e,
                            det_j: err.det_j,
                        }
                    })
                })
                .collect();
            for r in res {
                r?;
            }
            for (&e, buf) in chunk.iter().zip(bufs.chunks(N_DOF * N_DOF)) {
                self.scatter(mesh, dofs, e, buf, &mut val);
            }
        }
        let symbolic = SymbolicSparseColMat::new_checked(
            self.n,
            self.n,
            self.col_ptr.clone(),
            None,
            self.row_idx.clone(),
        );
        Ok(SparseColMat::new(symbolic, val))
    }

    fn scatter(&self, mesh: &HexMesh, dofs: &DofMap, e: usize, ae: &[f64], val: &mut [f64]) {
        let mut ld = [FIXED; N_DOF];
        for (a, &n) in mesh.elements[e].iter().enumerate() {
            for c in 0..3 {
                ld[3 * a + c] = dofs.dof_of[3 * n + c];
            }
        }
        for (k, &gc) in ld.iter().enumerate() {
            if gc == FIXED {
                continue;
            }
            let (s, t) = (self.col_ptr[gc], self.col_ptr[gc + 1]);
            let rows = &self.row_idx[s..t];
            // A_e is symmetric, so its row-major column k is row k
            let col = &ae[k * N_DOF..(k + 1) * N_DOF];
            for (r, &gr) in ld.iter().enumerate() {
                if gr == FIXED {
                    continue;
                }
                // the pattern holds every (gr, gc) of this element by construction
                if let Ok(p) = rows.binary_search(&gr) {
                    val[s + p] += col[r];
                }
            }
        }
    }
}

/// Assembles M, stiffness matrices over a mesh with a fixed DOF numbering.
pub struct Assembler<'a> {
    pub mesh: &'a HexMesh,
    pub dofs: &'a DofMap,
}

impl<'a> Assembler<'a> {
    pub fn new(mesh: &'a HexMesh, dofs: &'a DofMap) -> Self {
        Assembler { mesh, dofs }
    }

    /// Pattern of the given elements.
    pub fn pattern(&self, elements: &[usize]) -> Pattern {
        Pattern::new(self.mesh, self.dofs, elements)
    }

    /// Consistent mass over `pattern`'s elements, density `rho_of(element)` (kg/m^3).
    pub fn mass(
        &self,
        pattern: &Pattern,
        rho_of: impl Fn(usize) -> f64 + Sync,
    ) -> Result<SpMat, FeError> {
        pattern.fill(self.mesh, self.dofs, |e, c, out| {
            element_mass_into(c, rho_of(e), out)
        })
    }

    /// Isotropic elastic stiffness over `pattern`'s elements with `mat_of(element)`.
    pub fn stiffness(
        &self,
        pattern: &Pattern,
        mat_of: impl Fn(usize) -> Elasticity + Sync,
        rule: Integration,
    ) -> Result<SpMat, FeError> {
        pattern.fill(self.mesh, self.dofs, |e, c, out| {
            element_stiffness_into(c, mat_of(e), rule, out)
        })
    }
}

// keep N_NODES referenced for readers of the DOF layout (3 per node)
const _: () = assert!(N_DOF == 3 * N_NODES);
