//! Structured meshes of 20-node hexahedra: the bonded joint (beam on an adhesive block) and a
//! plain box (for the cantilever check).
//!
//! A mesh is a tensor grid of cells (cell boundaries `xs`, `ys`, `zs`), some of which hold an
//! element. Nodes live on the "lattice" of half-cells: lattice index 2 i is the grid line
//! `xs[i]`, 2 i + 1 the cell midpoint. A 20-node element of cell (i, j, k) uses the lattice
//! points (2 i + xi + 1, 2 j + eta + 1, 2 k + zeta + 1) for its reference nodes
//! (xi, eta, zeta) (see [`super::element::NODE_XI`]). Elements sharing a lattice point share
//! the node, so the beam and the adhesive are merged on the bond face y = 0 (perfect bond).
//! Nodes are numbered lattice-x-major (x outermost), which keeps the bandwidth small along
//! the long beam.

use super::element::{NODE_XI, N_NODES};
use super::geometry::ElementCoords;

/// Which part of the structure an element belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Region {
    /// The adherend (steel beam): contributes to M and K_b.
    Beam,
    /// The adhesive: contributes to M and S.
    Adhesive,
}

/// The grid behind a structured mesh, kept for point location.
#[derive(Clone, Debug, PartialEq)]
pub struct StructuredGrid {
    /// Cell boundaries along x, y, z (m), strictly increasing.
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    pub zs: Vec<f64>,
    /// Element index of cell (i, j, k) at `i + nx (j + ny k)`, `usize::MAX` when empty.
    pub cell_element: Vec<usize>,
}

impl StructuredGrid {
    pub fn n_cells(&self) -> [usize; 3] {
        [self.xs.len() - 1, self.ys.len() - 1, self.zs.len() - 1]
    }

    /// Element in cell (i, j, k), if any.
    pub fn element_at(&self, i: usize, j: usize, k: usize) -> Option<usize> {
        let [nx, ny, nz] = self.n_cells();
        if i >= nx || j >= ny || k >= nz {
            return None;
        }
        let e = self.cell_element[i + nx * (j + ny * k)];
        (e != usize::MAX).then_some(e)
    }
}

/// A mesh of 20-node hexahedra with region tags and fixed nodes.
#[derive(Clone, Debug, PartialEq)]
pub struct HexMesh {
    /// Node coordinates (m).
    pub nodes: Vec<[f64; 3]>,
    /// Element connectivity in the reference node order.
    pub elements: Vec<[usize; N_NODES]>,
    /// Region of each element.
    pub regions: Vec<Region>,
    /// Nodes whose three DOFs are fixed (u = 0).
    pub fixed: Vec<bool>,
    /// The structured grid the mesh was generated from.
    pub grid: StructuredGrid,
}

impl HexMesh {
    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }
    pub fn n_elements(&self) -> usize {
        self.elements.len()
    }
    /// Node coordinates of element `e`.
    pub fn element_coords(&self, e: usize) -> ElementCoords {
        let mut c = [[0.0; 3]; N_NODES];
        for (ca, &n) in c.iter_mut().zip(&self.elements[e]) {
            *ca = self.nodes[n];
        }
        c
    }
    /// Indices of the elements of one region, in increasing order.
    pub fn elements_in(&self, region: Region) -> Vec<usize> {
        (0..self.n_elements())
            .filter(|&e| self.regions[e] == region)
            .collect()
    }
    /// Largest element edge length per direction (m).
    pub fn max_cell_size(&self) -> [f64; 3] {
        let f = |v: &[f64]| v.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
        [f(&self.grid.xs), f(&self.grid.ys), f(&self.grid.zs)]
    }
    /// Smallest element edge length over all directions (m).
    pub fn min_cell_size(&self) -> f64 {
        let f = |v: &[f64]| {
            v.windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min)
        };
        f(&self.grid.xs).min(f(&self.grid.ys)).min(f(&self.grid.zs))
    }
}

/// Number of equal parts for a segment of length `len` with target element size `h`:
/// ceil(len / h) (with a 1e-9 relative slack so that 0.3 / 0.01 gives 30), at least 1.
pub fn segment_divisions(len: f64, h: f64) -> usize {
    segment_divisions_f64(len, h) as usize
}

