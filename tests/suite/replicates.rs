//! The likelihood's weighting pays off: over replicate data sets at a
//! realistic noise level, the MAP of the coherence likelihood scatters far less than the
//! deterministic RFM, which weighs a line of low coherence as much as a clean one.
//!
//! Data: rfmlab's virtual experiment in frequency-domain mode ([`simulate_level`] with
//! [`Mode::FrequencyDomain`]: block spectra drawn from their exact Gaussian law; Hann 1 s blocks,
//! 200 averages at 50 % overlap, force band (1, 500] Hz at Level 1's 3.3 N RMS), on the 10 mm
//! joint of `runner_common` through a certified ROM, Model 4 at the paper's Table 4 truth, white
//! sensor noise set so that the median coherence is about 0.99 (0.990 measured; the lowest
//! lines, 1-6 Hz, and the anti-resonances fall below 0.01); one seed per replicate.
//!
//! Fits: one study with one level per replicate, run as a user runs it ([`run_study`], the
//! estimator declared as the data were made): the global Model 4 RFM (the runner's, with its
//! leakage fixed point) and the MAP of the coherence likelihood (`[inference]` without samplers:
//! the runner's MAP search on `build_posterior`, started from the initial values and the RFM
//! result), both from Table 4's initial values.
//!
//! Checked per parameter: the MAP's sd and range of the relative error over the replicates are
//! at most a third of the RFM's, and the MAP's mean error is within 3 standard errors of zero.
//! Measured with 20 replicates (relative error, sd / range in %): RFM E0 11.4 / -20..+23,
//! h 34 / -58..+78, E1 25 / -39..+40, eta1 44 / -68..+105; MAP E0 0.067 / -0.11..+0.12,
//! h 0.27 / -0.64..+0.48, E1 0.14 / -0.30..+0.21, eta1 0.37 / -0.92..+0.59: ratios 0.006-0.009.
//! The MAP's spread is 1.5-1.8 times its Laplace sd: near the two resonances the channels'
//! H1 errors are correlated (the incoherent part left by the window's leakage is driven by
//! the same force in every channel; pooled |correlation| 0.3-0.7 there, below 0.1 elsewhere),
//! and the likelihood treats channels as independent.
//!
//! In the default suite: the first [`SHORT`] replicates, 35 s in release (about 11 s for the
//! study's ROM, then 3-5 s per replicate, on this 2-core machine while another build ran). The
//! ignored tests run all [`LONG`] (20), 98 s each (`cargo test --release --test suite --
//! --ignored NAME`): `map_of_the_coherence_likelihood_scatters_a_third_of_the_rfm_over_20_replicates`
//! and `with_the_leakage_correlation_the_map_scatter_matches_the_laplace_sd`.

use crate::runner_common::{built_structure, initial_of, structure};
use rfmlab::common::C64;
use rfmlab::experiment::plant::EnginePlant;
use rfmlab::experiment::{
    simulate_level, ChainParams, ChannelLabel, ExperimentError, Mode, NoiseLevel, Plant,
};
use rfmlab::output::{ColumnData, Table};
use rfmlab::report::run_study;
use rfmlab::report::RunOptions;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

/// Replicates of the always-on run.
const SHORT: usize = 5;
/// Replicates of the ignored tests (the scatter-over-Laplace-sd check needs them).
const LONG: usize = 20;
/// Response-sensor noise, fraction of each channel's RMS (white over 0..fs/2): median
/// coherence about 0.99 at Level 1.
const RESPONSE_NOISE: f64 = 0.06;
/// Force-sensor noise, fraction of the force RMS (the default rig's 0.2 %).
const FORCE_NOISE: f64 = 0.002;
/// Seed of replicate r: `SEED + r`.
const SEED: u64 = 20_251_100;

/// Accelerance `[channel][line]` of one grid, keyed by the grid's bits.
type Evaluated = (Vec<u64>, Vec<Vec<C64>>);

/// The simulation's plant, evaluated once per grid: every replicate asks for the same fine
/// grid and lines; only the noise differs.
struct Memo<'a> {
    plant: EnginePlant<'a>,
    seen: Mutex<Vec<Evaluated>>,
}

impl Plant for Memo<'_> {
    fn n_channels(&self) -> usize {
        self.plant.n_channels()
    }
    fn drive_channel(&self) -> usize {
        self.plant.drive_channel()
    }
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        let key: Vec<u64> = freq_hz.iter().map(|f| f.to_bits()).collect();
        let seen = self.seen.lock().unwrap();
        if let Some((_, v)) = seen.iter().find(|(k, _)| *k == key) {
            return Ok(v.clone());
        }
        drop(seen);
        let v = self.plant.accelerance(freq_hz)?;
        self.seen.lock().unwrap().push((key, v.clone()));
        Ok(v)
    }
}

