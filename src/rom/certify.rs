//! ROM build with its error certificate.
//!
//! Reference: full-model receptances H = B^T Z(w, E*)^-1 B by sparse complex LU on a
//! validation set: moduli on a log-spaced grid over [E'min, E'max] x [E''min, E''max]
//! (corners included) times lines spaced linearly across the band (ends included).
//! Error of one FRF (output i, input j, modulus m): max_w |H_rom - H_full| / max_w |H_full|.
//! Enrichment level L uses 2^L (n0 - 1) + 1 log-spaced E_ref (nested, so earlier Krylov
//! sequences are reused) and depth d0 + L * step blocks, until the largest error is below
//! the tolerance.

use super::basis::BasisBuilder;
use super::reduced::{check_inputs, ReducedModel};
use super::sparse::{FullSolver, ModelPattern, SharedLuSymbolic};
use super::term_reference::{
    shifted_lines, ShiftedLines, ShiftedStats, SHIFTED_MAX_VECTORS, SHIFTED_RESIDUAL_TOL,
};
use super::{Certificate, Reference, RomError, RomParams};
use crate::common::C64;
use crate::fe::model::StructuralModel;
use rayon::prelude::*;
use std::time::Instant;

fn logspace(a: f64, b: f64, n: usize) -> Vec<f64> {
    if n <= 1 || a == b {
        return vec![(a * b).sqrt()];
    }
    (0..n)
        .map(|k| (a.ln() + (b.ln() - a.ln()) * k as f64 / (n - 1) as f64).exp())
        .collect()
}

/// The validation moduli (Pa): log-spaced grid, corners included. A zero lower bound of
/// E'' is replaced by 1e-3 of its upper bound for the spacing, and the corner itself is kept.
pub fn validation_moduli(params: &RomParams) -> Vec<C64> {
    let n = params.n_cert_moduli_per_axis.max(2);
    let (a, b) = params.range.e_storage_pa;
    let (c, d) = params.range.e_loss_pa;
    let es = logspace(a, b, n);
    let mut el = if c > 0.0 {
        logspace(c, d, n)
    } else {
        logspace(1e-3 * d.max(1.0), d.max(1.0), n)
    };
    el[0] = c;
    let mut out = Vec::new();
    for &x in &es {
        for &y in &el {
            out.push(C64::new(x, y));
        }
    }
    out
}

/// The validation lines (rad/s).
pub fn validation_lines(params: &RomParams) -> Vec<f64> {
    let n = params.n_cert_lines.max(2);
    let (f0, f1) = params.band_hz;
    (0..n)
        .map(|k| 2.0 * std::f64::consts::PI * (f0 + (f1 - f0) * k as f64 / (n - 1) as f64))
        .collect()
}

pub(crate) fn validate(
    model: &StructuralModel,
    inputs: &[usize],
    p: &RomParams,
) -> Result<(), RomError> {
    p.range.validate()?;
    check_inputs(inputs, model.points.len())?;
    if !(p.band_hz.0 >= 0.0 && p.band_hz.1 > p.band_hz.0 && p.band_hz.1.is_finite()) {
        return Err(RomError::Params(format!(
            "band_hz must satisfy 0 <= f_min < f_max; got {:?}",
            p.band_hz
        )));
    }
    if !(p.tolerance > 0.0) {
        return Err(RomError::Params(format!(
            "tolerance must be positive; got {}",
            p.tolerance
        )));
    }
    if p.n_e_ref_initial < 2 || p.krylov_depth_initial == 0 {
        return Err(RomError::Params(
            "n_e_ref_initial must be >= 2 and krylov_depth_initial >= 1".into(),
        ));
    }
    if model.points.is_empty() {
        return Err(RomError::Model(
            "the model has no observation points".into(),
        ));
    }
    Ok(())
}

