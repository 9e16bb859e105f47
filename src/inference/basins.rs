//! Basins of attraction of a local search: end points of many starts clustered into basins.
//!
//! End points closer than `tol` in every coordinate (max norm, in the coordinates the caller
//! gives, e.g. `ln p`: `tol = 1e-3` is 0.1 % in every parameter) to a basin's best point
//! belong to that basin. Points are visited in order of their objective (lowest first), so
//! basin 0 holds the best end point (the global optimum found) and each basin is
//! represented by its best point. Failed starts (no end point or a non-finite objective)
//! belong to no basin.

/// One basin.
#[derive(Clone, Debug, PartialEq)]
pub struct Basin {
    /// 0 = the basin of the lowest objective.
    pub id: usize,
    /// Its best end point (the representative).
    pub point: Vec<f64>,
    pub best_objective: f64,
    /// Starts that ended in it.
    pub count: usize,
}

/// Cluster `ends` (one per start; `None` when the start failed) by their `objective`
/// (lower is better). Returns the basin of each start and the basins.
pub fn cluster(
    ends: &[Option<Vec<f64>>],
    objective: &[f64],
    tol: f64,
) -> (Vec<Option<usize>>, Vec<Basin>) {
    let mut order: Vec<usize> = (0..ends.len())
        .filter(|&i| ends[i].is_some() && objective[i].is_finite())
        .collect();
    order.sort_by(|a, b| objective[*a].total_cmp(&objective[*b]).then(a.cmp(b)));
    let mut basins: Vec<Basin> = Vec::new();
    let mut of = vec![None; ends.len()];
    for i in order {
        let Some(p) = ends[i].as_ref() else { continue };
        let hit = basins.iter().position(|b| {
            b.point.len() == p.len() && b.point.iter().zip(p).all(|(a, c)| (a - c).abs() <= tol)
        });
        let id = match hit {
            Some(k) => k,
            None => {
                basins.push(Basin {
                    id: basins.len(),
                    point: p.clone(),
                    best_objective: objective[i],
                    count: 0,
                });
                basins.len() - 1
            }
        };
        basins[id].count += 1;
        of[i] = Some(id);
    }
    (of, basins)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inference::map::{find_map, MapParams};
    use crate::inference::{DensityError, Posterior};
    use rand::rngs::StdRng;

    #[test]
    fn clusters_by_distance_and_orders_by_objective() {
        let ends = vec![
            Some(vec![1.0, 1.0]),
            Some(vec![0.0, 0.0]),
            None,
            Some(vec![1.0005, 0.9995]),
            Some(vec![0.0002, 0.0]),
            Some(vec![5.0, 5.0]),
        ];
        let obj = vec![2.0, 1.0, f64::INFINITY, 2.1, 1.0000001, f64::NAN];
        let (of, b) = cluster(&ends, &obj, 1e-3);
        assert_eq!(of, vec![Some(1), Some(0), None, Some(1), Some(0), None]);
        assert_eq!(b.len(), 2);
        assert_eq!((b[0].count, b[1].count), (2, 2));
        assert_eq!(b[0].best_objective, 1.0);
        assert_eq!(b[1].point, vec![1.0, 1.0]);
    }

    /// A double well in x: log L = ln(w exp(-|x - a|^2 / 2 s^2) + (1 - w) exp(-|x + a|^2 /
    /// 2 s^2)) with a = (1, 0), under a standard logistic prior per coordinate.
    struct DoubleWell;
    const S: f64 = 0.15;
    const W: f64 = 0.7;
    impl Posterior for DoubleWell {
        fn dim(&self) -> usize {
            2
        }
        fn names(&self) -> Vec<String> {
            vec!["a".into(), "b".into()]
        }
        fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
            let p = crate::inference::prior::Prior::Uniform { lo: 0.0, hi: 1.0 };
            let mut s = 0.0;
            let mut g = grad;
            for (i, xi) in x.iter().enumerate() {
                let (l, d) = p.log_density_x(*xi);
                s += l;
                if let Some(g) = g.as_deref_mut() {
                    g[i] = d;
                }
            }
            s
        }
        fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
            let q = |c: f64| ((x[0] - c).powi(2) + x[1] * x[1]) / (2.0 * S * S);
            let (ea, eb) = (W * (-q(1.0)).exp(), (1.0 - W) * (-q(-1.0)).exp());
            let tot = ea + eb + 1e-300;
            if let Some(g) = grad {
                g[0] = -(ea * (x[0] - 1.0) + eb * (x[0] + 1.0)) / (S * S * tot);
                g[1] = -(ea + eb) * x[1] / (S * S * tot);
            }
            Ok(tot.ln())
        }
        fn sample_prior(&self, _rng: &mut StdRng) -> Vec<f64> {
            vec![0.0, 0.0]
        }
        fn constrained(&self, x: &[f64]) -> Vec<f64> {
            x.to_vec()
        }
    }

    #[test]
    fn double_well_starts_split_into_two_basins_by_side() {
        // 200 space-filling starts over the logistic prior (|x| mostly < 4): the global well
        // at x = +1 collects the starts with x > 0, the other well those with x < 0; away from
        // the wells the likelihood is flat to machine precision, so far starts stay put.
        let params = MapParams {
            n_starts: 200,
            seed: 11,
            ..MapParams::default()
        };
        let r = find_map(&DoubleWell, None, &params, &|| ()).unwrap();
        let ends: Vec<Option<Vec<f64>>> = r
            .starts
            .iter()
            .map(|s| s.objective.is_finite().then(|| s.end_x.clone()))
            .collect();
        let obj: Vec<f64> = r.starts.iter().map(|s| s.objective).collect();
        let (of, basins) = cluster(&ends, &obj, 1e-3);
        assert!(basins.len() >= 2);
        assert!((basins[0].point[0] - 1.0).abs() < 0.05, "{:?}", basins[0]);
        assert!((basins[1].point[0] + 1.0).abs() < 0.05, "{:?}", basins[1]);
        // Starts near a well (|x0 -+ 1| < 0.4) end in it, but for a few whose first L-BFGS
        // step overshoots into the other well (a decrease too, so the line search accepts it).
        let mut near = 0;
        let mut own = 0;
        for (s, b) in r.starts.iter().zip(&of) {
            let x0 = &s.start_x;
            for (c, id) in [(1.0, 0), (-1.0, 1)] {
                if ((x0[0] - c).powi(2) + x0[1] * x0[1]).sqrt() < 0.4 {
                    near += 1;
                    own += (*b == Some(id)) as usize;
                    assert!(b.is_some_and(|b| b <= 1), "start {x0:?} ended in {b:?}");
                }
            }
        }
        assert!(own as f64 >= 0.8 * near as f64, "{own} of {near}");
        assert!(near >= 10, "{near}");
    }

    #[test]
    fn polished_end_points_of_one_well_coincide_and_stay_in_their_well() {
        // End points scattered by a fraction of the wells' width (sd 0.15), as a gradient
        // tolerance leaves them: after Newton polishing, the two wells' points agree to 1e-6
        // (a 1e-6 clustering tolerance finds exactly the two wells) and none changes well.
        use crate::inference::map::polish_end_point;
        let ends = [
            [1.05, 0.03],
            [0.97, -0.02],
            [1.01, 0.05],
            [-0.95, -0.04],
            [-1.04, 0.02],
        ];
        let polished: Vec<(Vec<f64>, f64)> = ends
            .iter()
            .map(|e| polish_end_point(&DoubleWell, e, 1e-14).unwrap())
            .collect();
        for (e, (x, _)) in ends.iter().zip(&polished) {
            assert_eq!(e[0].signum(), x[0].signum(), "{e:?} -> {x:?}");
            assert!(
                (x[0].abs() - 1.0).abs() < 0.05 && x[1].abs() < 1e-6,
                "{x:?}"
            );
        }
        let pts: Vec<Option<Vec<f64>>> = polished.iter().map(|(x, _)| Some(x.clone())).collect();
        let obj: Vec<f64> = polished.iter().map(|(_, f)| *f).collect();
        let (of, basins) = cluster(&pts, &obj, 1e-6);
        assert_eq!(basins.len(), 2, "{basins:?}");
        assert_eq!(of, vec![Some(0), Some(0), Some(0), Some(1), Some(1)]);
        // Unpolished, the same tolerance splits every end point into its own basin.
        let raw: Vec<Option<Vec<f64>>> = ends.iter().map(|e| Some(e.to_vec())).collect();
        assert_eq!(cluster(&raw, &[0.0; 5], 1e-6).1.len(), 5);
    }
}