/// Mean, sample sd, min and max.
fn stats(x: &[f64]) -> (f64, f64, f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let min = x.iter().copied().fold(f64::INFINITY, f64::min);
    let max = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (mean, var.sqrt(), min, max)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn str_column<'t>(t: &'t Table, name: &str) -> &'t [String] {
    match t.column(name) {
        Some(ColumnData::Str(v)) => v,
        _ => panic!("{}.{name} is not a string column", t.name()),
    }
}

/// The study: the 10 mm joint, one level per replicate file, Model 4 from Table 4's initial
/// values, the estimator as the data were made, the MAP of the coherence likelihood.
fn study_text(
    out: &Path,
    files: &[(String, std::path::PathBuf)],
    n_averages: f64,
    correlation: &str,
) -> String {
    let mut s = format!(
        "[study]\nname = \"replicates\"\noutput_dir = \"{}\"\nseed = 11\n{}\n\
[measurements]\nband_hz = [1.0, 500.0]\n\
[measurements.estimator]\nwindow = \"hann\"\nblock_s = 1.0\nfs_hz = 2048.0\nforce_band_hz = [1.0, 500.0]\n",
        out.display(),
        structure()
    );
    for (name, file) in files {
        writeln!(
            s,
            "[[measurements.levels]]\nname = \"{name}\"\nfiles = [\"{}\"]\nforce_rms_n = 3.3",
            file.display()
        )
        .unwrap();
    }
    s.push_str("[[models]]\nname = \"model4\"\n[models.initial]\n");
    for (p, v) in initial_of(4) {
        writeln!(s, "{p} = {v:e}").unwrap();
    }
    write!(
        s,
        "[solver]\nengine = \"rom\"\n\
[analyses]\nper_line = false\nsensitivity = false\nfigures = false\n\
[inference]\nmodels = [\"model4\"]\nsamplers = []\n\
[inference.noise]\nmodel = \"coherence\"\nn_averages = {n_averages}\nchannel_correlation = \"{correlation}\"\n\
[inference.map]\nstarts = 0\n"
    )
    .unwrap();
    s
}

#[test]
fn map_of_the_coherence_likelihood_scatters_a_third_of_the_rfm_over_replicates() {
    replicates("none", SHORT);
}

#[test]
#[ignore = "slow: 20 replicate experiments and a 20-level study, about 98 s in release on 2 cores; run with --ignored"]
fn map_of_the_coherence_likelihood_scatters_a_third_of_the_rfm_over_20_replicates() {
    replicates("none", LONG);
}

/// The same replicates with the channels' errors modelled as the leakage jitter
/// (`channel_correlation = "leakage"`): the MAP still scatters a third of the RFM.
#[test]
fn with_the_leakage_correlation_the_map_scatters_a_third_of_the_rfm() {
    replicates("leakage", SHORT);
}

/// The same over 20 replicates, and the MAP's scatter over its Laplace sd is at most 1.5.
/// Measured over 20 replicates: 1.16-1.41 (E0 1.31, h 1.16, E1 1.24, eta1 1.41) against
/// 1.53-1.83 with independent channels (the 99 % band of an sd from 20 draws is 0.60-1.42 times
/// the true one). What is left is the correlation between neighbouring lines of a
/// Hann-windowed estimate, which the likelihood does not model.
#[test]
#[ignore = "slow: 20 replicate experiments and a 20-level study, about 98 s in release on 2 cores; run with --ignored"]
fn with_the_leakage_correlation_the_map_scatter_matches_the_laplace_sd() {
    replicates("leakage", LONG);
}

