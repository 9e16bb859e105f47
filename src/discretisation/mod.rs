//! The mesher's joint to a stated accuracy, and the discretisation error it leaves
//! (docs/method.md, "The mesh's discretisation error").
//!
//! **Where the error is.** The bond line meets the adherend and the base at corners where a
//! nearly incompressible layer bonded to stiff faces has singular stresses. A uniform mesh
//! converges slowly there: the paper's block under uniform 5 mm cells is 2.9 % stiff in its
//! first y mode; refining the whole mesh costs eight times the DOFs per halving. Cells graded
//! towards the bond line's edges put the work where the error is: the element size away from
//! the edges (5 mm) barely matters (halving it moves the paper block's modes by 1e-4), the
//! size of the edge cells does.
//!
//! **The refinement** ([`select`]): a family of graded meshes with the study's element size
//! `h` away from the edges, growth ratio `r` (`grading_ratio`, default
//! [`DEFAULT_GRADING_RATIO`]) and edge cells `e_k = e_0 / 2^k`, `e_0 = min(h, t_a / 2)` (level 0
//! is the uniform mesh where the bond line is at least two cells thick). Each level adds a few
//! cells per edge, so the DOFs grow slowly (the paper's block: 10 248, 16 482, 27 360 and
//! 45 918 DOFs for levels 0-3). From level 1 on, the estimate of the finest level's error
//! (below) is compared with the tolerance; refinement stops when every mode's estimate is below it, or when the
//! next level would exceed [`MAX_AUTO_DOFS`] or the machine's memory (the estimate then says
//! how far the mesh is from the tolerance).
//!
//! **The estimate** (three meshes, as the grid-convergence index): with f_k the frequency of a
//! mode on level k, the error of level k is its step from level k - 1 extrapolated at order
//! [`ORDER`] = 1: e_k = (f_{k-1} - f_k) / (2^1 - 1). The observed order
//! p = log2((f_{k-2} - f_{k-1}) / (f_{k-1} - f_k)) is reported; where the three meshes do not
//! converge monotonically, or only two meshes fit under [`MAX_AUTO_DOFS`] (a thin bond line
//! whose first mesh is already large), the estimate is twice the last step. Why order 1: the observed order
//! of these graded families is irregular while the edge cells are larger than about a quarter
//! of the bond line's thickness (0.3-0.5) and 1.2-1.6 after, and the singular corners bound it
//! near 1. Against eight independent 27-node references (docs/validation.md, "The mesh to a
//! tolerance": blocks of 3-8 mm, bond lines of 0.5-3 mm, a lap joint) the actual error of the
//! first measured mode is 0.38-1.38 times the estimate, 0.81 on average with an sd of 0.40
//! (the paper's block at 0.625 mm edge cells: estimated 0.32 %, found 0.21 %; a 3 mm bond line
//! at 0.375 mm: 0.36 % against 0.50 %, with the reference's own extrapolation uncertain): the
//! estimate is a scale, not a bound, and the allowance carries that spread
//! ([`ESTIMATE_SHARE_CENTRE`], [`ESTIMATE_SHARE_SD`]).
//!
//! **What is left** ([`stiffness_excess`]): a mode k with a share phi_k of its strain energy in
//! the adhesive moves by 2 e_k / f_k = phi_k delta_a + (1 - phi_k) delta_b when the adhesive's
//! stiffness on the mesh exceeds the continuum's by the factor (1 + delta_a) and the
//! adherends' by (1 + delta_b). Both are fitted over the modes the points see (weighted by
//! their measured share; delta_b only where the lowest measured mode is mostly the
//! adherends', as in a lap joint; zero on a beam on a block). A lap joint's modes hold 1-13 % of their strain
//! energy in the bond line: there the strips' bending and the clamp are most of the error,
//! and charging it to the adhesive would move its modulus by tens of percent. With the
//! allowance the model's adhesive stiffness S is divided by (1 + [`ESTIMATE_SHARE_CENTRE`]
//! delta_a) and the adherends' K_b by (1 + [`ESTIMATE_SHARE_CENTRE`] delta_b), and the
//! posteriors carry the uncertainty of these corrections and what they leave of each mode's
//! error ([`crate::bayes::mesh_allowance`]).

