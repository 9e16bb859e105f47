//! Whether a fit is a result: [`FitStatus`], with the typed reasons ([`FlagReason`]) a fit is
//! flagged for. A fit is a result only when the model can represent it and the search ended
//! by its own stopping rule:
//!
//! * every modulus E*(w) the fit implies on the data's lines lies inside the modulus box the
//!   reduced model is certified over ([`crate::rom::ModulusRange`]; the full model has no box);
//! * no parameter sits on the edge of its admissible range or of its prior's support;
//! * the search stopped before its iteration limit and did not diverge;
//! * every parameter is finite and, for a modulus (unit Pa), inside
//!   [`PHYSICAL_MODULUS_PA`].
//!
//! The status travels with the typed results (the global RFM's [`crate::identify::GlobalResult`],
//! the MAP of each posterior) into the tables (`status`, `status_reason`), the console, the
//! first lines of report.md and the exit code of `rfmlab run`.

use crate::common::C64;
use crate::rom::ModulusRange;

/// Moduli (parameters in Pa) outside this range (Pa) are no adhesive's: below 1 kPa (softer
/// than a gel) or above 1 TPa (stiffer than diamond).
pub const PHYSICAL_MODULUS_PA: (f64, f64) = (1e3, 1e12);

/// A parameter within this fraction of its range's width (of its log range for a positive
/// range with both ends finite) from a finite end sits on the edge.
pub const EDGE_FRACTION: f64 = 1e-6;

/// Relative slack of the certified box: E' or E'' outside the box by less than this fraction
/// of the bound is still inside (rounding of the box's own ends).
pub const BOX_SLACK: f64 = 1e-9;

/// Why a fit is not reported as a result.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum FlagReason {
    /// E*(w) of the fit leaves the modulus box the reduced model is certified over: the model's
    /// FRFs there are extrapolated, not certified. The worst line is named.
    OutsideCertifiedBox {
        freq_hz: f64,
        storage_pa: f64,
        loss_pa: f64,
        box_storage_pa: (f64, f64),
        box_loss_pa: (f64, f64),
    },
    /// A parameter sits on the edge of its admissible range or of its prior's support.
    AtRangeEdge {
        parameter: String,
        value: f64,
        edge: f64,
    },
    /// The search used its whole iteration budget without meeting its tolerance.
    IterationLimit { iterations: usize, limit: usize },
    /// The search diverged (residual growing without bound, or no admissible step).
    Diverged,
    /// A parameter is outside its physical range ([`PHYSICAL_MODULUS_PA`] for a modulus).
    Unphysical {
        parameter: String,
        value: f64,
        unit: String,
        lo: f64,
        hi: f64,
    },
    /// A parameter or the fit's modulus is not a finite number.
    NotFinite { parameter: String },
}

impl FlagReason {
    /// A short machine name of the reason (`outside_certified_box`, `at_range_edge`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            FlagReason::OutsideCertifiedBox { .. } => "outside_certified_box",
            FlagReason::AtRangeEdge { .. } => "at_range_edge",
            FlagReason::IterationLimit { .. } => "iteration_limit",
            FlagReason::Diverged => "diverged",
            FlagReason::Unphysical { .. } => "unphysical",
            FlagReason::NotFinite { .. } => "not_finite",
        }
    }
}

impl std::fmt::Display for FlagReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FlagReason::OutsideCertifiedBox {
                freq_hz,
                storage_pa,
                loss_pa,
                box_storage_pa,
                box_loss_pa,
            } => write!(
                f,
                "the modulus leaves the reduced model's certified box (at {freq_hz:.1} Hz E' = {storage_pa:.3e} Pa, E'' = {loss_pa:.3e} Pa; the box is E' {:.3e}..{:.3e} Pa, E'' {:.3e}..{:.3e} Pa): check the study against the data (geometry, initial values) or run with engine = \"full\"",
                box_storage_pa.0, box_storage_pa.1, box_loss_pa.0, box_loss_pa.1
            ),
            FlagReason::AtRangeEdge {
                parameter,
                value,
                edge,
            } => write!(
                f,
                "{parameter} = {value:.4e} sits on the edge {edge:.4e} of its range: the data push it out of the range allowed"
            ),
            FlagReason::IterationLimit { iterations, limit } => write!(
                f,
                "stopped at the iteration limit ({iterations} of max_iterations = {limit}) without meeting the tolerance"
            ),
            FlagReason::Diverged => f.write_str("the iteration diverged"),
            FlagReason::Unphysical {
                parameter,
                value,
                unit,
                lo,
                hi,
            } => write!(
                f,
                "{parameter} = {value:.4e} {unit} is outside its physical range {lo:.0e}..{hi:.0e} {unit}"
            ),
            FlagReason::NotFinite { parameter } => write!(f, "{parameter} is not a finite number"),
        }
    }
}

/// Whether a fit is a result.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
#[serde(tag = "status", content = "reasons", rename_all = "snake_case")]
pub enum FitStatus {
    /// None of the flags of [`FlagReason`] applies: the fit is a result.
    #[default]
    Converged,
    /// At least one reason (never empty) why the fit is not a result.
    Flagged(Vec<FlagReason>),
}

