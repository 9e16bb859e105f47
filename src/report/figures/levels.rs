//! The figures of the comparison across levels, parameter redundancy and initial-value
//! sensitivity: the posterior bands of E'(f) and E''(f) of every model and level
//! (`fig_levels_modulus`), posterior sd over prior sd per parameter
//! (`fig_identifiability`) and the basin maps per level, model and method
//! (`fig_basins_<level>_<model>_<method>`).

use crate::bayes::PosteriorResult;
use crate::pipeline::tables::levels::{comparisons, union_names};
use crate::pipeline::LevelResults;
use crate::stage::RunError;

/// The two parameters of a basin map: the largest entries of the weakest direction.
fn map_pair(p: &PosteriorResult, nl: usize) -> (usize, usize) {
    let Ok(r) = &p.redundancy else {
        return (0, 1.min(nl - 1));
    };
    let Some((_, v)) = r.svd.weakest() else {
        return (0, 1.min(nl - 1));
    };
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|a, b| v[*b].abs().total_cmp(&v[*a].abs()));
    let (a, b) = (idx[0], idx.get(1).copied().unwrap_or(idx[0]));
    (a.min(b), a.max(b))
}

/// Figures: posterior bands of E' and E'' of every model and level on one figure; the
/// identifiability figure; basin maps per level, model and method.
pub(super) fn figures(
    dir: &std::path::Path,
    results: &[LevelResults],
) -> Result<Vec<(String, String)>, RunError> {
    use crate::plot::posterior::{posterior_bands_figure, BandGroup};
    use crate::plot::{line_figure, Curve};
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let mut out = Vec::new();
    if comparisons(results).is_empty()
        && posts
            .iter()
            .all(|p| p.basins.is_none() && p.redundancy.is_err())
    {
        return Ok(out);
    }
    // 1. E*(f) bands of every model and level.
    let freq: Vec<f64> = (0..=100).map(|k| 1.0 + 4.99 * k as f64).collect();
    let mut groups = Vec::new();
    for p in &posts {
        let (Ok(law), Some(s)) = (
            crate::material::model_from_name(&p.model, None),
            p.figure_sampler(),
        ) else {
            continue;
        };
        let n = s.draws.chain.len();
        let step = (n / 300).max(1);
        let (st, lo) = super::modulus_bands(law.as_ref(), &s.draws, &freq, step);
        groups.push(BandGroup {
            label: format!("{} {}", p.model, p.level),
            freq_hz: freq.clone(),
            storage: st,
            loss: lo,
        });
    }
    if groups.len() > 1 && !comparisons(results).is_empty() {
        let name = "fig_levels_modulus.png".to_string();
        posterior_bands_figure(
            &dir.join(&name),
            &groups,
            &[],
            "E'(f) and E''(f) of every model and level: median, 50 % and 95 % bands",
        )?;
        out.push((
            name,
            "posterior bands of E* of every model and level".to_string(),
        ));
    }
    // 2. Identifiability.
    let names = union_names(posts.iter().map(|p| p.names.as_slice()));
    let mut curves = Vec::new();
    for p in &posts {
        let Ok(r) = &p.redundancy else { continue };
        let ratio = r.ratio();
        let x: Vec<f64> = r
            .names
            .iter()
            .map(|n| names.iter().position(|m| m == n).unwrap_or(0) as f64 + 1.0)
            .collect();
        curves.push(Curve::points(format!("{} {}", p.model, p.level), x, ratio));
    }
    if !curves.is_empty() {
        let name = "fig_identifiability.png".to_string();
        let xl = names
            .iter()
            .enumerate()
            .map(|(i, n)| format!("{} {n}", i + 1))
            .collect::<Vec<_>>()
            .join(", ");
        line_figure(
            dir.join("fig_identifiability"),
            "Identifiability: posterior sd / prior sd (unconstrained coordinates)",
            &format!("parameter ({xl})"),
            "posterior sd / prior sd",
            &curves,
            true,
        )?;
        out.push((name, "identifiability per parameter".to_string()));
    }
    // 3. Basin maps.
    for p in &posts {
        let Some(b) = &p.basins else { continue };
        let nl = p.names.len().min(b.names.len());
        if nl < 2 {
            continue;
        }
        let (i, j) = map_pair(p, nl);
        for m in &b.methods {
            let mut curves = Vec::new();
            let n_show = m.basins.len().min(4);
            for k in 0..=n_show {
                let pick: Vec<&crate::bayes::basins::BasinStart> = m
                    .starts
                    .iter()
                    .filter(|s| match s.basin {
                        Some(bb) if k < n_show => bb == k,
                        Some(bb) => bb >= n_show,
                        None => false,
                    })
                    .collect();
                if pick.is_empty() {
                    continue;
                }
                let label = if k < n_show {
                    let d = m.distance_to_map_sd[k];
                    format!(
                        "basin {k} ({} starts, {:.1} sd from the MAP)",
                        pick.len(),
                        d
                    )
                } else {
                    format!("other basins ({} starts)", pick.len())
                };
                curves.push(Curve::points(
                    label,
                    pick.iter().map(|s| s.start[i].log10()).collect(),
                    pick.iter().map(|s| s.start[j].log10()).collect(),
                ));
            }
            let failed: Vec<&crate::bayes::basins::BasinStart> =
                m.starts.iter().filter(|s| s.basin.is_none()).collect();
            if !failed.is_empty() {
                curves.push(Curve::points(
                    format!("failed ({})", failed.len()),
                    failed.iter().map(|s| s.start[i].log10()).collect(),
                    failed.iter().map(|s| s.start[j].log10()).collect(),
                ));
            }
            if let Some(s) = m.starts.iter().find(|s| s.kind == "initial") {
                curves.push(
                    Curve::points(
                        "initial values (Table 4)",
                        vec![s.start[i].log10()],
                        vec![s.start[j].log10()],
                    )
                    .with_color((0, 0, 0)),
                );
            }
            if curves.is_empty() {
                continue;
            }
            let stem = format!("fig_basins_{}_{}_{}", p.level, p.model, m.method);
            line_figure(
                dir.join(&stem),
                &format!(
                    "{} at {}: where {} starts end ({})",
                    p.model,
                    p.level,
                    m.method.to_uppercase(),
                    if m.method == "map" {
                        "L-BFGS on -log posterior"
                    } else {
                        "global RFM"
                    }
                ),
                &format!("log10 {} ({}) at the start", p.names[i], p.units[i]),
                &format!("log10 {} ({}) at the start", p.names[j], p.units[j]),
                &curves,
                false,
            )?;
            out.push((
                format!("{stem}.png"),
                format!("basin map of {} at {} ({})", p.model, p.level, m.method),
            ));
        }
    }
    Ok(out)
}