use crate::fe::cost::CostEstimate;
use crate::fe::joint::{build_joint_model, joint_cost_estimate, JointSpec, MeshInfo, MeshSize};
use crate::fe::lap::{build_lap_model, lap_cost_estimate, LapSpec};
use crate::fe::{FeError, StructuralModel};
use std::sync::Mutex;
use std::time::Instant;

/// The largest cell when a study gives neither an element size nor divisions (m).
pub const DEFAULT_ELEMENT_SIZE_M: f64 = 0.005;
/// Growth ratio of the refined family when the study gives no `grading_ratio`.
pub const DEFAULT_GRADING_RATIO: f64 = 1.5;
/// Order of convergence the estimate assumes (module doc): the bond line's singular corners
/// bound the asymptotic order near 1 in the edge cells' size, and the observed order of the
/// graded family is irregular before it is reached.
pub const ORDER: f64 = 1.0;
/// The actual error as a share of the estimate, its centre and sd: against eight independent
/// converged references the first measured mode's actual error is 0.81 +- 0.40 times the
/// order-1 estimate (module doc). The model's stiffnesses are corrected by `CENTRE` times the
/// estimated excess, and the posteriors carry the sd ([`crate::bayes::mesh_allowance`]).
pub const ESTIMATE_SHARE_CENTRE: f64 = 0.8;
/// See [`ESTIMATE_SHARE_CENTRE`]: its 95 % band runs from nearly no error to 1.6 times the
/// estimate.
pub const ESTIMATE_SHARE_SD: f64 = 0.4;
/// Factor on the last step of a mode whose three meshes do not converge monotonically.
pub const NON_MONOTONE_FACTOR: f64 = 2.0;
/// Modes whose error is estimated (the lowest ones, at the reference modulus).
pub const N_MODES: usize = 6;
/// Most free DOFs the refinement goes to: the reduced model's build stays under a minute on 2
/// cores and the full engine's memory under 10 GiB, and the choice does not depend on the
/// machine (a machine without that memory is told so before anything is computed).
pub const MAX_AUTO_DOFS: usize = 60_000;
/// Most refinement levels.
pub const MAX_LEVELS: usize = 8;

/// One mesh of the refinement.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MeshLevel {
    /// Refinement level (0 = the study's element size without grading).
    pub level: usize,
    /// Size of the cells at the bond line's edges (m).
    pub edge_m: f64,
    pub n_dof: usize,
    pub n_elements: usize,
    /// The lowest modes at the reference modulus (Hz).
    pub freqs_hz: Vec<f64>,
    /// Assembly and eigen-solution (s).
    pub seconds: f64,
}

/// One mode's estimated discretisation error on the mesh used.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ModeError {
    /// Mode number (1 = lowest).
    pub mode: usize,
    /// Frequency on the mesh used (Hz).
    pub freq_hz: f64,
    /// On the next finer mesh of the comparison (Hz).
    pub freq_refined_hz: f64,
    /// Estimated f_h - f (Hz; positive: the mesh is stiff).
    pub error_hz: f64,
    /// error_hz / freq_hz.
    pub rel_error: f64,
    /// Order of convergence used (module doc).
    pub order: f64,
    /// Share of the mode's strain energy in the adhesive.
    pub adhesive_share: f64,
    /// Share of its kinetic energy along the axes the study's points measure (the modes the
    /// data see; the weight of the mode in the stiffness excess).
    pub measured_share: f64,
}