/// Reduced model from the current basis (the builder keeps its projections up to date).
pub(crate) fn reduce(
    model: &StructuralModel,
    basis: &BasisBuilder<'_>,
    inputs: &[usize],
    p: &RomParams,
) -> ReducedModel {
    let has_c = model.c_b.is_some();
    ReducedModel {
        n_r: basis.size(),
        n_out: model.points.len(),
        inputs: inputs.to_vec(),
        m_r: basis.project_op(0),
        k_r: basis.project_op(1),
        s_r: basis.project_op(2),
        c_r: has_c.then(|| basis.project_op(3)),
        d_r: model
            .d_b
            .as_ref()
            .map(|_| basis.project_op(if has_c { 4 } else { 3 })),
        b_r: basis.project_vecs(&basis.b_all),
        // V^T S B = (S V)^T B, S symmetric
        sb_r: crate::linalg::blocked::tn(basis.av(2).as_ref(), basis.b_all.as_ref()),
        range: p.range,
        m_axes_r: None,
    }
}

/// V^T M_a V for a = x, y, z, with M_a the entries of M between two DOFs of axis a.
fn project_axis_masses(
    model: &StructuralModel,
    basis: &BasisBuilder<'_>,
    dof_axes: &[u8],
) -> Result<Box<[faer::Mat<f64>; 3]>, RomError> {
    let n = model.n_dof();
    if dof_axes.len() != n || dof_axes.iter().any(|&a| a > 2) {
        return Err(RomError::Params(format!(
            "dof_axes must have one entry 0, 1 or 2 per free DOF ({n}); got {}",
            dof_axes.len()
        )));
    }
    let r = basis.size();
    let mut out: [faer::Mat<f64>; 3] = std::array::from_fn(|_| faer::Mat::zeros(r, r));
    for (a, slot) in out.iter_mut().enumerate() {
        let t: Vec<faer::sparse::Triplet<usize, usize, f64>> = model
            .m
            .triplet_iter()
            .filter(|t| dof_axes[t.row] as usize == a && dof_axes[t.col] as usize == a)
            .map(|t| faer::sparse::Triplet::new(t.row, t.col, *t.val))
            .collect();
        let ma = faer::sparse::SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &t)
            .map_err(|e| RomError::Model(format!("axis mass matrix: {e:?}")))?;
        *slot = basis.project(&ma);
    }
    Ok(Box::new(out))
}

/// Receptances per modulus and line (each n_out x n_in row-major).
type Receptances = Vec<Vec<Vec<C64>>>;

/// Full-model receptances on the validation set (h[m][l] = n_out x n_in row-major for each
/// modulus m and line l) and, per modulus and line, the sparse LU's attainable relative accuracy
/// ([`FullSolver::solve`]).
fn reference_with_floor(
    model: &StructuralModel,
    inputs: &[usize],
    moduli: &[C64],
    lines: &[f64],
) -> Result<(Receptances, Vec<Vec<f64>>), RomError> {
    let jobs: Vec<(usize, usize)> = (0..moduli.len())
        .flat_map(|m| (0..lines.len()).map(move |l| (m, l)))
        .collect();
    let res = reference_points(model, inputs, moduli, lines, &jobs)?;
    let mut out = vec![Vec::with_capacity(lines.len()); moduli.len()];
    let mut floor = vec![Vec::with_capacity(lines.len()); moduli.len()];
    for ((m, _), (h, f)) in jobs.into_iter().zip(res) {
        out[m].push(h);
        floor[m].push(f);
    }
    Ok((out, floor))
}

/// Full-model receptances (n_out x n_in row-major) by sparse complex LU at the validation
/// points `jobs` = (modulus index, line index), each with its attainable relative accuracy.
pub(crate) fn reference_points(
    model: &StructuralModel,
    inputs: &[usize],
    moduli: &[C64],
    lines: &[f64],
    jobs: &[(usize, usize)],
) -> Result<Vec<(Vec<C64>, f64)>, RomError> {
    let pat = ModelPattern::new(model)?;
    points_with(model, inputs, moduli, lines, jobs, &FullSolver::new(&pat)?)
}

