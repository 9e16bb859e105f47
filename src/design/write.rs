//! `rfmlab design`'s files: `design.parquet` (the ranked designs, the study's own first),
//! `design_candidates.parquet` (every candidate channel with what it adds), a figure of the
//! information along the joint, `design.md` and `manifest.json`, in one atomic folder swap.

use super::{axis_name, DesignResult, Evaluated};
use crate::output::{Columns, Manifest, OutputError, Replace, Report, ResultsDir};
use std::path::Path;

/// The ranked designs: one row per design and level, the study's own design first
/// (`design = "current"`), then the best (`"best"`) and the others by rank.
pub fn designs_table(r: &DesignResult) -> Result<crate::output::Table, OutputError> {
    let mut c = Columns::default();
    let mut rows: Vec<(&str, i64, &Evaluated)> = Vec::new();
    if let Some(cur) = &r.current {
        rows.push(("current", 0, cur));
    }
    rows.push(("best", 1, &r.best));
    for (k, e) in r.ranked.iter().enumerate() {
        if same(e, &r.best) {
            continue;
        }
        rows.push(("ranked", k as i64 + 1, e));
    }
    // Every model's parameters as columns (a model without one has NaN there).
    let mut names: Vec<String> = Vec::new();
    for ps in &r.params {
        for p in ps {
            if !names.contains(p) {
                names.push(p.clone());
            }
        }
    }
    for (kind, rank, e) in rows {
        for (mi, model) in r.models.iter().enumerate() {
            for (li, level) in r.levels.iter().enumerate() {
                c.s("design", kind.to_string());
                c.s("sensors", r.sensors(e));
                c.s("model", model.clone());
                c.s("level", level.clone());
                c.i("rank", rank);
                c.i("drive", e.drive as i64);
                c.i("n_sensors", e.channels.len() as i64);
                c.i("own_masses", e.own_masses as i64);
                for p in &names {
                    let v = r.params[mi]
                        .iter()
                        .position(|q| q == p)
                        .map_or(f64::NAN, |pi| e.score.rel_sd[mi][li][pi]);
                    c.f(&format!("sd_rel_{}", p.to_ascii_lowercase()), "1", v);
                }
                c.f("worst_sd_rel", "1", e.score.worst);
                c.f("info_gain", "nat", e.score.info_gain);
            }
        }
    }
    c.table("design")
}

fn same(a: &Evaluated, b: &Evaluated) -> bool {
    let (mut x, mut y) = (a.channels.clone(), b.channels.clone());
    x.sort_unstable();
    y.sort_unstable();
    x == y && a.drive == b.drive
}

/// Every candidate channel: place, position, direction, whether the best or the study's
/// design holds it, and the information it adds to the best design.
pub fn candidates_table(r: &DesignResult) -> Result<crate::output::Table, OutputError> {
    let mut c = Columns::default();
    for (k, ch) in r.channels.iter().enumerate() {
        let pl = &r.places[ch.place];
        c.s("face", pl.face.clone());
        c.s("direction", axis_name(ch.axis).to_string());
        c.i("place_id", pl.id as i64);
        c.i("in_best", r.best.channels.contains(&k) as i64);
        c.i(
            "in_current",
            r.current.as_ref().is_some_and(|e| e.channels.contains(&k)) as i64,
        );
        c.f("x", "m", pl.position_m[0]);
        c.f("y", "m", pl.position_m[1]);
        c.f("z", "m", pl.position_m[2]);
        c.f("info_gain", "nat", r.channel_gain[k]);
    }
    c.table("design_candidates")
}