/// How the mesh was chosen and what error it leaves.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Discretisation {
    /// `refined` (to the tolerance) or `fixed` (the study's mesh, estimated on it refined
    /// twice per direction).
    pub rule: String,
    pub tolerance: f64,
    /// Whether every mode's estimated error is below the tolerance.
    pub reached: bool,
    /// The refinement's meshes (empty for a fixed mesh).
    pub levels: Vec<MeshLevel>,
    /// Index into `levels` of the mesh used.
    pub chosen: usize,
    pub modes: Vec<ModeError>,
    /// The adhesive's stiffness on the mesh over the continuum's, minus 1 (module doc).
    pub stiffness_excess: f64,
    /// Its standard deviation.
    pub stiffness_excess_sd: f64,
    /// The adherends' stiffness on the mesh over the continuum's, minus 1 (module doc).
    pub adherend_excess: f64,
    /// Its standard deviation.
    pub adherend_excess_sd: f64,
    /// Whether the posteriors carry the error (`structure.mesh.allowance`,
    /// [`crate::bayes::mesh_allowance`]).
    pub allowance: bool,
    /// The storage modulus the modes were computed at (Pa).
    pub reference_modulus_pa: f64,
    /// Why the tolerance was not reached, when it was not.
    pub note: String,
}

impl Discretisation {
    /// The largest estimated relative error over the modes.
    pub fn worst_rel_error(&self) -> f64 {
        worst_rel_error(&self.modes)
    }

    /// The mode the points see (most of its kinetic energy along the measured axes) nearest
    /// `f_hz`.
    pub fn measured_mode_near(&self, f_hz: f64) -> Option<&ModeError> {
        self.modes
            .iter()
            .filter(|m| m.measured_share > 0.5)
            .min_by(|a, b| {
                (a.freq_hz - f_hz)
                    .abs()
                    .total_cmp(&(b.freq_hz - f_hz).abs())
            })
    }
}

/// The largest estimated relative error of `modes`.
fn worst_rel_error(modes: &[ModeError]) -> f64 {
    modes.iter().map(|m| m.rel_error.abs()).fold(0.0, f64::max)
}

/// The refinement's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineParams {
    pub tolerance: f64,
    pub allowance: bool,
    /// Storage modulus of the adhesive for the modes (Pa).
    pub reference_modulus_pa: f64,
}

/// Per mode: frequency (Hz), adhesive share of the strain energy, share of the kinetic energy
/// along the measured axes.
pub type ModeShares = (Vec<f64>, Vec<f64>, Vec<f64>);

/// The lowest `n` modes of a mesher's model at the storage modulus `e`: frequencies (Hz),
/// adhesive shares of the strain energy and shares of the kinetic energy along the axes in
/// `measured` (the mesher numbers free DOFs three per node, x, y, z, as
/// [`crate::study::build::BuiltModel::dof_axes`] says; with every axis measured the share is 1
/// whatever the numbering).
pub fn modes_with_shares(
    model: &StructuralModel,
    e: f64,
    n: usize,
    measured: &[bool; 3],
) -> Result<ModeShares, String> {
    let k = crate::modes::real::sp_add(&model.k_b, &model.s, e).map_err(|e| e.to_string())?;
    let n = n.min(model.n_dof() / 3).max(1);
    // the frequencies converge as the square of the residual: 1e-6 gives them to ~1e-12
    let params = crate::modes::EigenParams {
        tol: 1e-6,
        ..crate::modes::EigenParams::default()
    };
    let (lam, x) = crate::modes::real_modes(&k, &model.m, n, &params).map_err(|e| e.to_string())?;
    let nd = model.n_dof();
    let mut y = vec![0.0; nd];
    let mut shares = Vec::with_capacity(lam.len());
    let mut seen = Vec::with_capacity(lam.len());
    for j in 0..lam.len() {
        let v: Vec<f64> = (0..nd).map(|i| x[(i, j)]).collect();
        let quad = |a: &crate::linalg::SpMat, y: &mut [f64]| {
            crate::linalg::spmv_real(a, &v, y);
            v.iter().zip(y.iter()).map(|(a, b)| a * b).sum::<f64>()
        };
        let vs = e * quad(&model.s, &mut y);
        let vk = quad(&k, &mut y);
        shares.push(if vk > 0.0 {
            (vs / vk).clamp(0.0, 1.0)
        } else {
            0.0
        });
        let vm = quad(&model.m, &mut y);
        let on_axes: f64 = (0..nd)
            .filter(|i| measured[i % 3])
            .map(|i| v[i] * y[i])
            .sum();
        seen.push(if vm > 0.0 {
            (on_axes / vm).clamp(0.0, 1.0)
        } else {
            0.0
        });
    }
    let freqs = lam
        .iter()
        .map(|l| l.max(0.0).sqrt() / std::f64::consts::TAU)
        .collect();
    Ok((freqs, shares, seen))
}