/// [`reference_points`] with the symbolic analysis `symbolic` when `model` has its pattern.
pub(crate) fn reference_points_with(
    model: &StructuralModel,
    inputs: &[usize],
    moduli: &[C64],
    lines: &[f64],
    jobs: &[(usize, usize)],
    symbolic: &SharedLuSymbolic,
) -> Result<Vec<(Vec<C64>, f64)>, RomError> {
    let pat = ModelPattern::new(model)?;
    points_with(
        model,
        inputs,
        moduli,
        lines,
        jobs,
        &symbolic.solver_for(&pat)?,
    )
}

/// [`shifted_reference`]'s receptances, the points it did not resolve and its statistics.
type ShiftedReference = (Receptances, Vec<(usize, usize)>, ShiftedStats);

/// Full-model receptances on the validation set by the shifted Krylov solver
/// ([`super::term_reference::shifted_lines`]; the model has no C_b): per modulus one sparse LU
/// and the Krylov space that serves its lines. Returns them with the points it did not
/// resolve (left empty, for the sparse LU) and the solves' statistics.
fn shifted_reference(
    pat: &ModelPattern,
    model: &StructuralModel,
    inputs: &[usize],
    moduli: &[C64],
    lines: &[f64],
) -> Result<ShiftedReference, RomError> {
    let solver = FullSolver::new(pat)?;
    let per_modulus: Vec<ShiftedLines> = moduli
        .par_iter()
        .map(|&e| {
            shifted_lines(
                &solver,
                model,
                inputs,
                e,
                lines,
                SHIFTED_RESIDUAL_TOL,
                SHIFTED_MAX_VECTORS,
            )
        })
        .collect::<Result<_, _>>()?;
    let mut st = ShiftedStats::default();
    let mut h = Vec::with_capacity(moduli.len());
    let mut missing = Vec::new();
    for (m, r) in per_modulus.into_iter().enumerate() {
        st.max_residual = st.max_residual.max(r.max_residual);
        st.max_vectors = st.max_vectors.max(r.vectors);
        h.push(
            r.h.into_iter()
                .enumerate()
                .map(|(l, x)| {
                    x.unwrap_or_else(|| {
                        missing.push((m, l));
                        Vec::new()
                    })
                })
                .collect(),
        );
    }
    Ok((h, missing, st))
}

fn points_with(
    model: &StructuralModel,
    inputs: &[usize],
    moduli: &[C64],
    lines: &[f64],
    jobs: &[(usize, usize)],
    solver: &FullSolver<'_>,
) -> Result<Vec<(Vec<C64>, f64)>, RomError> {
    let n = model.n_dof();
    let n_out = model.points.len();
    let mut rhs = faer::Mat::<f64>::zeros(n, inputs.len());
    for (jj, &j) in inputs.iter().enumerate() {
        for &(d, w) in &model.points[j].dofs {
            rhs[(d, jj)] += w;
        }
    }
    jobs.par_iter()
        .map(|&(m, l)| {
            let (x, floor) = solver.solve(lines[l], moduli[m], &rhs)?;
            let mut h = vec![C64::new(0.0, 0.0); n_out * inputs.len()];
            for (i, p) in model.points.iter().enumerate() {
                for jj in 0..inputs.len() {
                    h[i * inputs.len() + jj] = p.dofs.iter().map(|&(d, w)| x[(d, jj)] * w).sum();
                }
            }
            Ok((h, floor))
        })
        .collect()
}

/// A validation point's error is judged against max(tolerance, `FLOOR_FACTOR` x the full
/// model's attainable accuracy there): where double precision cannot resolve the full model
/// to the tolerance, no reduced model can be shown to meet it. The reduced solve has rounding
/// errors of its own of the same origin (a stiff adherend on a soft layer), and on a slender
/// 584 mm beam held by a 22 mm patch the ROM and the sparse LU differed by 10.2 times the
/// LU's refinement step at the worst such point; 30 leaves a margin of 3 over that.
pub const FLOOR_FACTOR: f64 = 30.0;