/// [`segment_divisions`] as a float, for counting a mesh before making it: a count far beyond
/// what can be allocated does not saturate.
pub fn segment_divisions_f64(len: f64, h: f64) -> f64 {
    let r = len / h;
    (r - 1e-9 * r.max(1.0)).ceil().max(1.0)
}

/// Partition of [a, b] graded towards its ends: from a graded end the element sizes are
/// h_e, r h_e, r^2 h_e, ... (geometric growth) up to the element size h; the rest is divided
/// into equal elements of at most h. `grade_a`, `grade_b`: the end sizes h_e at a and b (None:
/// no grading there). When the graded runs do not fit, they are shortened; a leftover too short
/// for a cell of its own is spread over the others.
pub fn graded_partition(
    a: f64,
    b: f64,
    grade_a: Option<f64>,
    grade_b: Option<f64>,
    h: f64,
    r: f64,
) -> Vec<f64> {
    let len = b - a;
    let run = |he: f64| {
        let mut v = Vec::new();
        let mut s = he.min(h);
        while s < h * (1.0 - 1e-9) && v.len() < 10_000 {
            v.push(s);
            if r <= 1.0 {
                break;
            }
            s *= r;
        }
        v
    };
    let mut left = grade_a.map(run).unwrap_or_default();
    let mut right = grade_b.map(run).unwrap_or_default();
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    while sum(&left) + sum(&right) > len && !(left.is_empty() && right.is_empty()) {
        let (l, r_) = (left.last().copied(), right.last().copied());
        if l.unwrap_or(0.0) >= r_.unwrap_or(0.0) {
            left.pop();
        } else {
            right.pop();
        }
    }
    let mid = len - sum(&left) - sum(&right);
    let mut sizes = left.clone();
    let smallest_neighbour = left
        .last()
        .copied()
        .unwrap_or(h)
        .min(right.last().copied().unwrap_or(h));
    if mid > 1e-12 * len {
        let n = segment_divisions(mid, h);
        let s = mid / n as f64;
        if s >= 0.5 * smallest_neighbour || (left.is_empty() && right.is_empty()) {
            sizes.extend(std::iter::repeat_n(s, n));
        }
    }
    sizes.extend(right.iter().rev());
    let k = len / sum(&sizes);
    let mut out = Vec::with_capacity(sizes.len() + 1);
    out.push(a);
    let mut acc = a;
    for (i, s) in sizes.iter().enumerate() {
        acc += s * k;
        out.push(if i + 1 == sizes.len() { b } else { acc });
    }
    out
}

/// `n` equal cells on [a, b] appended to `out` (which already ends with `a` unless empty).
fn push_segment(out: &mut Vec<f64>, a: f64, b: f64, n: usize) {
    if out.is_empty() {
        out.push(a);
    }
    for i in 1..=n {
        out.push(if i == n {
            b
        } else {
            a + (b - a) * i as f64 / n as f64
        });
    }
}

/// Build a structured mesh from cell boundaries, a cell -> region rule and a lattice fixity
/// rule `fixed(I, J, K)` on lattice indices.
pub fn structured_mesh(
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    region_of_cell: impl Fn(usize, usize, usize) -> Option<Region>,
    fixed: impl Fn(usize, usize, usize) -> bool,
) -> HexMesh {
    let (nx, ny, nz) = (xs.len() - 1, ys.len() - 1, zs.len() - 1);
    let (lx, ly, lz) = (2 * nx + 1, 2 * ny + 1, 2 * nz + 1);
    let lat = |i: usize, j: usize, k: usize| (i * ly + j) * lz + k;
    let mut cell_element = vec![usize::MAX; nx * ny * nz];
    let mut cells = Vec::new();
    // element order: x outermost, like the nodes
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                if let Some(r) = region_of_cell(i, j, k) {
                    cell_element[i + nx * (j + ny * k)] = cells.len();
                    cells.push(((i, j, k), r));
                }
            }
        }
    }
    let mut node_of = vec![usize::MAX; lx * ly * lz];
    for &((i, j, k), _) in &cells {
        for xi in NODE_XI.iter() {
            let (a, b, c) = (
                2 * i + (xi[0] + 1.0) as usize,
                2 * j + (xi[1] + 1.0) as usize,
                2 * k + (xi[2] + 1.0) as usize,
            );
            node_of[lat(a, b, c)] = 0;
        }
    }
    let coord = |v: &[f64], l: usize| {
        if l.is_multiple_of(2) {
            v[l / 2]
        } else {
            0.5 * (v[l / 2] + v[l / 2 + 1])
        }
    };
    let mut nodes = Vec::new();
    let mut is_fixed = Vec::new();
    for a in 0..lx {
        for b in 0..ly {
            for c in 0..lz {
                let id = lat(a, b, c);
                if node_of[id] == 0 {
                    node_of[id] = nodes.len();
                    nodes.push([coord(&xs, a), coord(&ys, b), coord(&zs, c)]);
                    is_fixed.push(fixed(a, b, c));
                }
            }
        }
    }
    let mut elements = Vec::with_capacity(cells.len());
    let mut regions = Vec::with_capacity(cells.len());
    for &((i, j, k), r) in &cells {
        let mut conn = [0usize; N_NODES];
        for (cn, xi) in conn.iter_mut().zip(NODE_XI.iter()) {
            *cn = node_of[lat(
                2 * i + (xi[0] + 1.0) as usize,
                2 * j + (xi[1] + 1.0) as usize,
                2 * k + (xi[2] + 1.0) as usize,
            )];
        }
        elements.push(conn);
        regions.push(r);
    }
    HexMesh {
        nodes,
        elements,
        regions,
        fixed: is_fixed,
        grid: StructuredGrid {
            xs,
            ys,
            zs,
            cell_element,
        },
    }
}