/// The axes `points` measure (every axis when there are none).
fn measured_axes(points: &[crate::fe::joint::PointSpec]) -> [bool; 3] {
    let mut a = [false; 3];
    for p in points {
        a[p.direction.axis as usize] = true;
    }
    if !a.iter().any(|&b| b) {
        a = [true; 3];
    }
    a
}

/// A mesher's joint whose mesh the refinement chooses: its family of meshes (module doc).
pub trait Meshed: Clone + PartialEq + Sized {
    /// The joint on level `k` of its refined family (level 0: the study's mesh, graded where
    /// the family grades).
    fn level(&self, k: usize) -> Self;
    /// Size of the cells at the bond line's edges (m).
    fn edge_m(&self) -> f64;
    /// Size and cost before anything is allocated.
    fn cost(&self) -> Result<CostEstimate, FeError>;
    fn build(&self) -> Result<(StructuralModel, MeshInfo), FeError>;
    /// The model on this mesh with every cell split in two per direction (the estimate of a
    /// fixed mesh), its memory checked first.
    fn build_split(&self) -> Result<(StructuralModel, MeshInfo), FeError>;
    /// Its measurement points.
    fn points(&self) -> &[crate::fe::joint::PointSpec];
    /// The axes its points measure.
    fn measured_axes(&self) -> [bool; 3] {
        measured_axes(self.points())
    }
    /// The joint as a key of the process's memo.
    fn key(&self) -> Family;
    fn from_key(f: &Family) -> Option<Self>;
}

/// The joints the mesher refines.
#[derive(Clone, Debug, PartialEq)]
pub enum Family {
    /// A beam on an adhesive block or bond line ([`crate::fe::joint`]).
    Block(JointSpec),
    /// A single-lap joint ([`crate::fe::lap`]).
    Lap(LapSpec),
}

impl Meshed for JointSpec {
    fn level(&self, k: usize) -> Self {
        level_spec(self, k)
    }
    fn edge_m(&self) -> f64 {
        self.mesh.edge_m.unwrap_or(0.0)
    }
    fn cost(&self) -> Result<CostEstimate, FeError> {
        joint_cost_estimate(self)
    }
    fn build(&self) -> Result<(StructuralModel, MeshInfo), FeError> {
        build_joint_model(self)
    }
    fn build_split(&self) -> Result<(StructuralModel, MeshInfo), FeError> {
        crate::fe::joint::build_joint_model_refined(self, 2)
    }
    fn points(&self) -> &[crate::fe::joint::PointSpec] {
        &self.points
    }
    fn key(&self) -> Family {
        Family::Block(self.clone())
    }
    fn from_key(f: &Family) -> Option<Self> {
        match f {
            Family::Block(s) => Some(s.clone()),
            Family::Lap(_) => None,
        }
    }
}

/// The lap joint's family: level k halves the element size (along and across the strips) and
/// doubles the elements through the bond line (`y_adhesive`), so the cells at the overlap
/// ends (`end_aspect` bond-line elements long) and the longest adhesive cells (`max_aspect`)
/// halve too. Unlike a beam on a block, a lap joint's modes hold little of their strain
/// energy in the bond line: the strips' bending and their clamped end, which refining the
/// bond line alone leaves as they are, are most of the error (the reference lap joint: the
/// first mode +0.25 % on the study's mesh against an independent continuum, of which doubling
/// the bond line's elements removes 0.002 %).
impl Meshed for LapSpec {
    fn level(&self, k: usize) -> Self {
        let mut s = self.clone();
        let k = k.min(16);
        s.mesh.y_adhesive = self.mesh.y_adhesive << k;
        s.mesh.element_size_m = self.mesh.element_size_m / (1u64 << k) as f64;
        if let Some(z) = self.mesh.z {
            s.mesh.z = Some(z << k);
        }
        s
    }
    fn edge_m(&self) -> f64 {
        let ta = self.geometry.adhesive_thickness_m;
        (self.mesh.end_aspect * ta / self.mesh.y_adhesive as f64).min(self.mesh.element_size_m)
    }
    fn cost(&self) -> Result<CostEstimate, FeError> {
        lap_cost_estimate(self)
    }
    fn build(&self) -> Result<(StructuralModel, MeshInfo), FeError> {
        build_lap_model(self)
    }
    fn build_split(&self) -> Result<(StructuralModel, MeshInfo), FeError> {
        crate::fe::lap::build_lap_model_refined(self, 2)
    }
    fn points(&self) -> &[crate::fe::joint::PointSpec] {
        &self.points
    }
    fn key(&self) -> Family {
        Family::Lap(self.clone())
    }
    fn from_key(f: &Family) -> Option<Self> {
        match f {
            Family::Lap(s) => Some(s.clone()),
            Family::Block(_) => None,
        }
    }
}