/// Enrichment stops when the certificate's measure has not improved for this many levels: the
/// error is then at the reduced solve's rounding level, which more basis only raises.
const STALLED_LEVELS: usize = 2;

/// The certificate's measure: per validation point (m, l) and FRF k, the error |H_rom - H_full|
/// over its allowance max(allowance x scale_k, FLOOR_FACTOR floor[m][l] max_k' |H_full|),
/// times the tolerance, with allowance = max(tolerance, FLOOR_FACTOR floor[m][l]) and scale_k
/// from [`frf_scales`]; the largest. The second term is the full model's absolute rounding at
/// the point (its floor is relative to the largest response), which bounds how well an FRF
/// that vanishes by symmetry can be resolved. The measure is <= tolerance exactly when every
/// point is within its allowance, and equals the plain relative error where the floor is below
/// the tolerance. Also returns the points (m, l) over their allowance.
struct Judged {
    score: f64,
    over: Vec<(usize, usize)>,
    /// points whose allowance is set by the floor, and the largest plain error there
    floor_points: usize,
    floor_error: f64,
}

fn judge(
    rom: &ReducedModel,
    moduli: &[C64],
    lines: &[f64],
    reference: &[Vec<Vec<C64>>],
    floor: &[Vec<f64>],
    params: &RomParams,
) -> Result<Judged, RomError> {
    // the tolerance, and the outputs judged (all unless `certified_outputs` says)
    let (tol, outputs) = (params.tolerance, params.certified_outputs.as_deref());
    let mut j = Judged {
        score: 0.0,
        over: Vec::new(),
        floor_points: 0,
        floor_error: 0.0,
    };
    for (m, &e) in moduli.iter().enumerate() {
        let sw = rom
            .lu_sweep(lines, &vec![e; lines.len()], false)
            .map_err(|x| RomError::Factorization(x.to_string()))?;
        let want = &reference[m];
        let blk = want.first().map_or(0, |w| w.len());
        let peaks = frf_scales(want, rom.inputs.len());
        for (l, w) in want.iter().enumerate() {
            let allowance = tol.max(FLOOR_FACTOR * floor[m][l]);
            // The floor is the refinement step relative to the largest |x| of the point's
            // solves, so it bounds every FRF's rounding in absolute terms by floor x the
            // line's largest response: an FRF that vanishes by symmetry is resolved no better.
            let line_floor =
                FLOOR_FACTOR * floor[m][l] * w.iter().map(|v| v.norm()).fold(0.0, f64::max);
            let (mut worst, mut scaled, mut by_floor) = (0.0f64, 0.0f64, allowance > tol);
            let n_in = rom.inputs.len().max(1);
            for k in 0..blk {
                if outputs.is_some_and(|o| !o.contains(&(k / n_in))) {
                    continue;
                }
                let d = (sw.h[l * blk + k] - w[k]).norm();
                let rel = if peaks[k] > 0.0 { d / peaks[k] } else { d };
                let rel = if rel.is_nan() { f64::INFINITY } else { rel };
                worst = worst.max(rel);
                let own = allowance * peaks[k];
                by_floor |= line_floor > own && d > tol * peaks[k];
                scaled = scaled.max(if d == 0.0 {
                    0.0
                } else if d.is_nan() {
                    f64::INFINITY
                } else {
                    tol * d / own.max(line_floor)
                });
            }
            if by_floor {
                j.floor_points += 1;
                j.floor_error = j.floor_error.max(worst);
            }
            j.score = j.score.max(scaled);
            if !(scaled <= tol) {
                j.over.push((m, l));
            }
        }
    }
    Ok(j)
}

/// A GMRES reference is checked by sparse LU at the validation points where the ROM misses it,
/// when they are at most 1 / `MAX_DIRECT_FRACTION_INV` of all points (more means the basis,
/// not the reference, is short).
pub(crate) const MAX_DIRECT_FRACTION_INV: usize = 8;

