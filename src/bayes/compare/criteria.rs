//! The predictive criteria of one model at one level, on at most [`MAX_DRAWS`] posterior
//! draws (thinned evenly within each chain, the same number per chain): the pointwise log
//! likelihood per line (summed over channels) with PSIS-LOO and WAIC
//! ([`crate::inference::loo`], ArviZ's relative efficiency), FRAC per FRF (paper eq. 38),
//! SCC(w) and ACC(w) (eq. 39-40) as median and 95 % band with their values at the MAP, and at
//! the MAP the standardised residuals `r = (E[H1] - X) / sqrt(v)` per channel with
//! `chi2 = sum |r|^2` against chi-square(2 n_lines). Checked by the suite's
//! `model_comparison` test (LOO and WAIC against ArviZ on the same pointwise values).

use super::{Band, ChannelCheck, Comparison, MAX_DRAWS};
use crate::bayes::posterior::SamplerResult;
use crate::bayes::{fail, At};
use crate::common::C64;
use crate::correlation::{acc_curve, frac_per_frf, scc_curve};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::loo;
use crate::inference::map::MapResult;
use crate::inference::special::chi2_sf;
use crate::inference::Posterior;
use crate::stage::{Event, RunError};

/// Per draw: pointwise log likelihood, FRAC per channel, SCC and ACC per line.
type PerDraw = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

/// Thinned (chain, draw, row) triples (the draw number as in the `draws` table): at most [`MAX_DRAWS`] rows, evenly within each chain,
/// the same number per chain.
fn thin(s: &SamplerResult) -> Vec<(usize, usize, usize)> {
    let d = &s.draws;
    let n_chains = d.chain.iter().copied().max().map_or(0, |c| c + 1);
    if n_chains == 0 {
        return Vec::new();
    }
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); n_chains];
    for (r, c) in d.chain.iter().enumerate() {
        rows[*c].push(r);
    }
    let per = rows.iter().map(|r| r.len()).min().unwrap_or(0);
    let keep = (MAX_DRAWS / n_chains).min(per).max(1);
    let step = (per / keep).max(1);
    let mut out = Vec::new();
    for (c, rs) in rows.iter().enumerate() {
        for &r in rs.iter().step_by(step).take(keep) {
            out.push((c, d.draw[r], r));
        }
    }
    out
}

/// Median and central 95 % of `v` (linear interpolation between order statistics, numpy's
/// default).
fn band(map: f64, v: &mut [f64]) -> Band {
    v.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let h = p * (v.len() - 1) as f64;
        let (i, f) = (h.floor() as usize, h - h.floor());
        if i + 1 < v.len() {
            v[i] + f * (v[i + 1] - v[i])
        } else {
            v[i]
        }
    };
    Band {
        map,
        median: q(0.5),
        lo: q(0.025),
        hi: q(0.975),
    }
}

