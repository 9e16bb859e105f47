//! Bad files and bad levels give a DataError naming file, dataset and line; never a panic.

use rfmlab::common::{Direction, C64};
use rfmlab::data::uff58::parse_uff;
use rfmlab::data::{check_level, Channel, FrfLevel, Quantity};

const GOOD: &str = "    -1
    58
NONE
NONE
NONE
NONE
NONE
    4         0    0         0       NONE         2   3       NONE         1   3
         6         3         1  1.00000e+00  1.00000e+00  0.00000e+00
        18    0    0    0 NONE                 Hz
        12    0    0    0 NONE                 m/s^2
        13    0    0    0 NONE                 N
         0    0    0    0 NONE                 NONE
   1.00000000000e+00   2.00000000000e+00   3.00000000000e+00   4.00000000000e+00
   5.00000000000e+00   6.00000000000e+00
    -1
";

fn bad(text: &str) -> rfmlab::data::DataError {
    let g = parse_uff(GOOD.as_bytes(), "good.uff").unwrap();
    assert_eq!(g.datasets[0].values.len(), 3);
    parse_uff(text.as_bytes(), "bad.uff").expect_err("must fail")
}

#[test]
fn bad_files_name_file_dataset_line() {
    // truncated dataset (cut inside the data)
    let e = bad(&GOOD[..GOOD.find("   5.0000").unwrap()]);
    assert_eq!((e.file.as_str(), e.dataset), ("bad.uff", Some(0)));
    assert!(e.line.is_some() && e.message.contains("truncated"), "{e}");
    // missing records
    let e = bad(&GOOD[..GOOD.find("        18").unwrap()]);
    assert!(
        e.message.contains("record 7 of 11") && e.line.is_some(),
        "{e}"
    );
    // garbage numbers
    let e = bad(&GOOD.replace("   5.00000000000e+00", "   5.0000x000000e+00"));
    assert_eq!(e.line, Some(15), "{e}");
    // inconsistent num_pts
    let e = bad(&GOOD.replace("         6         3", "         6         4"));
    assert!(e.message.contains("num_pts") && e.dataset == Some(0), "{e}");
    // bad ordinate type
    let e = bad(&GOOD.replace("         6         3", "         7         3"));
    assert_eq!(e.line, Some(9), "{e}");
    // the second of two datasets is bad -> index 1
    let two = format!(
        "{GOOD}{}",
        GOOD.replace("   5.00000000000e+00", "   garbage")
    );
    let e = parse_uff(two.as_bytes(), "bad.uff").unwrap_err();
    assert_eq!(e.dataset, Some(1));
    assert!(
        e.to_string().starts_with("bad.uff: dataset 1, line 31"),
        "{e}"
    );
}

fn level() -> FrfLevel {
    let ch = |r: u32, c: u32| Channel {
        response_id: r,
        response_dir: Direction::PY,
        reference_id: c,
        reference_dir: Direction::PY,
        values: vec![C64::new(1.0, 0.0); 3],
        coherence: Some(vec![0.9; 3]),
        source: Some(("f.uff".into(), r as usize)),
    };
    FrfLevel {
        name: "L1".into(),
        force_rms_n: None,
        n_averages: None,
        quantity: Quantity::Accelerance,
        freq_hz: vec![1.0, 2.0, 3.0],
        channels: vec![ch(1, 2), ch(2, 2)],
    }
}

#[test]
fn level_checks() {
    let l = level();
    check_level(&l, Some((2, Direction::PY)), Some((1.0, 3.0))).unwrap();
    // excitation missing
    let e = check_level(&l, Some((3, Direction::PY)), None).unwrap_err();
    assert!(e.message.contains("excitation"), "{e}");
    // band not covered
    let e = check_level(&l, None, Some((0.5, 3.0))).unwrap_err();
    assert!(e.message.contains("band"), "{e}");
    // duplicate channel (sign ignored)
    let mut d = level();
    d.channels[1].response_id = 1;
    d.channels[1].response_dir = Direction::new(rfmlab::common::Axis::Y, -1);
    let e = check_level(&d, None, None).unwrap_err();
    assert!(
        e.message.contains("duplicate") && e.dataset == Some(2),
        "{e}"
    );
    // non-finite value, grid not increasing, mixed grid length
    let mut d = level();
    d.channels[0].values[1] = C64::new(f64::NAN, 0.0);
    assert!(check_level(&d, None, None)
        .unwrap_err()
        .message
        .contains("non-finite"));
    let mut d = level();
    d.freq_hz[2] = 2.0;
    assert!(check_level(&d, None, None)
        .unwrap_err()
        .message
        .contains("strictly increasing"));
    let mut d = level();
    d.channels[1].values.pop();
    assert!(check_level(&d, None, None)
        .unwrap_err()
        .message
        .contains("one grid per level"));
}

#[test]
fn convert_quantities() {
    let l = level();
    let r = l.convert(Quantity::Receptance);
    let back = r.convert(Quantity::Accelerance);
    for (a, b) in back.channels[0].values.iter().zip(&l.channels[0].values) {
        assert!((a - b).norm() < 1e-12);
    }
    // accelerance = -w^2 receptance at 2 Hz
    let w = 2.0 * std::f64::consts::PI * 2.0;
    assert!((r.channels[0].values[1] * (-w * w) - C64::new(1.0, 0.0)).norm() < 1e-12);
}

/// Two files with different frequency grids read into one level: the error names the second
/// file, its dataset and line, and says what to do.
#[test]
fn mixed_grids_within_a_uff_level_are_an_error() {
    use rfmlab::data::read_uff;
    use rfmlab::data::uff_frf::{frf_set_from_uff_files, UffImportOptions};
    let beam = read_uff(crate::common_data::data("beam/beam_accelerance_3frf.uff")).unwrap();
    let other = read_uff(crate::common_data::data(
        "uff/ufffiles_jl/dataset151_164_58_55.unv",
    ))
    .unwrap();
    let files = vec![(beam, "L1".to_string()), (other, "L1".to_string())];
    let err = frf_set_from_uff_files(&files, &UffImportOptions::default())
        .expect_err("two grids in one level")
        .to_string();
    assert!(err.contains("dataset151_164_58_55.unv"), "{err}");
    assert!(err.contains("dataset 2"), "{err}");
    assert!(err.contains("line"), "{err}");
    assert!(err.contains("mixed grids within level L1"), "{err}");
}

/// Dataset 164 (inch, pound-force) scales an FRF to SI: value x force factor / length factor.
#[test]
fn dataset_164_unit_factors_convert_frfs_to_si() {
    use rfmlab::data::read_uff;
    use rfmlab::data::uff_frf::{frf_set_from_uff_files, UffImportOptions};
    let f = read_uff(crate::common_data::data(
        "uff/ufffiles_jl/dataset151_164_58_55.unv",
    ))
    .unwrap();
    let u = f.units.clone().expect("dataset 164");
    assert!(
        (u.length - 39.37007874015748).abs() < 1e-9 && (u.force - 0.2248089430997105).abs() < 1e-12
    );
    let raw = f.datasets[0].values.to_complex();
    let set = frf_set_from_uff_files(&[(f, String::new())], &UffImportOptions::default()).unwrap();
    let ch = &set.levels[0].channels[0];
    assert_eq!(ch.values.len(), raw.len());
    let factor = 0.2248089430997105 / 39.37007874015748;
    for (a, b) in ch.values.iter().zip(&raw) {
        assert!(
            (a - b * factor).norm() <= 1e-12 * (b * factor).norm().max(1e-300),
            "{a} vs {b}"
        );
    }
}