/// A transfer FRF whose peak is below `TRANSFER_FLOOR` times the largest FRF of its input
/// column is judged against that fraction of the column's largest instead of its own peak: an
/// FRF that vanishes by symmetry (a y-force on the beam's centre plane and a z-response) has a
/// peak at the rounding level, and relative to it any two correct solvers differ by orders of
/// magnitude.
pub const TRANSFER_FLOOR: f64 = 1e-3;

/// The scale each FRF's error is measured against: its largest |want| over the lines, at least
/// `TRANSFER_FLOOR` times the largest FRF of its input column (`want` `[line][k]`, k = output
/// x `n_in` + input, row-major).
pub(crate) fn frf_scales(want: &[Vec<C64>], n_in: usize) -> Vec<f64> {
    let blk = want.first().map_or(0, |w| w.len());
    let peaks: Vec<f64> = (0..blk)
        .map(|k| want.iter().map(|w| w[k].norm()).fold(0.0, f64::max))
        .collect();
    let n_in = n_in.max(1);
    let mut column = vec![0.0f64; n_in];
    for (k, &p) in peaks.iter().enumerate() {
        column[k % n_in] = column[k % n_in].max(p);
    }
    peaks
        .iter()
        .enumerate()
        .map(|(k, &p)| p.max(TRANSFER_FLOOR * column[k % n_in]))
        .collect()
}

/// Largest |got - want| of each FRF relative to its scale ([`frf_scales`]), the worst FRF's:
/// `got` flat `[line * blk + k]`, `want` `[line][k]` (a NaN counts as infinite).
pub(crate) fn worst_rel_to_peak(got: &[C64], want: &[Vec<C64>], n_in: usize) -> f64 {
    let blk = want.first().map_or(0, |w| w.len());
    let scales = frf_scales(want, n_in);
    let mut worst = 0.0f64;
    for (k, &peak) in scales.iter().enumerate().take(blk) {
        let err = want
            .iter()
            .enumerate()
            .map(|(l, w)| (got[l * blk + k] - w[k]).norm())
            .fold(0.0, f64::max);
        let rel = if peak > 0.0 { err / peak } else { err };
        worst = worst.max(if rel.is_nan() { f64::INFINITY } else { rel });
    }
    worst
}

/// Enrichment level `level` (0 first): 2^level (n0 - 1) + 1 log-spaced E_ref over the range,
/// snapped to the previous levels' values (nested grids, so their Krylov sequences continue),
/// each brought to depth d0 + level * step blocks.
pub(crate) fn enrich(
    basis: &mut BasisBuilder<'_>,
    params: &RomParams,
    level: usize,
) -> Result<(), RomError> {
    let e_lo = params.range.e_storage_pa.0;
    let e_hi = params.range.e_storage_pa.1.hypot(params.range.e_loss_pa.1);
    let n_e = ((params.n_e_ref_initial - 1) << level) + 1;
    let depth = params.krylov_depth_initial + level * params.krylov_depth_step;
    let targets: Vec<(f64, usize)> = logspace(e_lo, e_hi, n_e)
        .into_iter()
        .map(|e| {
            let e = basis
                .e_refs()
                .into_iter()
                .find(|&x| ((x - e) / e).abs() < 1e-9)
                .unwrap_or(e);
            (e, depth)
        })
        .collect();
    basis.extend_all(&targets)?;
    Ok(())
}

