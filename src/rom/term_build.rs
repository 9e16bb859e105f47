//! Building and certifying a reduced model with extra structural terms ([`super::terms`]):
//! the certified ROM's basis enriched with the Krylov vectors of the full model with each term
//! on, certified against the modified full model at every (term, value) case (by the shifted
//! Krylov solver or the sparse LU, as `RomParams::reference` says: `rom::term_reference`),
//! then compressed ([`super::compress`]) and re-certified against the same reference.

use super::basis::BasisBuilder;
use super::certify::{
    enrich, frf_scales, reduce, validate, validation_lines, validation_moduli,
    MAX_DIRECT_FRACTION_INV,
};
use super::compress;
use super::sparse::ModelPattern;
use super::term_reference::{CaseRefs, Grid};
use super::terms::{pinvs, TermCertificate, TermMap, TermRom, TermSpec};
use super::{RomError, RomParams};
use crate::common::C64;
use crate::fe::model::{SpMat, StructuralModel};
use crate::frf::TermCoef;
use faer::Mat;
use std::time::Instant;

/// Per-case errors of a certificate: (term name, value, error).
type CaseErrors = Vec<(String, f64, f64)>;

/// `a + c b` for two sparse matrices of the same size (any patterns).
pub fn add_scaled(a: &SpMat, b: &SpMat, c: f64) -> Result<SpMat, RomError> {
    let mut t: Vec<faer::sparse::Triplet<usize, usize, f64>> = a
        .triplet_iter()
        .map(|t| faer::sparse::Triplet::new(t.row, t.col, *t.val))
        .collect();
    t.extend(
        b.triplet_iter()
            .map(|t| faer::sparse::Triplet::new(t.row, t.col, c * *t.val)),
    );
    SpMat::try_new_from_triplets(a.nrows(), a.ncols(), &t)
        .map_err(|e| RomError::Model(format!("sum of sparse matrices: {e:?}")))
}

/// The full model with one term on at value `v` (real part of `c G` into K_b and S, imaginary
/// part into D_b; an inertia term's `v G` into M).
pub fn model_with_term(
    model: &StructuralModel,
    spec: &TermSpec,
    v: f64,
) -> Result<StructuralModel, RomError> {
    if spec.matrix.nrows() != model.n_dof() || spec.matrix.ncols() != model.n_dof() {
        return Err(RomError::Model(format!(
            "term {}: G is {} x {}, the model has {} DOFs",
            spec.name,
            spec.matrix.nrows(),
            spec.matrix.ncols(),
            model.n_dof()
        )));
    }
    let mut out = model.clone();
    if let (Some(h), TermMap::Compliance { v_ref, v_floor }) = (&spec.held, spec.map) {
        // Another shape of the held springs: G / v in place of H / v_ref.
        if spec.per_modulus != 0.0 || spec.offset.im != 0.0 {
            return Err(RomError::Model(format!(
                "term {}: a compliance term in place of held springs must have a real offset and no modulus part",
                spec.name
            )));
        }
        if h.nrows() != model.n_dof() || h.ncols() != model.n_dof() {
            return Err(RomError::Model(format!(
                "term {}: the held springs are {} x {}, the model has {} DOFs",
                spec.name,
                h.nrows(),
                h.ncols(),
                model.n_dof()
            )));
        }
        let o = spec.offset.re;
        out.k_b = add_scaled(&out.k_b, &spec.matrix, o / v.max(v_floor))?;
        out.k_b = add_scaled(&out.k_b, h, -o / v_ref)?;
        out.description = format!("{} + term {} at {v}", model.description, spec.name);
        return Ok(out);
    }
    let fv = spec.map.f(v);
    if let TermMap::Inertia = spec.map {
        // A mass: v G (offset real) into M.
        if spec.per_modulus != 0.0 || spec.offset.im != 0.0 {
            return Err(RomError::Model(format!(
                "term {}: an inertia term must have a real offset and no modulus part",
                spec.name
            )));
        }
        out.m = add_scaled(&out.m, &spec.matrix, spec.offset.re * fv)?;
        out.description = format!("{} + term {} at {v}", model.description, spec.name);
        return Ok(out);
    }
    let p = spec.offset * fv;
    if p.re != 0.0 {
        out.k_b = add_scaled(&out.k_b, &spec.matrix, p.re)?;
    }
    if p.im != 0.0 {
        out.d_b = Some(match &out.d_b {
            Some(d) => add_scaled(d, &spec.matrix, p.im)?,
            None => add_scaled(&spec.matrix, &spec.matrix, p.im - 1.0)?,
        });
    }
    if spec.per_modulus != 0.0 {
        out.s = add_scaled(&out.s, &spec.matrix, spec.per_modulus * fv)?;
    }
    out.description = format!("{} + term {} at {v}", model.description, spec.name);
    Ok(out)
}

