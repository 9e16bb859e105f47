//! The material study's tables: `steps`, `parameters`, `residuals`, `kk` (module doc of
//! [`super`] lists their columns).

use crate::material_fit::{Candidate, LoopResult};
use crate::output::{OutputError, Table};
use crate::study::material::MaterialStudy;

pub(super) fn tables(study: &MaterialStudy, r: &LoopResult) -> Result<Vec<Table>, OutputError> {
    let cs = &r.candidates;
    let on_path: Vec<bool> = (0..cs.len()).map(|i| r.path.contains(&i)).collect();
    let f = |g: &dyn Fn(&Candidate) -> f64| cs.iter().map(g).collect::<Vec<f64>>();
    let mut steps = Table::new("steps");
    steps
        .push_i64("candidate", "", (0..cs.len() as i64).collect())?
        .push_i64("step", "", cs.iter().map(|c| c.step as i64).collect())?
        .push_str("proposal", cs.iter().map(|c| c.proposal.clone()).collect())?
        .push_str("law", cs.iter().map(|c| c.law.label()).collect())?
        .push_i64(
            "n_params",
            "",
            cs.iter().map(|c| c.n_params() as i64).collect(),
        )?
        .push_bool("accepted", cs.iter().map(|c| c.accepted).collect())?
        .push_bool("on_path", on_path.clone())?
        .push_f64("log_evidence", "nat", f(&|c| c.log_evidence))?
        .push_f64("evidence_gain", "nat", f(&|c| c.evidence_gain))?
        .push_f64("log_likelihood", "nat", f(&|c| c.log_likelihood))?
        .push_f64("rms_log10_storage", "1", f(&|c| c.rms_log10_storage))?
        .push_f64("rms_log10_loss", "1", f(&|c| c.rms_log10_loss))?
        .push_f64("rms_log10_sum", "1", f(&|c| c.rms_log10_sum()))?
        .push_f64("sigma_storage", "1", f(&|c| c.map[c.map.len() - 2]))?
        .push_f64("sigma_loss", "1", f(&|c| c.map[c.map.len() - 1]))?
        .push_f64("runs_z_storage", "1", f(&|c| c.stats_storage.runs_z))?
        .push_f64("runs_p_storage", "1", f(&|c| c.stats_storage.runs_p))?
        .push_f64("runs_z_loss", "1", f(&|c| c.stats_loss.runs_z))?
        .push_f64("runs_p_loss", "1", f(&|c| c.stats_loss.runs_p))?
        .push_f64("chi2_norm_storage", "1", f(&|c| c.stats_storage.chi2_norm))?
        .push_f64("chi2_norm_loss", "1", f(&|c| c.stats_loss.chi2_norm))?
        .push_f64(
            "scatter_log10_storage",
            "1",
            f(&|c| c.stats_storage.scatter_sd),
        )?
        .push_f64("scatter_log10_loss", "1", f(&|c| c.stats_loss.scatter_sd))?
        .push_str(
            "verdict_storage",
            cs.iter()
                .map(|c| c.stats_storage.verdict().to_string())
                .collect(),
        )?
        .push_str(
            "verdict_loss",
            cs.iter()
                .map(|c| c.stats_loss.verdict().to_string())
                .collect(),
        )?
        .push_bool(
            "positive_definite",
            cs.iter().map(|c| c.positive_definite).collect(),
        )?
        .push_f64("causal_floor_ratio", "1", f(&|c| c.causal_floor_ratio))?;
    let mut params = Table::new("parameters");
    let (mut ci, mut law, mut name, mut unit, mut val, mut sd, mut op) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    for (i, c) in cs.iter().enumerate() {
        let mut units = c.law.param_units();
        units.extend(["1".to_string(), "1".to_string()]);
        for k in 0..c.map.len() {
            ci.push(i as i64);
            law.push(c.law.label());
            name.push(c.names[k].clone());
            unit.push(units[k].clone());
            val.push(c.map[k]);
            sd.push(c.sd[k]);
            op.push(on_path[i]);
        }
    }
    params
        .push_i64("candidate", "", ci)?
        .push_str("law", law)?
        .push_str("param", name)?
        .push_str("unit", unit)?
        .push_f64("value", "SI (see unit)", val)?
        .push_f64("sd", "SI (see unit)", sd)?
        .push_bool("on_path", op)?;
    let c = &study.curve;
    let mut res = Table::new("residuals");
    let (mut pi, mut lw, mut fr, mut s, mut l, mut ms, mut ml, mut rs, mut rl) = (
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
    );
    for (k, &i) in r.path.iter().enumerate() {
        let cand = &cs[i];
        for j in 0..c.len() {
            pi.push(k as i64);
            lw.push(cand.law.label());
            fr.push(c.freq_hz[j]);
            s.push(c.storage_pa[j]);
            l.push(c.loss_pa[j]);
            ms.push(cand.model_storage_pa[j]);
            ml.push(cand.model_loss_pa[j]);
            rs.push(cand.res_log10_storage[j]);
            rl.push(cand.res_log10_loss[j]);
        }
    }
    res.push_i64("path_index", "", pi)?
        .push_str("law", lw)?
        .push_f64("freq_hz", "Hz", fr)?
        .push_f64("storage_pa", "Pa", s)?
        .push_f64("loss_pa", "Pa", l)?
        .push_f64("model_storage_pa", "Pa", ms)?
        .push_f64("model_loss_pa", "Pa", ml)?
        .push_f64("res_log10_storage", "1", rs)?
        .push_f64("res_log10_loss", "1", rl)?;
    let k = &r.kk;
    let mut kk = Table::new("kk");
    kk.push_f64("freq_hz", "Hz", c.freq_hz.clone())?
        .push_f64("storage_pa", "Pa", c.storage_pa.clone())?
        .push_f64("loss_pa", "Pa", c.loss_pa.clone())?
        .push_f64("loss_from_storage_pa", "Pa", k.loss_from_storage_pa.clone())?
        .push_f64("storage_from_loss_pa", "Pa", k.storage_from_loss_pa.clone())?
        .push_f64("causal_storage_pa", "Pa", k.causal_storage_pa.clone())?
        .push_f64("causal_loss_pa", "Pa", k.causal_loss_pa.clone())?
        .push_f64(
            "res_loss_from_storage",
            "1",
            k.res_loss_from_storage.clone(),
        )?
        .push_f64(
            "res_storage_from_loss",
            "1",
            k.res_storage_from_loss.clone(),
        )?
        .push_f64("res_causal_storage", "1", k.res_causal_storage.clone())?
        .push_f64("res_causal_loss", "1", k.res_causal_loss.clone())?
        .push_bool("non_causal", k.non_causal.clone())?;
    Ok(vec![steps, params, res, kk])
}