/// The plain-words report.
pub fn markdown(r: &DesignResult, figure: Option<&str>) -> Report {
    let mut rep = Report::new();
    rep.heading(1, "Test design");
    let pct = |v: f64| {
        if v.is_finite() && v < 10.0 {
            format!("{:.2} %", 100.0 * v)
        } else {
            "not determined".into()
        }
    };
    let worst_of = |e: &Evaluated| {
        let mut w = (0, 0, 0, 0.0);
        for (m, lv) in e.score.rel_sd.iter().enumerate() {
            for (l, ps) in lv.iter().enumerate() {
                for (i, v) in ps.iter().enumerate() {
                    if *v > w.3 {
                        w = (m, l, i, *v);
                    }
                }
            }
        }
        w
    };
    let (bm, bl, bi, bw) = worst_of(&r.best);
    let mut lead = format!(
        "Best design: drive at point {}, sensors {}. Its worst-determined parameter is {} of {} at {}: predicted posterior sd {}.",
        r.best.drive,
        r.sensors(&r.best),
        r.params[bm][bi],
        r.models[bm],
        r.levels[bl],
        pct(bw)
    );
    if let Some(cur) = &r.current {
        let (cm, cl, ci, cw) = worst_of(cur);
        lead += &format!(
            " The study's own design (drive at point {}, sensors {}) has {} of {} at {} worst: {}; the best design's sd of that parameter there is {} ({:.1} times smaller).",
            cur.drive,
            r.sensors(cur),
            r.params[cm][ci],
            r.models[cm],
            r.levels[cl],
            pct(cw),
            pct(r.best.score.rel_sd[cm][cl][ci]),
            cw / r.best.score.rel_sd[cm][cl][ci]
        );
        // Moves in plain words: the study's sensors the best design drops, and what it adds.
        let dropped: Vec<String> = cur
            .channels
            .iter()
            .filter(|c| !r.best.channels.contains(c))
            .map(|&c| r.label(c))
            .collect();
        let added: Vec<String> = r
            .best
            .channels
            .iter()
            .filter(|c| !cur.channels.contains(c))
            .map(|&c| {
                let ch = &r.channels[c];
                let pl = &r.places[ch.place];
                format!(
                    "{} ({}, x = {:.1} mm, measured in {})",
                    r.label(c),
                    pl.face,
                    pl.position_m[0] * 1e3,
                    axis_name(ch.axis)
                )
            })
            .collect();
        if !dropped.is_empty() {
            lead += &format!(
                " Move sensors {} to {}.",
                dropped.join(", "),
                added.join("; ")
            );
        }
    }
    rep.paragraph(&lead);
    rep.heading(
        2,
        "Predicted posterior sd (relative) per parameter and level",
    );
    let mut rows = Vec::new();
    let mut show = |name: &str, e: &Evaluated| {
        for (m, model) in r.models.iter().enumerate() {
            for (l, level) in r.levels.iter().enumerate() {
                let mut row = vec![
                    name.to_string(),
                    format!("{}", e.drive),
                    r.sensors(e),
                    model.clone(),
                    level.clone(),
                ];
                row.push(
                    r.params[m]
                        .iter()
                        .enumerate()
                        .map(|(i, p)| format!("{p} {}", pct(e.score.rel_sd[m][l][i])))
                        .collect::<Vec<_>>()
                        .join(", "),
                );
                row.push(format!("{:.1}", e.score.info_gain));
                rows.push(row);
            }
        }
    };
    if let Some(cur) = &r.current {
        show("the study's", cur);
    }
    show("best", &r.best);
    for (k, e) in r
        .ranked
        .iter()
        .filter(|e| !same(e, &r.best))
        .take(4)
        .enumerate()
    {
        show(&format!("alternative {}", k + 1), e);
    }
    rep.table(
        &[
            "design",
            "drive",
            "sensors",
            "model",
            "level",
            "predicted sd",
            "information gain (nats)",
        ],
        &rows,
    );
    if let Some(f) = figure {
        rep.image(f, "information gain per candidate channel along the joint");
    }
    rep.heading(2, "How this was predicted");
    let s = &r.settings;
    rep.paragraph(&format!(
        "Each design's posterior is the Laplace approximation of the likelihood `rfmlab run` fits: the Fisher information of the same forward model (reduced model, H1 measurement model) and coherence noise model, with the coherence the measurement chain is expected to give ({} averages, force noise {:.2} % of its RMS, accelerometer noise {}), plus the priors' curvature. It is averaged over {} of the parameters (geometric mean of the relative sds). Sensors are uniaxial, one per place; the channels' errors are taken as independent. Designs: {} sensors, drive at point(s) {}.",
        s.n_averages,
        100.0 * s.force_noise,
        match s.response_noise {
            crate::study::design::ResponseNoise::Fraction(f) => format!("{:.2} % of each channel's RMS", 100.0 * f),
            crate::study::design::ResponseNoise::Rms(v) => format!("{v:.1e} m/s^2 RMS"),
        },
        if s.draws == 0 {
            "the models' initial values (draws = 0)".to_string()
        } else {
            format!("{} Latin-hypercube draws from the priors", s.draws)
        },
        r.best.channels.len(),
        s.drives
            .as_ref()
            .map(|d| d.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(", "))
            .unwrap_or_else(|| "the study's excitation".into())
    ));
    for n in &r.notes {
        rep.paragraph(n);
    }
    rep.paragraph(&format!(
        "Timings: {}.",
        r.timings
            .iter()
            .map(|(k, v)| format!("{k} {v:.1} s"))
            .collect::<Vec<_>>()
            .join(", ")
    ));
    rep
}