/// A reduced model without a certificate: the first enrichment level of [`build_rom`]
/// (`params.n_e_ref_initial` log-spaced E_ref over the range, `krylov_depth_initial` blocks
/// each), no full-model solves. For the modes the observation points see (their Krylov
/// sequences converge to them first), e.g. a mesh-convergence study at a single modulus on a
/// mesh too large for full complex refinement; FRF use needs [`build_rom`].
///
/// With `dof_axes` (0 = x, 1 = y, 2 = z per free DOF) the modes also carry their
/// kinetic-energy split ([`crate::frf::EngineMode::energy_fraction_xyz`]).
pub fn build_basis_only(
    model: &StructuralModel,
    inputs: &[usize],
    params: &RomParams,
    dof_axes: Option<&[u8]>,
) -> Result<ReducedModel, RomError> {
    validate(model, inputs, params)?;
    let pat = ModelPattern::new(model)?;
    let mut basis = BasisBuilder::new(&pat, params.deflation_tol)?;
    enrich(&mut basis, params, 0)?;
    basis.drop_factors();
    let mut rom = reduce(model, &basis, inputs, params);
    if let Some(ax) = dof_axes {
        rom.m_axes_r = Some(project_axis_masses(model, &basis, ax)?);
    }
    Ok(rom)
}

