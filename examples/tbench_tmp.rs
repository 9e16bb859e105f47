use rfmlab::common::C64;
use rfmlab::frf::{FrfEngine, TermCoef};
use std::time::Instant;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let txt = std::fs::read_to_string(&path).unwrap();
    let v: serde_json::Value = serde_json::from_str(&txt).unwrap();
    let key = v["key"].as_str().unwrap().to_string();
    let (rom, _c) = rfmlab::rom::cache::load_terms(std::path::Path::new(&path), &key).unwrap();
    println!("n_r {}", rom.basis_size());
    let n = 500;
    let w: Vec<f64> = (1..=n).map(|k| std::f64::consts::TAU * k as f64).collect();
    let e: Vec<C64> = w
        .iter()
        .map(|&w| C64::new(7.2e6 + 1e3 * w, 1.1e6 + 5e3 * w))
        .collect();
    let terms = [TermCoef {
        index: 0,
        value: 3.3e-11,
        offset: C64::new(1.0, 0.0),
        per_modulus: 0.0,
    }];
    for d in [false, true] {
        let t = Instant::now();
        for _ in 0..3 {
            let _ = rom.sweep_terms(&w, &e, &terms, d).unwrap();
        }
        println!(
            "derivs {d}: {:.3} s per sweep",
            t.elapsed().as_secs_f64() / 3.0
        );
    }
}