/// Write the design's files into `target` (replaced as a whole under `replace`).
pub fn write(
    r: &DesignResult,
    study_file: &Path,
    seed: u64,
    target: &Path,
    replace: Replace,
) -> Result<(), OutputError> {
    crate::output::replace_dir_as(target, replace, |tmp| -> Result<(), OutputError> {
        let parent = tmp.parent().unwrap_or(Path::new("."));
        let name = tmp
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut dir = ResultsDir::create(parent, &name)?;
        dir.write_table(&designs_table(r)?)?;
        dir.write_table(&candidates_table(r)?)?;
        let figure = figure(r, &dir.file_path("design_information"));
        let fig_name = figure.as_ref().map(|_| "design_information.png");
        if let Some(files) = &figure {
            for f in files {
                dir.record(f);
            }
        }
        dir.write_report(&markdown(r, fig_name))?;
        let mut m = Manifest::new(study_file, Some(seed));
        for (k, v) in &r.timings {
            m.add_timing(k.clone(), *v);
        }
        for n in &r.notes {
            m.add_note(n.clone());
        }
        dir.write_manifest(&mut m)?;
        Ok(())
    })
}

/// The information each candidate channel adds to the best design, against its position
/// along the joint, one series per face and direction, the best design's channels marked.
fn figure(r: &DesignResult, stem: &Path) -> Option<Vec<std::path::PathBuf>> {
    use crate::plot::{Curve, CurveStyle};
    let mut series: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    let mut chosen = (Vec::new(), Vec::new());
    for (k, ch) in r.channels.iter().enumerate() {
        let pl = &r.places[ch.place];
        let label = format!("{} {}", pl.face, axis_name(ch.axis));
        let g = r.channel_gain[k].max(1e-6);
        let x = pl.position_m[0] * 1e3;
        match series.iter_mut().find(|s| s.0 == label) {
            Some(s) => {
                s.1.push(x);
                s.2.push(g);
            }
            None => series.push((label, vec![x], vec![g])),
        }
        if r.best.channels.contains(&k) {
            chosen.0.push(x);
            chosen.1.push(g);
        }
    }
    let mut curves: Vec<Curve> = series
        .into_iter()
        .map(|(l, x, y)| Curve::new(l, x, y, CurveStyle::Points))
        .collect();
    let mut best = Curve::new("best design", chosen.0, chosen.1, CurveStyle::Points);
    best.color = Some((0, 0, 0));
    curves.push(best);
    crate::plot::line_figure(
        stem,
        "Information each candidate sensor adds to the best design",
        "x along the joint (mm)",
        "information gain (nats)",
        &curves,
        true,
    )
    .ok()
    .map(|f| vec![f.png, f.svg])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::common::Axis;
    use crate::design::{candidates::Place, search::Score, Channel};

    /// Two laws with different parameters in one table: every row has every law's columns
    /// (NaN where a law lacks the parameter).
    #[test]
    fn designs_table_holds_laws_with_different_parameters() {
        let score = Score {
            rel_sd: vec![vec![vec![0.01, 0.02]], vec![vec![0.03, 0.04, 0.05]]],
            worst: 0.05,
            sum_log: 0.0,
            info_gain: 1.0,
        };
        let e = Evaluated {
            channels: vec![0],
            drive: 1,
            score,
            own_masses: true,
        };
        let r = DesignResult {
            models: vec!["model1".into(), "model3".into()],
            params: vec![
                vec!["E0".into(), "h".into()],
                vec!["E0".into(), "E1".into(), "eta1".into()],
            ],
            levels: vec!["L1".into()],
            places: vec![Place {
                id: 1,
                position_m: [0.1, 0.01, 0.01],
                face: "point".into(),
                current: true,
            }],
            channels: vec![Channel {
                place: 0,
                axis: Axis::Y,
                output: 0,
            }],
            current: Some(e.clone()),
            best: e.clone(),
            ranked: vec![e],
            channel_gain: vec![1.0],
            draws: Vec::new(),
            settings: crate::design::default_settings(),
            notes: Vec::new(),
            timings: Vec::new(),
        };
        let t = designs_table(&r).unwrap();
        assert_eq!(t.n_rows(), 4);
        let h = t.column("sd_rel_h").unwrap().as_f64().unwrap();
        assert_eq!(h[0], 0.02);
        assert!(h[1].is_nan());
        let eta1 = t.column("sd_rel_eta1").unwrap().as_f64().unwrap();
        assert_eq!(eta1[1], 0.05);
        assert!(candidates_table(&r).is_ok());
    }
}
