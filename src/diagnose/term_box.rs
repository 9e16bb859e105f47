//! The term ROM's modulus box ([`term_modulus_range`]; the rule in `terms.rs`'s module doc),
//! how far a law's modulus leaves it ([`outside_box`]), and the band of the levels' lines
//! ([`band_of`]).

use super::params::TermParams;

/// The term ROM's modulus box (see `terms.rs`'s module doc): E*(w) of the initial values of
/// the box's models (`p.box_models`: the `[inference]` models) over `band_hz`, widened by 2
/// either way. Falls back to the effect-free ROM's box of every model when none gives a
/// modulus.
pub fn term_modulus_range(p: &TermParams, band_hz: (f64, f64)) -> crate::rom::ModulusRange {
    let mut r = crate::rom::ModulusRange {
        e_storage_pa: (f64::INFINITY, 0.0),
        e_loss_pa: (f64::INFINITY, 0.0),
    };
    crate::stage::engine::widen_to_initial_moduli(&mut r, &p.box_models, band_hz, 50);
    if r.e_storage_pa.0 < r.e_storage_pa.1 && r.e_loss_pa.0 < r.e_loss_pa.1 {
        r
    } else {
        crate::stage::engine::initial_modulus_range(&p.all_models, band_hz)
    }
}

/// The largest factor by which `law` at `params` leaves `range` on `freq_hz` (1: inside; 2:
/// somewhere twice above the top or half below the bottom of E' or E'').
pub fn outside_box(
    law: &dyn crate::material::ConstitutiveModel,
    params: &[f64],
    freq_hz: &[f64],
    range: &crate::rom::ModulusRange,
) -> f64 {
    let ratio = |x: f64, (lo, hi): (f64, f64)| {
        if x < lo {
            if x > 0.0 {
                lo / x
            } else {
                f64::INFINITY
            }
        } else if x > hi {
            x / hi
        } else {
            1.0
        }
    };
    freq_hz
        .iter()
        .map(|&f| {
            let e = law.modulus(params, std::f64::consts::TAU * f);
            ratio(e.re, range.e_storage_pa).max(ratio(e.im, range.e_loss_pa))
        })
        .fold(1.0, f64::max)
}

pub use crate::stage::data::band_of;