/// Fill `c`'s criteria from the draws of `s` and its checks at `map` (see the module
/// documentation).
pub(super) fn predictive(
    c: &mut Comparison,
    post: &FrfPosterior<'_>,
    map: &MapResult,
    s: &SamplerResult,
    at: &At<'_>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<(), RunError> {
    let (level, model) = (at.level, at.model);
    let nl = post.n_law();
    let lik = &post.likelihood;
    // Pointwise log likelihood and predictions on thinned draws.
    let rows = thin(s);
    let n_out = lik.data.n_out;
    let n_lines = lik.data.freq_hz.len();
    let x_rows: Vec<Vec<C64>> = lik.data.values.chunks(n_out).map(|r| r.to_vec()).collect();
    progress(Event::Start {
        step: format!(
            "{}: predictive criteria of {model} ({} draws)",
            level.name,
            rows.len()
        ),
        total: 0,
    });
    use rayon::prelude::*;
    let per_draw: Vec<Option<PerDraw>> = rows
        .par_iter()
        .map(|&(_, _, r)| {
            let phys: Vec<f64> = s.draws.values.iter().map(|col| col[r]).collect();
            let pw = lik.pointwise(&phys[..nl], &phys[nl..]).ok()?;
            let pred = lik.forward.predict(&phys[..nl], false).ok()?;
            let a: Vec<Vec<C64>> = pred.values.chunks(n_out).map(|r| r.to_vec()).collect();
            Some((
                pw,
                frac_per_frf(&x_rows, &a),
                scc_curve(&x_rows, &a),
                acc_curve(&x_rows, &a),
            ))
        })
        .collect();
    let mut fr: Vec<Vec<f64>> = vec![Vec::new(); n_out];
    let mut sc: Vec<Vec<f64>> = vec![Vec::new(); n_lines];
    let mut ac: Vec<Vec<f64>> = vec![Vec::new(); n_lines];
    for (&(ch, dr, _), v) in rows.iter().zip(per_draw) {
        let Some((pw, f, sv, av)) = v else {
            c.notes.push(format!(
                "draw {dr} of chain {ch} could not be evaluated and is left out of the criteria"
            ));
            continue;
        };
        c.draw_index.push((ch, dr));
        c.pointwise.push(pw);
        for (k, v) in f.into_iter().enumerate() {
            fr[k].push(v);
        }
        for (l, v) in sv.into_iter().enumerate() {
            sc[l].push(v);
        }
        for (l, v) in av.into_iter().enumerate() {
            ac[l].push(v);
        }
    }
    progress(Event::Finish);
    // Deterministic values at the MAP.
    let map_p = &map.map_physical;
    let map_pred = lik
        .forward
        .predict(&map_p[..nl], false)
        .map_err(|e| fail(format!("prediction of {model} at the MAP"), e))?;
    let a: Vec<Vec<C64>> = map_pred.values.chunks(n_out).map(|r| r.to_vec()).collect();
    let f_map = frac_per_frf(&x_rows, &a);
    let s_map = scc_curve(&x_rows, &a);
    let a_map = acc_curve(&x_rows, &a);
    if !c.pointwise.is_empty() {
        c.frac = fr
            .iter_mut()
            .zip(&f_map)
            .map(|(v, m)| band(*m, v))
            .collect();
        c.scc = sc
            .iter_mut()
            .zip(&s_map)
            .map(|(v, m)| band(*m, v))
            .collect();
        c.acc = ac
            .iter_mut()
            .zip(&a_map)
            .map(|(v, m)| band(*m, v))
            .collect();
        // LOO and WAIC over [chain][draw][line], ArviZ's relative efficiency from the thinned
        // draws of every coordinate.
        let n_chains = c.draw_index.iter().map(|d| d.0).max().map_or(0, |m| m + 1);
        let mut ll: Vec<Vec<Vec<f64>>> = vec![Vec::new(); n_chains];
        let mut par: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); n_chains]; post.dim()];
        let kept: Vec<usize> = rows
            .iter()
            .filter(|(ch, dr, _)| c.draw_index.contains(&(*ch, *dr)))
            .map(|t| t.2)
            .collect();
        for ((ch, _), (pw, r)) in c.draw_index.iter().zip(c.pointwise.iter().zip(&kept)) {
            ll[*ch].push(pw.clone());
            for (k, p) in par.iter_mut().enumerate() {
                p[*ch].push(s.draws.values[k][*r]);
            }
        }
        let equal = ll.iter().all(|c| c.len() == ll[0].len());
        let r_eff = if equal {
            loo::relative_eff(&par).unwrap_or(1.0)
        } else {
            1.0
        };
        match loo::loo(&ll, r_eff) {
            Ok(l) => c.loo = Some(l),
            Err(e) => c.notes.push(format!("PSIS-LOO not computed: {e}")),
        }
        match loo::waic(&ll) {
            Ok(w) => c.waic = Some(w),
            Err(e) => c.notes.push(format!("WAIC not computed: {e}")),
        }
    }
    // PPC at the MAP: standardised residuals and chi-square per channel.
    let std = lik
        .standardised(&map_p[..nl], &map_p[nl..])
        .map_err(|e| fail(format!("residuals of {model} at the MAP"), e))?;
    for (k, id) in level.response_ids.iter().enumerate().take(n_out) {
        let residuals: Vec<C64> = (0..n_lines).map(|l| std[l * n_out + k]).collect();
        let chi2: f64 = residuals.iter().map(|r| r.norm_sqr()).sum();
        let dof = 2 * n_lines;
        c.ppc.push(ChannelCheck {
            response_id: *id,
            residuals,
            chi2,
            dof,
            p_value: chi2_sf(chi2, dof as f64),
        });
    }
    Ok(())
}