/// The sum of the compliance terms' reduced matrices (None without one): the springs' shapes
/// share its null space, the motions off the base face.
fn compliance_sum(rom: &TermRom) -> Option<Mat<f64>> {
    let mut k = rom.compliance_terms();
    let mut g = rom.g_r[k.next()?].clone();
    for i in k {
        g += &rom.g_r[i];
    }
    Some(g)
}

/// Build and certify a reduced model of `model` with the extra `terms` (see the module doc),
/// for the FRFs of all observation points x `inputs`, with the band, range, tolerance,
/// enrichment schedule, validation grid and reference solver of `params`.
pub fn build_term_rom(
    model: &StructuralModel,
    inputs: &[usize],
    params: &RomParams,
    terms: &[TermSpec],
) -> Result<(TermRom, TermCertificate), RomError> {
    validate(model, inputs, params)?;
    if terms.is_empty() {
        return Err(RomError::Params(
            "build_term_rom needs at least one term".into(),
        ));
    }
    let moduli = validation_moduli(params);
    let lines = validation_lines(params);
    let grid = Grid {
        inputs,
        moduli: &moduli,
        lines: &lines,
    };
    // Modified full models for the basis.
    let mut side_models = Vec::new();
    for t in terms {
        for &v in &t.enrich_values {
            side_models.push(model_with_term(model, t, v)?);
        }
    }
    let cases: Vec<(usize, f64)> = terms
        .iter()
        .enumerate()
        .flat_map(|(k, t)| t.cert_values.iter().map(move |&v| (k, v)))
        .collect();
    let t0 = Instant::now();
    // (the reference does not depend on the basis: every enrichment level is judged by it)
    let mut refs = CaseRefs::new(model, terms, &cases, &grid, params.reference)?;
    let mut seconds_certify = t0.elapsed().as_secs_f64();
    let mut seconds_basis = 0.0;

    let pat = ModelPattern::new(model)?;
    let side_pats: Vec<ModelPattern<'_>> = side_models
        .iter()
        .map(ModelPattern::new)
        .collect::<Result<_, _>>()?;
    let mut basis = BasisBuilder::new(&pat, params.deflation_tol)?;
    let mut sides: Vec<BasisBuilder<'_>> = side_pats
        .iter()
        .map(|p| BasisBuilder::new(p, params.deflation_tol))
        .collect::<Result<_, _>>()?;
    let mut best: Option<(TermRom, f64, CaseErrors)> = None;
    let mut levels = 0;
    for level in 0..params.max_levels.max(1) {
        levels = level + 1;
        let t = Instant::now();
        enrich(&mut basis, params, level)?;
        for side in sides.iter_mut() {
            let before = side.size();
            enrich(side, params, level)?;
            let v = side.v();
            let new = Mat::from_fn(v.nrows(), side.size() - before, |i, j| v[(i, before + j)]);
            if new.ncols() > 0 {
                basis.absorb(new);
            }
        }
        let g_r: Vec<Mat<f64>> = terms.iter().map(|t| basis.project(&t.matrix)).collect();
        let maps: Vec<TermMap> = terms.iter().map(|t| t.map).collect();
        let mut rom = TermRom {
            rom: reduce(model, &basis, inputs, params),
            g_pinv: pinvs(&g_r, &maps),
            g_r,
            names: terms.iter().map(|t| t.name.clone()).collect(),
            maps,
            g_held: terms
                .iter()
                .map(|t| t.held.as_ref().map(|h| basis.project(h)))
                .collect(),
            memo: Default::default(),
        };
        if let Some(g) = compliance_sum(&rom) {
            // The springs' rigid limit is a penalty method: rotate to their null space and
            // range, and zero the terms' rounding on the null block (compress::split_rotation).
            let (q, k_null) = compress::split_rotation(&g)?;
            rom = rom.rotated_split(&q, k_null);
        }
        seconds_basis += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (worst, per_case) =
            certify_cases(&rom, model, terms, &cases, &mut refs, &grid, params)?;
        seconds_certify += t.elapsed().as_secs_f64();
        best = Some((rom, worst, per_case));
        if worst <= params.tolerance {
            break;
        }
    }
    basis.drop_factors();
    let (mut rom, mut err, mut per_case) =
        best.ok_or_else(|| RomError::Params("max_levels must be >= 1".into()))?;
    let enriched_size = rom.rom.n_r;
    let mut compression_error = None;
    let t = Instant::now();
    // With a compliance term the POD keeps the springs' near-null space and range apart
    // (compress::pod_basis_split): its rigid limit is a penalty method.
    if let (Some(cp), true) = (params.compress, err <= params.tolerance) {
        // See super::compress: kept only when it agrees with the enriched ROM on samples of
        // its own and passes the same certificate.
        let train = compress::samples(params.band_hz, params.range, terms, 0, cp.samples)?;
        let check = compress::samples(
            params.band_hz,
            params.range,
            terms,
            cp.samples,
            cp.check_samples,
        )?;
        let (u, split) = match compliance_sum(&rom) {
            None => (compress::pod_basis(&rom, &train, cp.sv_tol)?, None),
            Some(g) => {
                let (u, k_null) = compress::pod_basis_split(&rom, &train, cp.sv_tol, &g)?;
                (u, Some(k_null))
            }
        };
        if u.ncols() < rom.rom.n_r {
            let small = match split {
                Some(k_null) => rom.rotated_split(&u, k_null),
                None => rom.rotated(&u),
            };
            let e_check = compress::check_error(&small, &rom, &check)?;
            compression_error = Some(e_check);
            if e_check <= params.tolerance {
                let (worst, cases_small) =
                    certify_cases(&small, model, terms, &cases, &mut refs, &grid, params)?;
                if worst <= params.tolerance {
                    rom = small;
                    err = worst;
                    per_case = cases_small;
                }
            }
        }
    }
    let seconds_compress = t.elapsed().as_secs_f64();
    let cert = TermCertificate {
        max_rel_error: err,
        per_case,
        basis_size: rom.rom.n_r,
        enriched_basis_size: enriched_size,
        compression_error,
        levels,
        n_moduli: moduli.len(),
        n_lines: lines.len(),
        seconds_basis,
        seconds_certify,
        seconds_compress,
        passed: err <= params.tolerance,
        reference: if refs.shifted.is_some() {
            "shifted Krylov".into()
        } else {
            "sparse LU".into()
        },
        reference_residual: refs.shifted.as_ref().map(|s| s.max_residual),
        reference_krylov_vectors: refs.shifted.as_ref().map(|s| s.max_vectors),
        reference_direct_points: refs.direct.iter().map(|d| d.len()).sum(),
    };
    if !cert.passed && !params.allow_uncertified {
        return Err(RomError::Uncertified {
            error: err,
            tolerance: params.tolerance,
            basis_size: rom.rom.n_r,
            levels,
        });
    }
    Ok((rom, cert))
}

