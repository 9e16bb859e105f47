//! Every FRF and coherence dataset in shared/data/uff reads; ASCII/binary pairs agree; values
//! agree with pyuff (independent reader) to 1e-6 relative except where pyuff is known wrong.
//!
//! Deliberately not read (skipped with a note): datasets other than 58 and 164 (15, 18, 55, 82,
//! 151, 1858, 1859, 2411, 2412, 2414, 2420, 734): nodes, geometry, mode shapes and headers carry
//! no functions. `pyuff_testdata/dataset_milestone_in_header.uff` is an error on purpose: it
//! is truncated (num_pts 2 508 876, 42 values present).

use crate::common_data::*;

use rfmlab::common::Direction;
use rfmlab::data::uff58::{read_uff, Ordinate, Precision, Uff58Dataset};
use rfmlab::data::uff_frf::{frf_set_from_uff, UffImportOptions};
use rfmlab::data::Quantity;

fn all_uff_files() -> Vec<std::path::PathBuf> {
    let mut v = Vec::new();
    for sub in [
        "uff/ufffiles_jl",
        "uff/readuff_matlab",
        "uff/pyuff_testdata",
    ] {
        let mut e: Vec<_> = std::fs::read_dir(data(sub))
            .expect("shared data")
            .flatten()
            .map(|e| e.path())
            .collect();
        e.sort();
        v.extend(
            e.into_iter()
                .filter(|p| p.file_name().is_some_and(|n| n != "LICENSE")),
        );
    }
    v
}

fn re_im(d: &Uff58Dataset) -> (Vec<f64>, Option<Vec<f64>>) {
    match &d.values {
        Ordinate::Real(v) => (v.clone(), None),
        Ordinate::Complex(v) => (
            v.iter().map(|z| z.re).collect(),
            Some(v.iter().map(|z| z.im).collect()),
        ),
    }
}

fn close(a: &[f64], b: &[f64], rel: f64) -> Result<(), String> {
    if a.len() != b.len() {
        return Err(format!("lengths {} vs {}", a.len(), b.len()));
    }
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        if (x - y).abs() > rel * y.abs().max(1e-6 * scale) {
            return Err(format!("value {k}: {x} vs {y}"));
        }
    }
    Ok(())
}

#[test]
fn every_file_reads_or_fails_for_a_stated_reason() {
    let mut n58 = 0;
    let mut n_frf_coh = 0;
    for p in all_uff_files() {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let r = read_uff(&p);
        if name == "dataset_milestone_in_header.uff" {
            let e = r.expect_err("truncated file must fail");
            assert_eq!(e.dataset, Some(0));
            assert!(e.line.is_some() && e.message.contains("2508876"), "{e}");
            continue;
        }
        let f = r.unwrap_or_else(|e| panic!("{name}: {e}"));
        for d in &f.datasets {
            n58 += 1;
            assert_eq!(d.values.len(), d.num_pts, "{name} ds {}", d.index);
            assert_eq!(d.x.len(), d.num_pts);
            if d.func_type == 4 || d.func_type == 6 {
                n_frf_coh += 1;
            }
        }
    }
    assert!(n58 >= 40, "{n58} datasets 58");
    assert!(n_frf_coh >= 45, "{n_frf_coh} FRF/coherence datasets");
}

#[test]
fn ascii_binary_pairs_agree() {
    for case in 1..=8 {
        let a = read_uff(data(&format!(
            "uff/ufffiles_jl/dataset58_case{case}_ascii.unv"
        )))
        .unwrap();
        let b = read_uff(data(&format!(
            "uff/ufffiles_jl/dataset58_case{case}_binary.unv"
        )))
        .unwrap();
        let (a, b) = (&a.datasets[0], &b.datasets[0]);
        assert!(b.binary && !a.binary);
        assert_eq!(a.num_pts, b.num_pts);
        assert_eq!(a.ord_data_type, b.ord_data_type);
        assert_eq!(a.even, b.even, "case {case}");
        // ASCII has 6 significant digits for singles and 13 for doubles
        let tol = if a.precision == Precision::Single {
            1e-6
        } else {
            1e-11
        };
        let (ar, ai) = re_im(a);
        let (br, bi) = re_im(b);
        close(&ar, &br, tol).unwrap_or_else(|e| panic!("case {case} re: {e}"));
        if let (Some(ai), Some(bi)) = (ai, bi) {
            close(&ai, &bi, tol).unwrap_or_else(|e| panic!("case {case} im: {e}"));
        }
        // abscissa: E13.5 in ASCII (6 digits, 5e-6 relative), float32 in binary
        close(&a.x, &b.x, 5e-6).unwrap_or_else(|e| panic!("case {case} x: {e}"));
        assert!(
            b.notes.iter().all(|n| !n.contains("differs")),
            "case {case}: {:?}",
            b.notes
        );
    }
}