/// Which face of a box is clamped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClampedFace {
    /// Nothing fixed (free-free).
    None,
    /// The face x = 0.
    XMin,
}

/// A box [0, lx] x [0, ly] x [0, lz] of beam elements with `n[d]` equal divisions per direction.
pub fn box_mesh(size_m: [f64; 3], n: [usize; 3], clamp: ClampedFace) -> HexMesh {
    let mut g: [Vec<f64>; 3] = Default::default();
    for d in 0..3 {
        push_segment(&mut g[d], 0.0, size_m[d], n[d].max(1));
    }
    let [xs, ys, zs] = g;
    structured_mesh(
        xs,
        ys,
        zs,
        |_, _, _| Some(Region::Beam),
        |i, _, _| clamp == ClampedFace::XMin && i == 0,
    )
}

/// Divisions of the joint per segment, after resolution of the mesh size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JointDivisions {
    /// x divisions of [0, x0], [x0, x0 + L_a], [x0 + L_a, L] (0 for an empty segment).
    pub x: [usize; 3],
    pub y_adhesive: usize,
    pub y_beam: usize,
    pub z: usize,
}

/// Joint layout (m): beam [0, L] x [0, t_b] x [0, w], adhesive [x0, x0 + L_a] x [-t_a, 0] x [0, w].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLayout {
    pub beam_length_m: f64,
    pub beam_thickness_m: f64,
    pub width_m: f64,
    pub adhesive_x_start_m: f64,
    pub adhesive_length_m: f64,
    pub adhesive_thickness_m: f64,
}

/// Cell boundaries of the joint's tensor grid along x, y and z, with the adhesive's cells along
/// x (`adh_cells.0..adh_cells.1`) and the adhesive's layers along y (`0..ny_a`; the beam's
/// follow).
#[derive(Clone, Debug, PartialEq)]
pub struct JointGrid {
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    pub zs: Vec<f64>,
    pub adh_cells: (usize, usize),
    pub ny_a: usize,
}

impl JointGrid {
    /// Equal cells per segment: the divisions `div` of [0, x0], [x0, x1], [x1, L], the adhesive's
    /// and the beam's thickness, and the width.
    pub fn uniform(layout: &JointLayout, div: &JointDivisions) -> JointGrid {
        let l = layout;
        let x0 = l.adhesive_x_start_m;
        let x1 = x0 + l.adhesive_length_m;
        let bounds = [(0.0, x0), (x0, x1), (x1, l.beam_length_m)];
        let mut xs = Vec::new();
        let mut adh_cells = (0usize, 0usize);
        for (s, &(a, b)) in bounds.iter().enumerate() {
            if div.x[s] == 0 || b <= a {
                continue;
            }
            let start = xs.len().saturating_sub(1);
            push_segment(&mut xs, a, b, div.x[s]);
            if s == 1 {
                adh_cells = (start, start + div.x[s]);
            }
        }
        let mut ys = Vec::new();
        push_segment(&mut ys, -l.adhesive_thickness_m, 0.0, div.y_adhesive);
        push_segment(&mut ys, 0.0, l.beam_thickness_m, div.y_beam);
        let mut zs = Vec::new();
        push_segment(&mut zs, 0.0, l.width_m, div.z);
        JointGrid {
            xs,
            ys,
            zs,
            adh_cells,
            ny_a: div.y_adhesive,
        }
    }

