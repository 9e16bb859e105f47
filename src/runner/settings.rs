//! The study's settings as the algorithms' parameter structs.

use crate::rfm::RfmParams;
use crate::study::Study;

/// The RFM settings of a study.
pub fn rfm_params(study: &Study) -> RfmParams {
    RfmParams {
        tol_rel_change: study.solver.tolerance,
        max_iterations: study.solver.max_iterations,
        rcond: study.solver.svd_rtol,
        ..RfmParams::default()
    }
}
