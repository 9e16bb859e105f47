//! CSV read/write: exact round trip, the bundled wide-layout files, errors with line numbers.

use crate::common_data::*;

use rfmlab::common::Direction;
use rfmlab::data::csv::{parse_csv, read_csv, write_csv, CsvOptions};
use rfmlab::data::uff_frf::{frf_set_from_uff, UffImportOptions};
use rfmlab::data::Quantity;

#[test]
fn beam_csv_matches_beam_uff() {
    let opts = CsvOptions {
        quantity: Some(Quantity::Accelerance),
        level: "beam".into(),
        wide_direction: Direction::PX,
    };
    let c = read_csv(data("beam/beam_accelerance_3frf.csv"), &opts).unwrap();
    let u = frf_set_from_uff(
        &[(data("beam/beam_accelerance_3frf.uff"), "beam".to_string())],
        &UffImportOptions::default(),
    )
    .unwrap();
    let (c, u) = (&c.levels[0], &u.levels[0]);
    assert_eq!(c.freq_hz.len(), 1001);
    assert_eq!(c.channels.len(), 3);
    for (cc, uc) in c.channels.iter().zip(&u.channels) {
        assert_eq!(
            (cc.response_id, cc.reference_id),
            (uc.response_id, uc.reference_id)
        );
        // the CSV has 10 significant digits
        for (a, b) in cc.values.iter().zip(&uc.values) {
            assert!((a - b).norm() <= 1e-9 * b.norm().max(1e-12), "{a} vs {b}");
        }
    }
    // impact: one FRF with a shared coherence column
    let i = read_csv(data("impact/impact_H1_coh.csv"), &opts).unwrap();
    assert!(i.levels[0].channels[0].coherence.is_some());
}

#[test]
fn rfmlab_layout_round_trip_is_exact() {
    let opts = CsvOptions {
        quantity: Some(Quantity::Accelerance),
        ..Default::default()
    };
    let mut set = read_csv(data("impact/impact_H1_coh.csv"), &opts).unwrap();
    set.levels[0].force_rms_n = Some(3.3);
    set.levels[0].n_averages = Some(200);
    let mut l2 = set.levels[0].clone();
    l2.name = "L2".into();
    l2.quantity = Quantity::Mobility;
    l2.channels[0].coherence = None;
    set.levels.push(l2);
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("set.csv");
    write_csv(&set, &p).unwrap();
    let mut back = read_csv(&p, &CsvOptions::default()).unwrap();
    for l in back.levels.iter_mut() {
        for c in l.channels.iter_mut() {
            c.source = None;
        }
    }
    for l in set.levels.iter_mut() {
        for c in l.channels.iter_mut() {
            c.source = None;
        }
    }
    assert_eq!(back, set);
}

#[test]
fn csv_errors_name_file_and_line() {
    let h = "# level=L1 quantity=mobility\nlevel,response_id,response_dir,reference_id,reference_dir,freq_hz,re,im,coherence\n";
    let e = parse_csv(
        &format!("{h}L1,1,+y,2,+y,1,0.5,x,\n"),
        "a.csv",
        &CsvOptions::default(),
    )
    .unwrap_err();
    assert_eq!((e.file.as_str(), e.line), ("a.csv", Some(3)));
    let e = parse_csv(
        &format!("{h}L1,1,+w,2,+y,1,0.5,0.1,\n"),
        "a.csv",
        &CsvOptions::default(),
    )
    .unwrap_err();
    assert!(e.message.contains("direction"), "{e}");
    let e = parse_csv(
        &format!("{h}L1,1,+y,2,+y,1,0.5,0.1,\nL1,1,+y,2,+y,2,0.5,0.1,\nL1,3,+y,2,+y,1,0.5,0.1,\n"),
        "a.csv",
        &CsvOptions::default(),
    )
    .unwrap_err();
    assert!(
        e.message.contains("mixed grids") && e.line == Some(5),
        "{e}"
    );
    let e = parse_csv("level,response_id,response_dir,reference_id,reference_dir,freq_hz,re,im,coherence\nL1,1,+y,2,+y,1,0.5,0.1,\n", "a.csv", &CsvOptions::default()).unwrap_err();
    assert!(e.message.contains("quantity"), "{e}");
}