/// Build and certify a ROM for the FRFs of all observation points x `inputs`
/// (indices into `model.points`) over `params.band_hz` and `params.range`.
///
/// Returns `RomError::Uncertified` when the tolerance is not met after `max_levels`
/// levels, unless `params.allow_uncertified` (then `certificate.passed == false`).
pub fn build_rom(
    model: &StructuralModel,
    inputs: &[usize],
    params: &RomParams,
) -> Result<(ReducedModel, Certificate), RomError> {
    validate(model, inputs, params)?;
    let moduli = validation_moduli(params);
    let lines = validation_lines(params);

    let mut seconds_certify = 0.0;
    let n_points = moduli.len() * lines.len();
    // the sparse LU's attainable accuracy per point (0 where an iterative solve is the reference)
    let mut floor = vec![vec![0.0; lines.len()]; moduli.len()];
    let mut gmres_stats = None;
    let mut shifted_stats = None;
    // validation points whose reference is a sparse-LU solve (iterative references only)
    let mut direct: Vec<(usize, usize)> = Vec::new();
    let mut seconds_basis = 0.0;

    // the reference and its floor at `points` by sparse LU, the points recorded as direct
    let solve_directly = |points: &[(usize, usize)],
                          h: &mut Receptances,
                          floor: &mut Vec<Vec<f64>>,
                          direct: &mut Vec<(usize, usize)>|
     -> Result<(), RomError> {
        if points.is_empty() {
            return Ok(());
        }
        let lu = reference_points(model, inputs, &moduli, &lines, points)?;
        for (&(m, l), (hv, f)) in points.iter().zip(lu) {
            h[m][l] = hv;
            floor[m][l] = f;
        }
        direct.extend_from_slice(points);
        Ok(())
    };
    let pat = ModelPattern::new(model)?;
    let mut refh = match params.reference {
        Reference::Shifted if model.c_b.is_none() => {
            let t0 = Instant::now();
            let (mut h, missing, st) = shifted_reference(&pat, model, inputs, &moduli, &lines)?;
            // the lines the Krylov space did not resolve are solved directly instead
            solve_directly(&missing, &mut h, &mut floor, &mut direct)?;
            shifted_stats = Some(st);
            seconds_certify += t0.elapsed().as_secs_f64();
            Some(h)
        }
        // the shifted solver with C_b present (Z quadratic in w: no shifted systems of one
        // operator) falls back to the sparse LU at every point
        Reference::SparseLu | Reference::Shifted => {
            let t0 = Instant::now();
            let (r, f) = reference_with_floor(model, inputs, &moduli, &lines)?;
            floor = f;
            seconds_certify += t0.elapsed().as_secs_f64();
            Some(r)
        }
        Reference::Iterative { .. } => None,
    };
    let mut basis = BasisBuilder::new(&pat, params.deflation_tol)?;
    if let Some(o) = &params.certified_outputs {
        let mut starts = o.clone();
        starts.extend(inputs.iter().filter(|i| !o.contains(i)));
        basis.restrict_starts(&starts);
    }
    let mut history = Vec::new();
    let mut best: Option<(ReducedModel, Judged)> = None;
    let mut levels = 0;
    for level in 0..params.max_levels.max(1) {
        levels = level + 1;
        let t = Instant::now();
        enrich(&mut basis, params, level)?;
        let rom = reduce(model, &basis, inputs, params);
        seconds_basis += t.elapsed().as_secs_f64();
        let t = Instant::now();
        if let (
            None,
            Reference::Iterative {
                residual_tol,
                max_iter,
            },
        ) = (&refh, params.reference)
        {
            // the full-model solutions do not depend on the basis (to the residual
            // tolerance), so the first level's basis serves every later level
            let (mut h, st) = super::reference::reference(
                &basis,
                &rom,
                inputs,
                &moduli,
                &lines,
                residual_tol,
                max_iter,
            )?;
            // the points GMRES could not resolve (too ill-conditioned for its
            // preconditioner) are solved directly instead
            solve_directly(&st.unconverged_points, &mut h, &mut floor, &mut direct)?;
            gmres_stats = Some(st);
            refh = Some(h);
        }
        let h = refh.as_mut().expect("reference");
        let mut judged = judge(&rom, &moduli, &lines, h, &floor, params)?;
        if judged.score > params.tolerance && (gmres_stats.is_some() || shifted_stats.is_some()) {
            // near a lightly damped resonance an iterative reference converged to its residual
            // tolerance can itself be off by more than the certificate's tolerance, and it has
            // no floor (the sparse LU's attainable accuracy): the few points where the ROM
            // misses it are solved directly before more basis is added
            let suspect: Vec<(usize, usize)> = judged
                .over
                .iter()
                .copied()
                .filter(|p| !direct.contains(p))
                .collect();
            if !suspect.is_empty() && suspect.len() * MAX_DIRECT_FRACTION_INV <= n_points {
                solve_directly(&suspect, h, &mut floor, &mut direct)?;
                judged = judge(&rom, &moduli, &lines, h, &floor, params)?;
            }
        }
        seconds_certify += t.elapsed().as_secs_f64();
        history.push(judged.score);
        let done = judged.score <= params.tolerance;
        // the best level is kept (a larger basis can be worse once rounding dominates)
        if best.as_ref().is_none_or(|(_, b)| judged.score < b.score) {
            best = Some((rom, judged));
        }
        if done {
            break;
        }
        let best_score = best.as_ref().map_or(f64::INFINITY, |(_, b)| b.score);
        if history.len() > STALLED_LEVELS
            && history[history.len() - STALLED_LEVELS..]
                .iter()
                .all(|&h| h >= best_score)
        {
            break;
        }
    }
    basis.drop_factors();
    let (rom, judged) = best.ok_or_else(|| RomError::Params("max_levels must be >= 1".into()))?;
    let err = judged.score;
    let cert = Certificate {
        max_rel_error: err,
        n_moduli: moduli.len(),
        n_lines: lines.len(),
        basis_size: rom.n_r,
        seconds_basis,
        seconds_certify,
        passed: err <= params.tolerance,
        levels,
        e_ref_pa: basis.e_refs(),
        error_history: history,
        reference: if gmres_stats.is_some() {
            "GMRES".into()
        } else if shifted_stats.is_some() {
            "shifted Krylov".into()
        } else {
            "sparse LU".into()
        },
        reference_residual: gmres_stats
            .as_ref()
            .map(|s| s.max_residual)
            .or(shifted_stats.as_ref().map(|s| s.max_residual)),
        reference_iterations: gmres_stats
            .as_ref()
            .map(|s| s.max_iterations)
            .or(shifted_stats.as_ref().map(|s| s.max_vectors)),
        reference_direct_points: direct.len(),
        floor_points: judged.floor_points,
        floor_max: floor.iter().flatten().copied().fold(0.0, f64::max),
        floor_points_error: judged.floor_error,
    };
    if !cert.passed && !params.allow_uncertified {
        return Err(RomError::Uncertified {
            error: err,
            tolerance: params.tolerance,
            basis_size: rom.n_r,
            levels,
        });
    }
    Ok((rom, cert))
}