#[test]
fn named_files() {
    // dam0: 26 FRFs, complex single, 0..12.5 Hz
    let f = read_uff(data("uff/readuff_matlab/dam0.unv")).unwrap();
    let frfs: Vec<_> = f.datasets.iter().filter(|d| d.func_type == 4).collect();
    assert_eq!(frfs.len(), 26);
    assert!(frfs
        .iter()
        .all(|d| d.precision == Precision::Single && d.values.is_complex()));
    // UFF58B.FRF: 1601 lines complex single, 0..20 kHz, CRLF, Latin-1 id line
    let f = read_uff(data("uff/readuff_matlab/UFF58B.FRF")).unwrap();
    let d = &f.datasets[0];
    assert!(d.binary && d.values.is_complex() && d.precision == Precision::Single);
    assert_eq!(d.num_pts, 1601);
    assert_eq!(d.x[1600], 20000.0);
    assert!(d.ids[3].contains('°'), "{:?}", d.ids[3]);
    // dataset58_FRF: 1600 points, last line zero-padded -> exactly num_pts kept, note
    for name in ["dataset58_FRF.unv", "dataset58_FRF_UTF.unv"] {
        let f = read_uff(data(&format!("uff/ufffiles_jl/{name}"))).unwrap();
        let d = &f.datasets[0];
        assert_eq!(d.values.len(), 1600);
        assert!(
            d.notes.iter().any(|n| n.contains("kept 1600")),
            "{:?}",
            d.notes
        );
        assert_eq!(d.rsp_entity, ".1.Z-");
    }
    let set = frf_set_from_uff(
        &[(data("uff/ufffiles_jl/dataset58_FRF.unv"), "L1".to_string())],
        &UffImportOptions::default(),
    )
    .unwrap();
    let ch = &set.levels[0].channels[0];
    assert_eq!(set.levels[0].quantity, Quantity::Mobility); // units label (m/s)/N
    assert_eq!(
        (ch.response_id, ch.response_dir),
        (1, Direction::new(rfmlab::common::Axis::Z, -1))
    );
    assert_eq!((ch.reference_id, ch.reference_dir), (56, Direction::PZ));
    // glued fields with 3-digit exponents
    let f = read_uff(data("uff/ufffiles_jl/dataset58_nospacing.uff")).unwrap();
    let (re, _) = re_im(&f.datasets[0]);
    assert_eq!(&re[..3], &[-3.09944e-4, -2.74181e-4, -0.00115633]);
    // 58b id line without trailing fields, unit exponents in records 9/10
    let f = read_uff(data("uff/ufffiles_jl/dataset58_ufb.ufb")).unwrap();
    assert_eq!(f.datasets[0].num_pts, 801);
    assert_eq!(
        (
            f.datasets[0].ordinate.length_exp,
            f.datasets[0].denominator.force_exp
        ),
        (1, 1)
    );
    // Latin-1 units label
    let f = read_uff(data("uff/pyuff_testdata/non_ascii_header.uff")).unwrap();
    assert_eq!(f.datasets[0].ordinate.units_label, "(1/N)*(m/s²)");
    // dataset 164 units
    let f = read_uff(data("uff/ufffiles_jl/dataset164.unv")).unwrap();
    let u = f.units.expect("units");
    assert_eq!((u.code, u.length, u.force), (1, 1.0, 1.0));
}