/// The observed order of three successive differences (coarse to fine), NaN when they do not
/// converge monotonically.
pub fn observed_order(d_coarse: f64, d_fine: f64) -> f64 {
    if d_coarse * d_fine <= 0.0 || d_fine.abs() >= d_coarse.abs() {
        return f64::NAN;
    }
    (d_coarse / d_fine).log2()
}

/// The finest mesh's error from its step `d_fine` from the previous mesh, at order [`ORDER`]
/// (refinement ratio 2), or [`NON_MONOTONE_FACTOR`] times the step when the convergence is not
/// monotone (`observed` NaN).
pub fn extrapolated_error(d_fine: f64, observed: f64) -> f64 {
    if observed.is_finite() {
        d_fine / (2f64.powf(ORDER) - 1.0)
    } else {
        NON_MONOTONE_FACTOR * d_fine
    }
}

/// Relative ridge on the adherends' excess in [`stiffness_excess`] (a share of the modes'
/// summed weights), where it is fitted at all (the first measured mode mostly the adherends':
/// a lap joint, 1-13 % in the bond line).
pub const ADHEREND_RIDGE: f64 = 1e-2;

/// The stiffness excess of the mesh over the continuum, in the adhesive and in the adherends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Excess {
    /// delta_a: the adhesive's stiffness on the mesh over the continuum's, minus 1.
    pub adhesive: f64,
    pub adhesive_sd: f64,
    /// delta_b: the same for the adherends (and base).
    pub adherend: f64,
    pub adherend_sd: f64,
}

/// Weighted least squares of 2 e_k / f_k = phi_k delta_a + (1 - phi_k) delta_b over the modes,
/// each weighted by its measured share (the modes the data see), with the ridge
/// [`ADHEREND_RIDGE`] on delta_b; delta_b = 0 unless the lowest mode the points see (measured
/// share above one half) holds less than half its strain energy in the adhesive. Each sd is half the
/// value combined with the weighted scatter of the modes about the fit, carried by each part in
/// proportion to its sensitivity.
pub fn stiffness_excess(modes: &[ModeError]) -> Excess {
    let w = |m: &ModeError| m.measured_share;
    let (mut aa, mut ab, mut bb, mut ra, mut rb, mut sw) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for m in modes {
        let (p, q, r) = (m.adhesive_share, 1.0 - m.adhesive_share, 2.0 * m.rel_error);
        aa += w(m) * p * p;
        ab += w(m) * p * q;
        bb += w(m) * q * q;
        ra += w(m) * p * r;
        rb += w(m) * q * r;
        sw += w(m);
    }
    let zero = Excess {
        adhesive: 0.0,
        adhesive_sd: 0.0,
        adherend: 0.0,
        adherend_sd: 0.0,
    };
    if sw <= 1e-12 || aa <= 1e-12 {
        return zero;
    }
    // the adherends' part only where the first mode the points see is mostly the adherends' (a
    // lap joint's strips bending): on a beam on a block the low measured modes are the
    // adhesive's, and a higher mode of the beam (often beyond the band) would set delta_b from
    // one step of its own
    let adherend_seen = modes
        .iter()
        .find(|m| m.measured_share > 0.5)
        .is_some_and(|m| m.adhesive_share < 0.5);
    // (delta_a, delta_b) and the diagonal of the normal matrix's inverse
    let (da, db, ia, ib) = if adherend_seen {
        let bb = bb + ADHEREND_RIDGE * sw;
        let det = aa * bb - ab * ab;
        if det <= 1e-18 {
            return zero;
        }
        (
            (bb * ra - ab * rb) / det,
            (aa * rb - ab * ra) / det,
            bb / det,
            aa / det,
        )
    } else {
        (ra / aa, 0.0, 1.0 / aa, 0.0)
    };
    let residual2 = modes
        .iter()
        .map(|m| {
            w(m) * (2.0 * m.rel_error - m.adhesive_share * da - (1.0 - m.adhesive_share) * db)
                .powi(2)
        })
        .sum::<f64>();
    // the scatter's variance on each part
    let (va, vb) = (residual2 * ia, residual2 * ib);
    Excess {
        adhesive: da,
        adhesive_sd: (0.25 * da * da + va).sqrt(),
        adherend: db,
        adherend_sd: (0.25 * db * db + vb).sqrt(),
    }
}