/// The certificate of `rom` over every (term, value) case: the largest error and each case's.
/// With the shifted Krylov reference, the points where the ROM misses it by more than the
/// tolerance are solved by sparse LU before the verdict when they are at most
/// 1 / `MAX_DIRECT_FRACTION_INV` of all points (more mean the basis is short), as the
/// effect-free ROM does with its GMRES reference ([`super::certify::build_rom`]).
fn certify_cases(
    rom: &TermRom,
    model: &StructuralModel,
    terms: &[TermSpec],
    cases: &[(usize, f64)],
    refs: &mut CaseRefs,
    g: &Grid<'_>,
    params: &RomParams,
) -> Result<(f64, CaseErrors), RomError> {
    let tol = params.tolerance;
    let judge = |c: usize, refs: &CaseRefs| {
        let (k, v) = cases[c];
        case_error(rom, &[terms[k].coef(k, v)], g, &refs.h[c], tol)
    };
    let mut judged: Vec<(f64, Vec<(usize, usize)>)> = (0..cases.len())
        .map(|c| judge(c, refs))
        .collect::<Result<_, _>>()?;
    let worst = judged.iter().map(|j| j.0).fold(0.0f64, f64::max);
    if !(worst <= tol) && refs.shifted.is_some() {
        let suspect: Vec<Vec<(usize, usize)>> = judged
            .iter()
            .zip(&refs.direct)
            .map(|((_, over), direct)| {
                over.iter()
                    .copied()
                    .filter(|p| !direct.contains(p))
                    .collect()
            })
            .collect();
        let n_suspect: usize = suspect.iter().map(|s| s.len()).sum();
        let n_points = cases.len() * g.moduli.len() * g.lines.len();
        if n_suspect > 0 && n_suspect * MAX_DIRECT_FRACTION_INV <= n_points {
            for (c, points) in suspect.iter().enumerate() {
                if !points.is_empty() {
                    refs.solve_directly(model, terms, cases, c, points, g)?;
                    judged[c] = judge(c, refs)?;
                }
            }
        }
    }
    let mut worst = 0.0f64;
    let mut per_case = Vec::with_capacity(cases.len());
    for (&(k, v), (err, _)) in cases.iter().zip(&judged) {
        worst = worst.max(*err);
        per_case.push((terms[k].name.clone(), v, *err));
    }
    Ok((worst, per_case))
}