#[test]
fn beam_reads_as_three_accelerance_frfs() {
    let set = frf_set_from_uff(
        &[(data("beam/beam_accelerance_3frf.uff"), "beam".to_string())],
        &UffImportOptions::default(),
    )
    .unwrap();
    assert_eq!(set.levels.len(), 1);
    let l = &set.levels[0];
    assert_eq!(l.quantity, Quantity::Accelerance);
    assert_eq!(l.channels.len(), 3);
    assert_eq!(l.freq_hz.len(), 1001);
    assert_eq!((l.freq_hz[0], l.freq_hz[1000]), (0.0, 1000.0));
    // first line of meas_point_1.txt: (-0.0774752256830106+2.6838208936737454e-08j)
    let h = l.channels[0].values[0];
    assert!(
        (h.re + 0.0774752256830106).abs() < 1e-12 && (h.im - 2.6838208936737454e-08).abs() < 1e-18,
        "{h}"
    );
    // impact file: FRF + coherence paired
    let set = frf_set_from_uff(
        &[(data("impact/impact_H1_coh.uff"), "L1".to_string())],
        &UffImportOptions::default(),
    )
    .unwrap();
    let c = &set.levels[0].channels;
    assert_eq!(c.len(), 1);
    let coh = c[0].coherence.as_ref().expect("coherence paired");
    assert_eq!(coh.len(), set.levels[0].freq_hz.len());
}

#[test]
fn values_agree_with_pyuff() {
    let Some(py) = python_with_pyuff() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let files: Vec<_> = all_uff_files()
        .into_iter()
        .filter(|p| !p.to_string_lossy().contains("milestone"))
        .filter(|p| read_uff(p).map(|f| !f.datasets.is_empty()).unwrap_or(false))
        .collect();
    let dump = pyuff_dump(&py, &files, tmp.path());
    let mut compared = 0;
    for p in &files {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let ours = read_uff(p).unwrap();
        let theirs = &dump[p.to_string_lossy().as_ref()];
        if theirs.get("error").is_some() {
            eprintln!("pyuff cannot read {name}: {}", theirs["error"]);
            continue;
        }
        let theirs = theirs.as_array().unwrap();
        assert_eq!(theirs.len(), ours.datasets.len(), "{name}");
        for (d, t) in ours.datasets.iter().zip(theirs) {
            // pyuff is known wrong for 58b uneven double written per spec (float32 abscissa):
            // those are checked against their ASCII twin in ascii_binary_pairs_agree.
            if d.binary && !d.even && d.precision == Precision::Double {
                continue;
            }
            let (re, im) = re_im(d);
            let mut tre = nums(&t["re"]);
            let mut tim = if t["im"].is_null() {
                None
            } else {
                Some(nums(&t["im"]))
            };
            let mut tx = nums(&t["x"]);
            // pyuff keeps zero padding beyond num_pts: the extra values must be zeros.
            if tre.len() > re.len() {
                assert!(
                    tre[re.len()..].iter().all(|v| *v == 0.0),
                    "{name}: padding not zero"
                );
                tre.truncate(re.len());
                tx.truncate(re.len());
                if let Some(v) = tim.as_mut() {
                    assert!(v[re.len()..].iter().all(|x| *x == 0.0));
                    v.truncate(re.len());
                }
            }
            close(&re, &tre, 1e-6).unwrap_or_else(|e| panic!("{name} ds {} re: {e}", d.index));
            if let (Some(a), Some(b)) = (&im, &tim) {
                close(a, b, 1e-6).unwrap_or_else(|e| panic!("{name} ds {} im: {e}", d.index));
            }
            close(&d.x, &tx, 1e-6).unwrap_or_else(|e| panic!("{name} ds {} x: {e}", d.index));
            assert_eq!(
                (d.rsp_node, d.ref_node),
                (
                    t["rsp_node"].as_i64().unwrap(),
                    t["ref_node"].as_i64().unwrap()
                )
            );
            compared += 1;
        }
    }
    assert!(compared >= 40, "only {compared} datasets compared");
}