/// The error of every mode on level `k` of `levels` (k >= 1), with the shares of level `k`:
/// the last step at order [`ORDER`], twice it when the last three levels do not converge
/// monotonically or only two levels exist.
fn estimate(levels: &[MeshLevel], k: usize, shares: &[f64], seen: &[f64]) -> Vec<ModeError> {
    let (b, c) = (&levels[k - 1], &levels[k]);
    let a = (k >= 2).then(|| &levels[k - 2]);
    let n = b.freqs_hz.len().min(c.freqs_hz.len());
    (0..n)
        .map(|i| {
            let (fb, fc) = (b.freqs_hz[i], c.freqs_hz[i]);
            let p = a
                .and_then(|a| a.freqs_hz.get(i))
                .map_or(f64::NAN, |&fa| observed_order(fa - fb, fb - fc));
            // the finest level's error: its step from the previous level, extrapolated
            let err = extrapolated_error(fb - fc, p);
            ModeError {
                mode: i + 1,
                freq_hz: fc,
                freq_refined_hz: fc - err,
                error_hz: err,
                rel_error: err / fc,
                order: p,
                adhesive_share: shares.get(i).copied().unwrap_or(0.0),
                measured_share: seen.get(i).copied().unwrap_or(0.0),
            }
        })
        .collect()
}

/// A model of the refinement and its size.
pub struct Refined<S = JointSpec> {
    pub spec: S,
    pub model: StructuralModel,
    pub info: MeshInfo,
    pub discretisation: Discretisation,
}

type Memo = Vec<(Family, RefineParams, Family, Discretisation)>;
static MEMO: Mutex<Memo> = Mutex::new(Vec::new());

/// The chosen spec and the record of a refinement already run in this process.
fn memo_get<S: Meshed>(spec: &S, p: &RefineParams) -> Option<(S, Discretisation)> {
    let m = MEMO.lock().ok()?;
    let key = spec.key();
    m.iter()
        .find(|(s, q, _, _)| *s == key && q == p)
        .and_then(|(_, _, c, d)| Some((S::from_key(c)?, d.clone())))
}

/// The spec [`select`] chooses, without building its model when this process already chose it.
pub fn select_spec<S: Meshed>(
    spec: &S,
    p: &RefineParams,
    progress: &dyn Fn(&str),
) -> Result<S, FeError> {
    match memo_get(spec, p) {
        Some((chosen, _)) => Ok(chosen),
        None => Ok(select(spec, p, progress)?.spec),
    }
}

/// `spec` on level `k` of the refined family (module doc).
pub fn level_spec(spec: &JointSpec, k: usize) -> JointSpec {
    let h = match spec.mesh.size {
        MeshSize::ElementSize(h) => h,
        MeshSize::Divisions(_) => DEFAULT_ELEMENT_SIZE_M,
    };
    let e0 = h.min(0.5 * spec.geometry.adhesive_thickness_m);
    let mut s = spec.clone();
    s.mesh.size = MeshSize::ElementSize(h);
    s.mesh.grading = Some(spec.mesh.grading.unwrap_or(DEFAULT_GRADING_RATIO));
    s.mesh.edge_m = Some(e0 / 2f64.powi(k as i32));
    s
}