/// Largest error relative to the scale of each FRF ([`frf_scales`]: its peak) of one
/// (term, value) case, and the validation points (modulus, line) where it exceeds `tol`.
fn case_error(
    rom: &TermRom,
    coef: &[TermCoef],
    g: &Grid<'_>,
    refh: &[Vec<Vec<C64>>],
    tol: f64,
) -> Result<(f64, Vec<(usize, usize)>), RomError> {
    let n_in = rom.rom.inputs.len();
    let mut worst = 0.0f64;
    let mut over = Vec::new();
    for (m, &e) in g.moduli.iter().enumerate() {
        let (sw, _) = rom
            .sweep_terms_impl(g.lines, &vec![e; g.lines.len()], coef, false)
            .map_err(|x| RomError::Factorization(x.to_string()))?;
        let want = &refh[m];
        let blk = want.first().map_or(0, |w| w.len());
        let scales = frf_scales(want, n_in);
        for (l, w) in want.iter().enumerate() {
            let mut line = 0.0f64;
            for (k, &scale) in scales.iter().enumerate().take(blk) {
                let err = (sw.h[l * blk + k] - w[k]).norm();
                let rel = if scale > 0.0 { err / scale } else { err };
                line = line.max(if rel.is_nan() { f64::INFINITY } else { rel });
            }
            worst = worst.max(line);
            if !(line <= tol) {
                over.push((m, l));
            }
        }
    }
    Ok((worst, over))
}
