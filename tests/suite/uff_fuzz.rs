//! Fuzz the UFF reader with mutated real files (byte flips, truncations, inserted garbage):
//! parsing never panics. The seeds are whole files (ASCII and 58b, even and uneven, a 164
//! unit-factor dataset, Latin-1 labels) that parse cleanly before mutation, so the mutations
//! reach every record of both encodings. Cases: RFMLAB_FUZZ_CASES (default 2000), e.g.
//! `RFMLAB_FUZZ_CASES=200000 cargo test --release --test suite uff_fuzz::`.

use crate::common_data::*;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use rfmlab::data::uff58::parse_uff;

fn corpus() -> Vec<Vec<u8>> {
    [
        "uff/ufffiles_jl/dataset58_case3_binary.unv",
        "uff/ufffiles_jl/dataset58_case8_binary.unv",
        "uff/ufffiles_jl/dataset58_case6_ascii.unv",
        "uff/ufffiles_jl/dataset58_nospacing.uff",
        "uff/ufffiles_jl/dataset58_ufb.ufb",
        "uff/ufffiles_jl/dataset151_164_58_55.unv",
        "uff/pyuff_testdata/non_ascii_header.uff",
        "uff/pyuff_testdata/sample_dataset58_psd.uff",
    ]
    .iter()
    .map(|p| std::fs::read(data(p)).unwrap())
    .collect()
}

#[test]
fn fuzz_seeds_parse_before_mutation() {
    for (i, b) in corpus().iter().enumerate() {
        let parsed = parse_uff(b, "seed");
        assert!(parsed.is_ok(), "seed {i}: {:?}", parsed.err());
    }
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Truncate(usize),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Mutation::Flip(p, b)),
        any::<usize>().prop_map(Mutation::Truncate),
        (
            any::<usize>(),
            prop_oneof![
                proptest::collection::vec(any::<u8>(), 1..20),
                Just(b"\n    -1\n".to_vec()),
                Just(b"\n    58b     1     2          11   999999999\n".to_vec()),
                Just(b"        99999999\n".to_vec()),
                Just(b"1.0E+99999 nan inf".to_vec()),
            ]
        )
            .prop_map(|(p, g)| Mutation::Insert(p, g)),
        (any::<usize>(), 1usize..200).prop_map(|(p, n)| Mutation::Delete(p, n)),
    ]
}

#[test]
fn mutated_real_files_never_panic() {
    let cases: u32 = std::env::var("RFMLAB_FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2000);
    let corpus = corpus();
    let mut runner = TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    });
    runner
        .run(
            &(0..corpus.len(), proptest::collection::vec(mutation(), 1..6)),
            |(i, muts)| {
                let mut b = corpus[i].clone();
                for m in muts {
                    let n = b.len().max(1);
                    match m {
                        Mutation::Flip(p, v) => {
                            if !b.is_empty() {
                                b[p % n] = v;
                            }
                        }
                        Mutation::Truncate(p) => b.truncate(p % n),
                        Mutation::Insert(p, g) => {
                            let at = p % (b.len() + 1);
                            b.splice(at..at, g);
                        }
                        Mutation::Delete(p, k) => {
                            let at = p % n;
                            let end = (at + k).min(b.len());
                            if at < end {
                                b.drain(at..end);
                            }
                        }
                    }
                }
                let _ = parse_uff(&b, "fuzz");
                Ok(())
            },
        )
        .unwrap();
}