/// Refine `spec` (an element size; its grading ratio, if any, is the family's) until the
/// estimated error of each of the lowest [`N_MODES`] modes is below the tolerance, or the
/// next mesh would be too large (module doc). `progress` receives one line per mesh. Repeated calls
/// with the same spec and settings reuse the choice (the same mesh in every command of a
/// process).
pub fn select<S: Meshed>(
    spec: &S,
    p: &RefineParams,
    progress: &dyn Fn(&str),
) -> Result<Refined<S>, FeError> {
    if let Some((chosen, d)) = memo_get(spec, p) {
        let (mut model, info) = chosen.build()?;
        correct(&mut model, &d);
        return Ok(Refined {
            spec: chosen,
            model,
            info,
            discretisation: d,
        });
    }
    let mut levels: Vec<MeshLevel> = Vec::new();
    let mut best: Option<(S, StructuralModel, MeshInfo, Vec<ModeError>)> = None;
    let mut note = String::new();
    let mut reached = false;
    for k in 0..MAX_LEVELS {
        let s = spec.level(k);
        let cost = match s.cost() {
            Ok(c) => c,
            Err(e) if k >= 2 => {
                note = format!(
                    "the next mesh (edge cells {:.3} mm) is beyond this machine: {}",
                    1e3 * s.edge_m(),
                    e.detail()
                );
                break;
            }
            Err(e) => return Err(e),
        };
        if k >= 2 && cost.n_dof > MAX_AUTO_DOFS {
            note = format!(
                "the next mesh (edge cells {:.3} mm) would have about {} DOFs, more than the {MAX_AUTO_DOFS} the refinement goes to",
                1e3 * s.edge_m(),
                cost.n_dof
            );
            break;
        }
        let t0 = Instant::now();
        let (model, info) = s.build()?;
        let (freqs, shares, seen) = modes_with_shares(
            &model,
            p.reference_modulus_pa,
            N_MODES,
            &spec.measured_axes(),
        )
        .map_err(|m| FeError::InvalidMesh {
            key: "structure.mesh".into(),
            detail: format!("the modes of the refined mesh (level {k}): {m}"),
        })?;
        levels.push(MeshLevel {
            level: k,
            edge_m: s.edge_m(),
            n_dof: info.n_dof,
            n_elements: info.n_elements,
            freqs_hz: freqs,
            seconds: t0.elapsed().as_secs_f64(),
        });
        let estimate_now = (k >= 1).then(|| estimate(&levels, k, &shares, &seen));
        let worst = estimate_now.as_deref().map(worst_rel_error);
        progress(&match worst {
            Some(w) => format!(
                "mesh level {k}: edge cells {:.3} mm, {} DOFs, estimated error {:.3} % (tolerance {:.3} %)",
                1e3 * s.edge_m(),
                info.n_dof,
                100.0 * w,
                100.0 * p.tolerance
            ),
            None => format!(
                "mesh level {k}: edge cells {:.3} mm, {} DOFs",
                1e3 * s.edge_m(),
                info.n_dof
            ),
        });
        best = Some((s, model, info, estimate_now.unwrap_or_default()));
        if worst.is_some_and(|w| w <= p.tolerance) {
            reached = true;
            break;
        }
    }
    let (chosen, mut model, info, modes) = best.expect("level 0 is always built");
    if !reached && note.is_empty() {
        note = format!("{MAX_LEVELS} levels of refinement did not reach it");
    }
    let x = stiffness_excess(&modes);
    let d = Discretisation {
        rule: "refined".into(),
        tolerance: p.tolerance,
        reached,
        chosen: levels.len() - 1,
        levels,
        modes,
        stiffness_excess: x.adhesive,
        stiffness_excess_sd: x.adhesive_sd,
        adherend_excess: x.adherend,
        adherend_excess_sd: x.adherend_sd,
        allowance: p.allowance,
        reference_modulus_pa: p.reference_modulus_pa,
        note,
    };
    correct(&mut model, &d);
    if let Ok(mut m) = MEMO.lock() {
        m.push((spec.key(), *p, chosen.key(), d.clone()));
    }
    Ok(Refined {
        spec: chosen,
        model,
        info,
        discretisation: d,
    })
}