/// `n_rep` replicates fitted with `channel_correlation = correlation`; the MAP's scatter over
/// its Laplace sd is checked with [`LONG`] replicates and a channel correlation.
fn replicates(correlation: &str, n_rep: usize) {
    let t0 = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let built = built_structure();
    let law = rfmlab::material::model_from_name("model4", None).unwrap();
    let (truth, _) = rfmlab::material::paper_table4(4);
    let names = law.param_names();

    // The simulation's engine: a certified ROM of the drive-point column over the band and
    // the truth's moduli (like `rfmlab simulate`).
    let chain0 = ChainParams {
        mode: Mode::FrequencyDomain,
        force_noise: NoiseLevel::FractionOfSignalRms(FORCE_NOISE),
        response_noise: vec![NoiseLevel::FractionOfSignalRms(RESPONSE_NOISE)],
        ..ChainParams::default()
    };
    let (lo, hi) = chain0.band_hz;
    let band = ((lo - 0.5).max(0.25), hi + 1.0);
    let moduli: Vec<C64> = (0..=200)
        .map(|k| {
            let f = band.0 + (band.1 - band.0) * k as f64 / 200.0;
            law.modulus(&truth, std::f64::consts::TAU * f)
        })
        .collect();
    let fold = |f: fn(f64, f64) -> f64, init: f64, part: fn(&C64) -> f64| {
        moduli.iter().map(part).fold(init, f)
    };
    let range = rfmlab::rom::ModulusRange {
        e_storage_pa: (
            fold(f64::min, f64::INFINITY, |z| z.re) / 1.5,
            fold(f64::max, 0.0, |z| z.re) * 1.5,
        ),
        e_loss_pa: (
            fold(f64::min, f64::INFINITY, |z| z.im) / 1.5,
            fold(f64::max, 0.0, |z| z.im) * 1.5,
        ),
    };
    let (rom, cert) = rfmlab::rom::build_rom(
        &built.model,
        &[built.excitation],
        &rfmlab::rom::RomParams {
            band_hz: band,
            range,
            tolerance: 1e-5,
            ..rfmlab::rom::RomParams::default()
        },
    )
    .unwrap();
    let t_rom = t0.elapsed().as_secs_f64();
    let modulus = |w: f64| law.modulus(&truth, w);
    let plant = Memo {
        plant: EnginePlant {
            engine: &rom,
            modulus: &modulus,
            input_col: 0,
            drive_output: built.excitation,
        },
        seen: Mutex::new(Vec::new()),
    };
    let exc = &built.model.points[built.excitation];
    let labels = ChannelLabel::for_responses(
        built.model.points.iter().map(|p| (p.id, p.direction)),
        (exc.id, exc.direction),
    );

    // Replicates.
    let mut files = Vec::new();
    let mut medians = Vec::new();
    let mut n_eff = 0.0;
    let mut low: Vec<(f64, f64, u32)> = Vec::new(); // (coherence, Hz, channel) of replicate 0
    for r in 0..n_rep {
        let chain = ChainParams {
            seed: SEED + r as u64,
            ..chain0.clone()
        };
        let sim = simulate_level(&plant, &chain).unwrap();
        n_eff = sim.truth.effective_averages;
        let coh: Vec<f64> = sim
            .channels
            .iter()
            .flat_map(|c| c.coherence.iter().copied())
            .collect();
        medians.push(median(coh));
        if r == 0 {
            for (c, ch) in sim.channels.iter().enumerate() {
                for (l, g) in ch.coherence.iter().enumerate() {
                    low.push((*g, sim.freq_hz[l], labels[c].response_id));
                }
            }
        }
        let name = format!("R{r:02}");
        let level = sim.to_frf_level(&name, &labels).unwrap();
        let file = dir.path().join(format!("{name}.uff"));
        rfmlab::data::frf_set_to_uff(
            &rfmlab::data::FrfSet {
                levels: vec![level],
            },
            &file,
            true,
        )
        .unwrap();
        files.push((name, file));
    }
    let t_sim = t0.elapsed().as_secs_f64() - t_rom;
    low.sort_by(|a, b| a.0.total_cmp(&b.0));
    let below = |x: f64| low.iter().filter(|l| l.0 < x).count();
    eprintln!(
        "sim ROM {} vectors, certificate {:.1e}; median coherence per replicate {:.4}..{:.4}; replicate 0: {} of {} values below 0.9, {} below 0.5; lowest {:?}",
        cert.basis_size,
        cert.max_rel_error,
        medians.iter().copied().fold(f64::INFINITY, f64::min),
        medians.iter().copied().fold(0.0, f64::max),
        below(0.9),
        low.len(),
        below(0.5),
        &low[..8.min(low.len())]
    );

    // One study, one level per replicate.
    let out = dir.path().join("out");
    let text = study_text(&out, &files, n_eff, correlation);
    let file = dir.path().join("replicates.toml");
    std::fs::write(&file, text).unwrap();
    let study = rfmlab::study::load(&file).unwrap();
    let summary = run_study(
        &study,
        &RunOptions {
            no_figures: true,
            output_dir: Some(out.clone()),
            rom_cache: Some(crate::shared_rom_cache::runs_folder()),
        },
        &|_| {},
    )
    .unwrap();
    let t_fit = t0.elapsed().as_secs_f64() - t_rom - t_sim;
    let lap = Table::read_parquet(out.join("laplace.parquet")).unwrap();
    let (lv, par) = (str_column(&lap, "level"), str_column(&lap, "parameter"));
    let (map_col, sd_col) = (
        lap.column("map").and_then(|c| c.as_f64()).unwrap(),
        lap.column("sd").and_then(|c| c.as_f64()).unwrap(),
    );

    // Relative errors per replicate: [param][replicate].
    let np = names.len();
    let mut rfm = vec![Vec::new(); np];
    let mut map = vec![Vec::new(); np];
    let mut lap_sd = vec![Vec::new(); np];
    for (name, _) in &files {
        let m = summary
            .models
            .iter()
            .find(|m| m.level == *name && m.model == "model4")
            .unwrap_or_else(|| panic!("no Model 4 RFM result at {name}"));
        assert_eq!(m.param_names, names);
        let mut line = format!("{name}: RFM ({}, {} it)", m.stop_reason, m.iterations);
        for k in 0..np {
            let e = (m.identified[k] - truth[k]) / truth[k];
            rfm[k].push(e);
            write!(line, " {} {:+.2} %", names[k], 100.0 * e).unwrap();
        }
        line.push_str(" | MAP");
        for k in 0..np {
            let row = (0..lap.n_rows())
                .find(|&i| lv[i] == *name && par[i] == names[k])
                .unwrap_or_else(|| panic!("no MAP of {} at {name}", names[k]));
            let e = (map_col[row] - truth[k]) / truth[k];
            map[k].push(e);
            lap_sd[k].push(sd_col[row] / truth[k]);
            write!(line, " {} {:+.3} %", names[k], 100.0 * e).unwrap();
        }
        eprintln!("{line}");
    }

    eprintln!(
        "{n_rep} replicates, relative error (%): sd and range over replicates\n\
param | RFM mean | RFM sd | RFM range        | MAP mean | MAP sd | MAP range        | Laplace sd | sd ratio | range ratio | MAP sd / Laplace sd (channel_correlation = {correlation})"
    );
    let mut failures = Vec::new();
    for k in 0..np {
        let (rm, rs, rlo, rhi) = stats(&rfm[k]);
        let (mm, ms, mlo, mhi) = stats(&map[k]);
        let lsd = lap_sd[k].iter().sum::<f64>() / n_rep as f64;
        eprintln!(
            "{:5} | {:+8.3} | {:6.3} | {:+7.2}..{:+7.2} | {:+8.4} | {:6.4} | {:+7.3}..{:+7.3} | {:10.4} | {:8.3} | {:11.3} | {:.3}",
            names[k],
            100.0 * rm,
            100.0 * rs,
            100.0 * rlo,
            100.0 * rhi,
            100.0 * mm,
            100.0 * ms,
            100.0 * mlo,
            100.0 * mhi,
            100.0 * lsd,
            ms / rs,
            (mhi - mlo) / (rhi - rlo),
            ms / lsd
        );
        if correlation != "none" && n_rep == LONG && !(0.6..=1.5).contains(&(ms / lsd)) {
            failures.push(format!(
                "{}: MAP sd over replicates / Laplace sd = {:.3}, outside 0.6-1.5",
                names[k],
                ms / lsd
            ));
        }
        if ms > rs / 3.0 {
            failures.push(format!(
                "{}: MAP sd {:.4} % > RFM sd {:.4} % / 3",
                names[k],
                100.0 * ms,
                100.0 * rs
            ));
        }
        if mhi - mlo > (rhi - rlo) / 3.0 {
            failures.push(format!(
                "{}: MAP range {:.4} % > RFM range {:.4} % / 3",
                names[k],
                100.0 * (mhi - mlo),
                100.0 * (rhi - rlo)
            ));
        }
        let se = ms / (n_rep as f64).sqrt();
        if mm.abs() > 3.0 * se {
            failures.push(format!(
                "{}: MAP mean error {:+.4} % is beyond 3 standard errors ({:.4} %)",
                names[k],
                100.0 * mm,
                100.0 * 3.0 * se
            ));
        }
    }
    eprintln!(
        "time: ROM {t_rom:.1} s, simulation {t_sim:.1} s, study (RFM + MAP) {t_fit:.1} s, total {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    let m = median(medians);
    assert!(
        (0.98..=0.995).contains(&m),
        "median coherence {m:.4}: the noise settings no longer give about 0.99"
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