impl FitStatus {
    /// [`FitStatus::Converged`] when `reasons` is empty, else flagged with them.
    pub fn from_reasons(reasons: Vec<FlagReason>) -> FitStatus {
        if reasons.is_empty() {
            FitStatus::Converged
        } else {
            FitStatus::Flagged(reasons)
        }
    }
    pub fn is_flagged(&self) -> bool {
        matches!(self, FitStatus::Flagged(_))
    }
    /// The reasons (empty when converged).
    pub fn reasons(&self) -> &[FlagReason] {
        match self {
            FitStatus::Converged => &[],
            FitStatus::Flagged(r) => r,
        }
    }
    /// `converged` or `flagged` (the tables' `status` column).
    pub fn label(&self) -> &'static str {
        match self {
            FitStatus::Converged => "converged",
            FitStatus::Flagged(_) => "flagged",
        }
    }
    /// The reasons in plain words, `; `-separated (the tables' `status_reason` column; empty
    /// when converged).
    pub fn reason_text(&self) -> String {
        self.reasons()
            .iter()
            .map(|r| r.to_string())
            .collect::<Vec<_>>()
            .join("; ")
    }
}

impl std::fmt::Display for FitStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitStatus::Converged => f.write_str("converged"),
            FitStatus::Flagged(_) => write!(f, "FLAGGED: {}", self.reason_text()),
        }
    }
}

/// One parameter of a fit as the checks see it.
#[derive(Clone, Copy, Debug)]
pub struct ParamCheck<'a> {
    pub name: &'a str,
    /// SI unit (`Pa` makes it a modulus, checked against [`PHYSICAL_MODULUS_PA`]).
    pub unit: &'a str,
    pub value: f64,
    /// The admissible range, or the prior's support (ends may be infinite).
    pub range: (f64, f64),
}