/// The estimate of a fixed mesh: the study's mesh against it refined twice per direction
/// (eight times the DOFs), at the order [`ORDER`] of the singular corners (module doc). The
/// model is not changed: [`correct`] applies the allowance.
pub fn fixed<S: Meshed>(
    spec: &S,
    model: &StructuralModel,
    p: &RefineParams,
) -> Result<Discretisation, FeError> {
    let (fine, _) = spec.build_split()?;
    let fail = |m: String| FeError::InvalidMesh {
        key: "structure.mesh".into(),
        detail: format!("the discretisation-error estimate: {m}"),
    };
    let axes = spec.measured_axes();
    let (coarse, shares, seen) =
        modes_with_shares(model, p.reference_modulus_pa, N_MODES, &axes).map_err(fail)?;
    let (refined, _, _) =
        modes_with_shares(&fine, p.reference_modulus_pa, N_MODES, &axes).map_err(fail)?;
    let g = 2f64.powf(ORDER);
    let modes: Vec<ModeError> = coarse
        .iter()
        .zip(&refined)
        .enumerate()
        .map(|(i, (&fh, &ff))| {
            let err = (fh - ff) * g / (g - 1.0);
            ModeError {
                mode: i + 1,
                freq_hz: fh,
                freq_refined_hz: ff,
                error_hz: err,
                rel_error: err / fh,
                order: ORDER,
                adhesive_share: shares[i],
                measured_share: seen[i],
            }
        })
        .collect();
    let x = stiffness_excess(&modes);
    let worst = worst_rel_error(&modes);
    Ok(Discretisation {
        rule: "fixed".into(),
        tolerance: p.tolerance,
        reached: worst <= p.tolerance,
        levels: Vec::new(),
        chosen: 0,
        modes,
        stiffness_excess: x.adhesive,
        stiffness_excess_sd: x.adhesive_sd,
        adherend_excess: x.adherend,
        adherend_excess_sd: x.adherend_sd,
        allowance: p.allowance,
        reference_modulus_pa: p.reference_modulus_pa,
        note: String::new(),
    })
}

/// With the allowance of `d`, divide the model's adhesive stiffness by
/// (1 + [`ESTIMATE_SHARE_CENTRE`] delta_a) and the adherends' by (1 + [`ESTIMATE_SHARE_CENTRE`]
/// delta_b).
pub fn correct(model: &mut StructuralModel, d: &Discretisation) {
    if !d.allowance {
        return;
    }
    let f = 1.0 / (1.0 + ESTIMATE_SHARE_CENTRE * d.stiffness_excess);
    for v in model.s.val_mut() {
        *v *= f;
    }
    let g = 1.0 / (1.0 + ESTIMATE_SHARE_CENTRE * d.adherend_excess);
    if g != 1.0 {
        for v in model.k_b.val_mut() {
            *v *= g;
        }
    }
}

impl Discretisation {
    /// ", the adherends' by ... %" where the adherends' excess was fitted (a lap joint), else
    /// "": for the sentences of `check` and the report.
    pub fn adherends_clause(&self) -> String {
        if self.adherend_excess == 0.0 {
            return String::new();
        }
        format!(
            ", the adherends' by {:+.3} % (sd {:.3} %)",
            100.0 * self.adherend_excess,
            100.0 * self.adherend_excess_sd
        )
    }

    /// The part of mode `m`'s relative error the two excesses explain:
    /// (phi delta_a + (1 - phi) delta_b) / 2.
    pub fn explained(&self, m: &ModeError) -> f64 {
        0.5 * (m.adhesive_share * self.stiffness_excess
            + (1.0 - m.adhesive_share) * self.adherend_excess)
    }
}
