//! The design criterion and the search over candidate channels.
//!
//! A design's score, per model, level and parameter, is the predicted relative posterior
//! standard deviation `sd(p_i) / p_i` (from the posterior precision prior + sum of the design's
//! channels' information, [`super::information::covariance`]), summarised over the parameter
//! draws by their geometric mean. The criterion is the worst of them (the worst-determined
//! parameter at the worst level); its tie-breaker the sum of their logarithms. The expected
//! information gain is `(ln det A_post - ln det A_prior) / 2` (nats, the Gaussian
//! approximation of the mutual information), averaged over the draws and summed over models
//! and levels.
//!
//! Search: greedy selection on the smooth sum of log sds (from the kept channels, one channel
//! per place: uniaxial sensors), then exchange passes that swap a chosen channel for any other
//! candidate while the worst sd falls (Fedorov's exchange with the minimax criterion).

use std::collections::HashMap;

use super::information::{covariance, prior_logdet, relative_sd, Draw};

/// The information of every candidate channel for one drive point and one set of sensor
/// masses: `info[model][level][draw][channel]`, and the draws `[model][level][draw]`.
pub struct Infos {
    pub info: Vec<Vec<Vec<Vec<Vec<f64>>>>>,
    pub draws: Vec<Vec<Vec<Draw>>>,
}

/// A design's predicted posterior.
#[derive(Clone, Debug, PartialEq)]
pub struct Score {
    /// `[model][level][param]`: geometric mean over the draws of the relative sd.
    pub rel_sd: Vec<Vec<Vec<f64>>>,
    /// The largest of `rel_sd`.
    pub worst: f64,
    /// Sum of `ln rel_sd` (the greedy step's criterion).
    pub sum_log: f64,
    /// Expected information gain (nats).
    pub info_gain: f64,
}

impl Score {
    fn better_than(&self, o: &Score) -> bool {
        self.worst < o.worst * (1.0 - 1e-9)
            || (self.worst <= o.worst * (1.0 + 1e-9) && self.sum_log < o.sum_log - 1e-9)
    }
}

/// The score of the channels `chosen` (indices into the candidate channels).
pub fn score(infos: &Infos, chosen: &[usize]) -> Score {
    let mut rel_sd = Vec::new();
    let mut gain = 0.0;
    for (m, levels) in infos.draws.iter().enumerate() {
        let mut per_model = Vec::new();
        for (l, draws) in levels.iter().enumerate() {
            let np = draws.first().map_or(0, |d| d.p.len());
            let mut lv = vec![0.0; np];
            for (s, draw) in draws.iter().enumerate() {
                let fs: Vec<&[f64]> = chosen
                    .iter()
                    .map(|&c| infos.info[m][l][s][c].as_slice())
                    .collect();
                match covariance(draw, &fs) {
                    Some((cov, logdet)) => {
                        for (i, v) in lv.iter_mut().enumerate() {
                            *v += relative_sd(draw, &cov, i).max(1e-300).ln();
                        }
                        gain += 0.5 * (logdet - prior_logdet(draw)) / draws.len() as f64;
                    }
                    None => lv.iter_mut().for_each(|v| *v += f64::INFINITY),
                }
            }
            let ns = draws.len().max(1) as f64;
            per_model.push(lv.into_iter().map(|v| (v / ns).exp()).collect());
        }
        rel_sd.push(per_model);
    }
    let all = rel_sd.iter().flatten().flatten().copied();
    let worst = all.clone().fold(0.0, f64::max);
    let sum_log = all.map(|v: f64| v.ln()).sum();
    Score {
        rel_sd,
        worst,
        sum_log,
        info_gain: gain,
    }
}

/// What the search may choose.
pub struct SearchParams<'a> {
    /// Channels per design, kept ones included.
    pub size: usize,
    /// Channels every design holds.
    pub keep: &'a [usize],
    /// The place of each candidate channel (one sensor per place).
    pub place_of: &'a [usize],
}

/// Greedy selection then exchange; returns the chosen channels (kept first) and every design
/// evaluated on the way with its score (for the ranked table).
pub fn search(infos: &Infos, p: &SearchParams<'_>) -> (Vec<usize>, Vec<(Vec<usize>, Score)>) {
    let n = p.place_of.len();
    let mut seen: HashMap<Vec<usize>, Score> = HashMap::new();
    let record = |d: &[usize], s: &Score, seen: &mut HashMap<Vec<usize>, Score>| {
        let mut key = d.to_vec();
        key.sort_unstable();
        seen.entry(key).or_insert_with(|| s.clone());
    };
    let free = |chosen: &[usize], c: usize| {
        !chosen.contains(&c) && !chosen.iter().any(|&o| p.place_of[o] == p.place_of[c])
    };
    let mut chosen: Vec<usize> = p.keep.to_vec();
    while chosen.len() < p.size.min(n) {
        let mut best: Option<(usize, Score)> = None;
        for c in 0..n {
            if !free(&chosen, c) {
                continue;
            }
            let mut d = chosen.clone();
            d.push(c);
            let s = score(infos, &d);
            let better = match &best {
                None => true,
                Some((_, b)) => {
                    s.sum_log < b.sum_log - 1e-12
                        || (s.sum_log <= b.sum_log + 1e-12 && s.worst < b.worst)
                }
            };
            if better {
                best = Some((c, s));
            }
        }
        let Some((c, s)) = best else { break };
        chosen.push(c);
        record(&chosen, &s, &mut seen);
    }
    let mut current = score(infos, &chosen);
    for _round in 0..10 {
        let mut improved = false;
        for slot in p.keep.len()..chosen.len() {
            let mut best: Option<(usize, Score)> = None;
            for c in 0..n {
                let mut others = chosen.clone();
                others.remove(slot);
                if !free(&others, c) || chosen[slot] == c {
                    continue;
                }
                others.insert(slot, c);
                let s = score(infos, &others);
                record(&others, &s, &mut seen);
                let cand_better = match &best {
                    None => s.better_than(&current),
                    Some((_, b)) => s.better_than(b),
                };
                if cand_better {
                    best = Some((c, s));
                }
            }
            if let Some((c, s)) = best {
                chosen[slot] = c;
                current = s;
                improved = true;
            }
        }
        if !improved {
            break;
        }
    }
    record(&chosen, &current, &mut seen);
    let mut all: Vec<(Vec<usize>, Score)> = seen.into_iter().collect();
    all.sort_by(|a, b| {
        a.1.worst
            .total_cmp(&b.1.worst)
            .then(a.1.sum_log.total_cmp(&b.1.sum_log))
            .then(a.0.cmp(&b.0))
    });
    (chosen, all)
}
