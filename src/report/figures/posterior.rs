//! The figures of the `[inference]` part of a run: per level and model the trace plot
//! (`fig_trace_<level>_<model>`) and the pair plot with the MAP and the Laplace 95 % ellipse
//! (`fig_pair_<level>_<model>`), and per model the posterior bands of E'(f) and E''(f) of
//! every level (`fig_posterior_modulus_<model>`).

use crate::bayes::PosteriorResult;
use crate::stage::RunError;

/// Posterior figures: per level and model the NUTS trace plot and the pair plot (MAP and the
/// Laplace 95 % ellipse), and per model the posterior bands of E'(f) and E''(f) of every level
/// on one figure. Returns (PNG file name, alt text).
pub(super) fn figures(
    dir: &std::path::Path,
    posts: &[&PosteriorResult],
) -> Result<Vec<(String, String)>, RunError> {
    use crate::plot::posterior::{pair_figure, posterior_bands_figure, trace_figure, BandGroup};
    let mut out = Vec::new();
    for p in posts {
        let Some(s) = p.figure_sampler() else {
            continue;
        };
        let by = s.draws.by_chain();
        let name = format!("fig_trace_{}_{}.png", p.level, p.model);
        trace_figure(
            &dir.join(&name),
            &p.names,
            &by,
            &format!("{} at {}: {} draws", p.model, p.level, s.sampler),
        )?;
        out.push((name, format!("trace plot of {} at {}", p.model, p.level)));
        let name = format!("fig_pair_{}_{}.png", p.level, p.model);
        let lap = &p.map.laplace;
        pair_figure(
            &dir.join(&name),
            &p.names,
            &s.draws.values,
            Some(&p.map.map_physical),
            lap.positive_definite.then_some(lap.cov_physical.as_slice()),
            &format!(
                "{} at {}: posterior, MAP and Laplace 95 % ellipse",
                p.model, p.level
            ),
        )?;
        out.push((name, format!("pair plot of {} at {}", p.model, p.level)));
    }
    // Bands of E*(f) per model, levels together.
    let mut models: Vec<&str> = posts.iter().map(|p| p.model.as_str()).collect();
    models.dedup();
    for m in models {
        let Ok(law) = crate::material::model_from_name(m, None) else {
            continue;
        };
        let freq: Vec<f64> = (0..=100).map(|k| 1.0 + 4.99 * k as f64).collect();
        let mut groups = Vec::new();
        for p in posts.iter().filter(|p| p.model == m) {
            let Some(s) = p.figure_sampler() else {
                continue;
            };
            let n = s.draws.chain.len();
            let step = (n / 400).max(1);
            let (storage, loss) = super::modulus_bands(law.as_ref(), &s.draws, &freq, step);
            groups.push(BandGroup {
                label: format!("level {}", p.level),
                freq_hz: freq.clone(),
                storage,
                loss,
            });
        }
        if groups.is_empty() {
            continue;
        }
        let name = format!("fig_posterior_modulus_{m}.png");
        posterior_bands_figure(
            &dir.join(&name),
            &groups,
            &[],
            &format!("{m}: posterior E'(f) and E''(f), median, 50 % and 95 % bands"),
        )?;
        out.push((name, format!("posterior bands of E* of {m}")));
    }
    Ok(out)
}