/// The flags of parameter values: not finite, on a finite edge of their range, outside the
/// physical range of a modulus.
pub fn parameter_flags(params: &[ParamCheck<'_>]) -> Vec<FlagReason> {
    let mut out = Vec::new();
    for p in params {
        if !p.value.is_finite() {
            out.push(FlagReason::NotFinite {
                parameter: p.name.to_string(),
            });
            continue;
        }
        if let Some(edge) = on_edge(p.value, p.range) {
            out.push(FlagReason::AtRangeEdge {
                parameter: p.name.to_string(),
                value: p.value,
                edge,
            });
        }
        if p.unit == "Pa" {
            let (lo, hi) = PHYSICAL_MODULUS_PA;
            if !(p.value.abs() >= lo && p.value.abs() <= hi) {
                out.push(FlagReason::Unphysical {
                    parameter: p.name.to_string(),
                    value: p.value,
                    unit: p.unit.to_string(),
                    lo,
                    hi,
                });
            }
        }
    }
    out
}

/// The finite end of `range` that `v` sits on ([`EDGE_FRACTION`]), if any. A range with an
/// infinite end has no width to measure closeness by: only its finite end with a nonzero
/// value counts, relative to that value (the end 0 of a positive parameter is never reached
/// by a log-parameter search: a vanishing modulus shows in the physical range instead).
fn on_edge(v: f64, (lo, hi): (f64, f64)) -> Option<f64> {
    let near = |end: f64, scale: f64| (v - end).abs() <= EDGE_FRACTION * scale;
    if lo.is_finite() && hi.is_finite() {
        if lo > 0.0 && v > 0.0 {
            let w = (hi / lo).ln();
            let (a, b) = ((v / lo).ln(), (hi / v).ln());
            return if a <= EDGE_FRACTION * w {
                Some(lo)
            } else if b <= EDGE_FRACTION * w {
                Some(hi)
            } else {
                None
            };
        }
        let w = hi - lo;
        return if near(lo, w) {
            Some(lo)
        } else if near(hi, w) {
            Some(hi)
        } else {
            None
        };
    }
    if lo.is_finite() && lo != 0.0 && near(lo, lo.abs()) {
        return Some(lo);
    }
    if hi.is_finite() && hi != 0.0 && near(hi, hi.abs()) {
        return Some(hi);
    }
    None
}

/// The flag of a modulus curve (`(freq_hz, E*)` per line) against the certified `range`: the
/// line that leaves it by the largest factor, or a non-finite modulus.
pub fn box_flag(modulus: &[(f64, C64)], range: &ModulusRange) -> Option<FlagReason> {
    let factor = |x: f64, (lo, hi): (f64, f64)| {
        if x < lo * (1.0 - BOX_SLACK) {
            if x > 0.0 {
                lo / x
            } else {
                f64::INFINITY
            }
        } else if x > hi * (1.0 + BOX_SLACK) {
            x / hi
        } else {
            1.0
        }
    };
    let mut worst: Option<(f64, f64, C64)> = None;
    for &(f, e) in modulus {
        if !(e.re.is_finite() && e.im.is_finite()) {
            return Some(FlagReason::NotFinite {
                parameter: format!("E*({f:.1} Hz)"),
            });
        }
        let k = factor(e.re, range.e_storage_pa).max(factor(e.im, range.e_loss_pa));
        if k > 1.0 && worst.is_none_or(|(w, _, _)| k > w) {
            worst = Some((k, f, e));
        }
    }
    worst.map(|(_, f, e)| FlagReason::OutsideCertifiedBox {
        freq_hz: f,
        storage_pa: e.re,
        loss_pa: e.im,
        box_storage_pa: range.e_storage_pa,
        box_loss_pa: range.e_loss_pa,
    })
}

/// The status of a global RFM run: its stop reason against `max_iterations`, its parameters
/// (`units` and `bounds` of the law) and its modulus on the lines `freq_hz` against the
/// certified box (`None`: an engine without one).
pub fn rfm_status(
    result: &super::RfmResult,
    units: &[String],
    bounds: &[(f64, f64)],
    freq_hz: &[f64],
    certified: Option<&ModulusRange>,
    max_iterations: usize,
) -> FitStatus {
    let mut reasons = Vec::new();
    match result.stop_reason {
        super::StopReason::MaxIterations => reasons.push(FlagReason::IterationLimit {
            iterations: result.iterations,
            limit: max_iterations,
        }),
        super::StopReason::Diverged => reasons.push(FlagReason::Diverged),
        super::StopReason::Converged | super::StopReason::RankDeficient => {}
    }
    let checks: Vec<ParamCheck<'_>> = result
        .params
        .iter()
        .enumerate()
        .map(|(k, &value)| ParamCheck {
            name: result.param_names.get(k).map(String::as_str).unwrap_or("?"),
            unit: units.get(k).map(String::as_str).unwrap_or(""),
            value,
            range: bounds
                .get(k)
                .copied()
                .unwrap_or((f64::NEG_INFINITY, f64::INFINITY)),
        })
        .collect();
    reasons.extend(parameter_flags(&checks));
    if let Some(range) = certified {
        let curve: Vec<(f64, C64)> = freq_hz
            .iter()
            .copied()
            .zip(result.modulus.iter().copied())
            .collect();
        reasons.extend(box_flag(&curve, range));
    }
    FitStatus::from_reasons(reasons)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p<'a>(name: &'a str, unit: &'a str, value: f64, range: (f64, f64)) -> ParamCheck<'a> {
        ParamCheck {
            name,
            unit,
            value,
            range,
        }
    }

    #[test]
    fn moduli_outside_the_physical_range_are_flagged() {
        let pos = (0.0, f64::INFINITY);
        let f = parameter_flags(&[
            p("E0", "Pa", 1.2e-4, pos),
            p("E1", "Pa", 1.3e18, pos),
            p("h", "Pa", 1.5e6, pos),
            p("eta1", "Pa s", 1e-3, pos),
        ]);
        let kinds: Vec<&str> = f.iter().map(FlagReason::kind).collect();
        assert_eq!(kinds, ["unphysical", "unphysical"]);
    }

    #[test]
    fn edges_of_finite_ranges_and_non_finite_values_are_flagged() {
        let f = parameter_flags(&[
            p("alpha", "1", 1.0 - 1e-9, (0.0, 1.0)),
            p("beta", "1", 0.5, (0.0, 1.0)),
            p("E", "Pa", 1e4 * (1.0 + 1e-8), (1e4, 1e8)),
            p("x", "1", f64::NAN, (0.0, 1.0)),
        ]);
        assert_eq!(
            f,
            vec![
                FlagReason::AtRangeEdge {
                    parameter: "alpha".into(),
                    value: 1.0 - 1e-9,
                    edge: 1.0
                },
                FlagReason::AtRangeEdge {
                    parameter: "E".into(),
                    value: 1e4 * (1.0 + 1e-8),
                    edge: 1e4
                },
                FlagReason::NotFinite {
                    parameter: "x".into()
                },
            ]
        );
    }

    #[test]
    fn the_worst_line_outside_the_box_is_named() {
        let range = ModulusRange::default();
        let inside = [(10.0, C64::new(5e6, 1e6)), (20.0, C64::new(5e7, 2e7))];
        assert_eq!(box_flag(&inside, &range), None);
        let outside = [
            (10.0, C64::new(1e-4, 1e6)),
            (20.0, C64::new(1e5, 1e6)),
            (30.0, C64::new(5e6, 1e6)),
        ];
        match box_flag(&outside, &range) {
            Some(FlagReason::OutsideCertifiedBox {
                freq_hz,
                storage_pa,
                ..
            }) => {
                assert_eq!(freq_hz, 10.0);
                assert_eq!(storage_pa, 1e-4);
            }
            other => panic!("expected a box flag, got {other:?}"),
        }
        let status = FitStatus::from_reasons(box_flag(&outside, &range).into_iter().collect());
        assert!(status.is_flagged());
        assert_eq!(status.label(), "flagged");
        assert!(status.reason_text().contains("certified box"));
        assert_eq!(FitStatus::from_reasons(Vec::new()), FitStatus::Converged);
    }
}