    /// Cells graded towards the bond line's edges, where its stresses are singular: along x
    /// towards both ends of the adhesive (inside it and in the beam beside it), along y
    /// towards both faces of the bond line, along z towards both sides. From an edge the sizes
    /// are `h_edge`, `r h_edge`, `r^2 h_edge`, ... up to `h` (in the bond line's thickness up to
    /// half of it); the beam's thickness gets `y_beam` equal cells.
    pub fn graded(layout: &JointLayout, h: f64, h_edge: f64, r: f64, y_beam: usize) -> JointGrid {
        let l = layout;
        let x0 = l.adhesive_x_start_m;
        let x1 = x0 + l.adhesive_length_m;
        let t_a = l.adhesive_thickness_m;
        let he = Some(h_edge.min(h));
        let mut xs: Vec<f64> = Vec::new();
        let append = |part: Vec<f64>, xs: &mut Vec<f64>| {
            let skip = usize::from(!xs.is_empty());
            xs.extend(part.into_iter().skip(skip));
        };
        if x0 > 0.0 {
            append(graded_partition(0.0, x0, None, he, h, r), &mut xs);
        }
        let start = xs.len().saturating_sub(1);
        append(graded_partition(x0, x1, he, he, h, r), &mut xs);
        let adh_cells = (start, xs.len() - 1);
        if x1 < l.beam_length_m {
            append(
                graded_partition(x1, l.beam_length_m, he, None, h, r),
                &mut xs,
            );
        }
        let mut ys = graded_partition(-t_a, 0.0, he, he, (0.5 * t_a).min(h), r);
        let ny_a = ys.len() - 1;
        push_segment(&mut ys, 0.0, l.beam_thickness_m, y_beam);
        let zs = graded_partition(0.0, l.width_m, he, he, h, r);
        JointGrid {
            xs,
            ys,
            zs,
            adh_cells,
            ny_a,
        }
    }

    /// Every cell split into `f` equal parts per direction.
    pub fn split(&self, f: usize) -> JointGrid {
        let f = f.max(1);
        let split = |v: &[f64]| {
            let mut out = vec![v[0]];
            for w in v.windows(2) {
                for i in 1..=f {
                    out.push(if i == f {
                        w[1]
                    } else {
                        w[0] + (w[1] - w[0]) * i as f64 / f as f64
                    });
                }
            }
            out
        };
        JointGrid {
            xs: split(&self.xs),
            ys: split(&self.ys),
            zs: split(&self.zs),
            adh_cells: (self.adh_cells.0 * f, self.adh_cells.1 * f),
            ny_a: self.ny_a * f,
        }
    }

    /// Cell counts per segment (for the cost estimate).
    pub fn divisions(&self) -> JointDivisions {
        let nx = self.xs.len() - 1;
        JointDivisions {
            x: [
                self.adh_cells.0,
                self.adh_cells.1 - self.adh_cells.0,
                nx - self.adh_cells.1,
            ],
            y_adhesive: self.ny_a,
            y_beam: self.ys.len() - 1 - self.ny_a,
            z: self.zs.len() - 1,
        }
    }
}

/// Mesh of the bonded joint: beam + adhesive, nodes merged on y = 0, every node of the
/// adhesive's lower face y = -t_a fixed.
pub fn joint_mesh(layout: &JointLayout, div: &JointDivisions) -> HexMesh {
    joint_mesh_on(JointGrid::uniform(layout, div))
}

/// [`joint_mesh`] on a given grid.
pub fn joint_mesh_on(grid: JointGrid) -> HexMesh {
    let JointGrid {
        xs,
        ys,
        zs,
        adh_cells,
        ny_a,
    } = grid;
    structured_mesh(
        xs,
        ys,
        zs,
        |i, j, _| {
            if j >= ny_a {
                Some(Region::Beam)
            } else if i >= adh_cells.0 && i < adh_cells.1 {
                Some(Region::Adhesive)
            } else {
                None
            }
        },
        |_, j, _| j == 0,
    )
}
