//! The engine of a pass with every measured point's x, y and z directions that sweeps what
//! lies in the measured directions on the first pass's engine.
//!
//! `rfmlab diagnose` runs the loop again with every point's three directions when a first
//! pass on the measured directions accepted a point mass ([`super::command`]). The second pass
//! models the same structure and data: its starting model, the measured-direction candidates,
//! the alternative law, the null level and the drop-one check all read the receptances
//! between measured directions only, which the first pass's basis reproduces as certified (it
//! was built for exactly those points) at a third of the cost per sweep of the twelve-input
//! basis, and on grids no pencil was prepared for (the beam factor's scaled lines, the null
//! level's plant) with a dense LU of a third the size. Only a sweep that reads another
//! direction (a three-direction sensor mass) runs on the twelve-input basis.

use crate::common::C64;
use crate::fe::model::ObservationPoint;
use crate::frf::{EngineMode, FrfEngine, FrfError, Sweep, TermCoef};

/// The twelve-input engine `all` with the first pass's engine `measured` for the sweeps whose
/// inputs and outputs are all points of `measured` ([`FrfEngine::with_fewer_points`]); every
/// other call is `all`'s.
pub(crate) struct ThreeDirections<'a> {
    all: &'a dyn FrfEngine,
    measured: &'a dyn FrfEngine,
    /// Per point of `all`, the same point of `measured` (id, direction and DOFs), if any.
    map: Vec<Option<usize>>,
}

impl<'a> ThreeDirections<'a> {
    /// `all` (points `all_points`) with `measured` (points `measured_points`) for the sweeps
    /// within the points both have. None when `measured` has a point `all` lacks, or no point
    /// in common.
    pub(crate) fn new(
        all: &'a dyn FrfEngine,
        all_points: &[ObservationPoint],
        measured: &'a dyn FrfEngine,
        measured_points: &[ObservationPoint],
    ) -> Option<Self> {
        let same = |a: &ObservationPoint, b: &ObservationPoint| {
            a.id == b.id && a.direction == b.direction && a.dofs == b.dofs
        };
        if all_points.len() != all.n_out() || measured_points.len() != measured.n_out() {
            return None;
        }
        let map: Vec<Option<usize>> = all_points
            .iter()
            .map(|p| measured_points.iter().position(|q| same(p, q)))
            .collect();
        let covered = (0..measured_points.len()).all(|k| map.contains(&Some(k)));
        (covered && map.iter().any(Option::is_some)).then_some(ThreeDirections {
            all,
            measured,
            map,
        })
    }
}

impl FrfEngine for ThreeDirections<'_> {
    fn n_out(&self) -> usize {
        self.all.n_out()
    }
    fn inputs(&self) -> &[usize] {
        self.all.inputs()
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        self.all
            .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
    }
    fn with_fewer_points(
        &self,
        inputs: &[usize],
        outputs: &[usize],
    ) -> Option<Box<dyn FrfEngine + '_>> {
        let mapped = |v: &[usize]| -> Option<Vec<usize>> {
            v.iter()
                .map(|&i| self.map.get(i).copied().flatten())
                .collect()
        };
        let (Some(m_in), Some(m_out)) = (mapped(inputs), mapped(outputs)) else {
            return self.all.with_fewer_points(inputs, outputs);
        };
        if m_in.iter().any(|j| !self.measured.inputs().contains(j)) {
            return self.all.with_fewer_points(inputs, outputs);
        }
        let inner: Box<dyn FrfEngine + '_> = match self.measured.with_fewer_points(&m_in, &m_out) {
            Some(e) => e,
            None => Box::new(Borrowed(self.measured)),
        };
        // The inner engine's columns in the order of `inputs`.
        let cols = m_in
            .iter()
            .map(|j| inner.inputs().iter().position(|k| k == j))
            .collect::<Option<Vec<usize>>>()?;
        // Per point of `all`, its row in the inner engine's sweep.
        let rows = self.map.clone();
        Some(Box::new(Remapped {
            inner,
            n_out: self.all.n_out(),
            inputs: inputs.to_vec(),
            cols,
            rows,
        }))
    }
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<EngineMode>, FrfError>> {
        self.all.complex_modes(modulus_pa, n_modes)
    }
    fn complex_modes_with_masses(
        &self,
        modulus_pa: C64,
        n_modes: usize,
        masses: &[(usize, f64)],
    ) -> Option<Result<Vec<EngineMode>, FrfError>> {
        self.all
            .complex_modes_with_masses(modulus_pa, n_modes, masses)
    }
    fn term_names(&self) -> Vec<String> {
        self.all.term_names()
    }
    fn sweep_terms(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        terms: &[TermCoef],
        with_derivatives: bool,
    ) -> Result<(Sweep, Vec<Vec<C64>>), FrfError> {
        self.all
            .sweep_terms(omega_rad_s, modulus_pa, terms, with_derivatives)
    }
}

/// An engine used whole where a narrowed one is expected.
struct Borrowed<'a>(&'a dyn FrfEngine);

impl FrfEngine for Borrowed<'_> {
    fn n_out(&self) -> usize {
        self.0.n_out()
    }
    fn inputs(&self) -> &[usize] {
        self.0.inputs()
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        self.0
            .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
    }
}

/// The first pass's narrowed engine read in the points of the second pass: its sweeps are
/// scattered into the second pass's layout (the points it lacks read NaN).
struct Remapped<'a> {
    inner: Box<dyn FrfEngine + 'a>,
    n_out: usize,
    /// The second pass's inputs swept, in order.
    inputs: Vec<usize>,
    /// Per input, its column in the inner engine's sweep.
    cols: Vec<usize>,
    /// Per point of the second pass, its row in the inner engine's sweep.
    rows: Vec<Option<usize>>,
}

impl FrfEngine for Remapped<'_> {
    fn n_out(&self) -> usize {
        self.n_out
    }
    fn inputs(&self) -> &[usize] {
        &self.inputs
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        let mut inner = Sweep::default();
        self.inner
            .sweep_into(omega_rad_s, modulus_pa, with_derivatives, &mut inner)?;
        let nl = omega_rad_s.len();
        let ni = self.inputs.len();
        let nan = C64::new(f64::NAN, f64::NAN);
        let with_sh = with_derivatives && !inner.sh.is_empty();
        *out = Sweep {
            n_lines: nl,
            n_out: self.n_out,
            n_in: ni,
            h: vec![nan; nl * self.n_out * ni],
            dh_de: if with_derivatives {
                vec![nan; nl * self.n_out * ni]
            } else {
                Vec::new()
            },
            sh: if with_sh {
                vec![nan; nl * self.n_out * ni]
            } else {
                Vec::new()
            },
        };
        for l in 0..nl {
            for (o, row) in self.rows.iter().enumerate() {
                let Some(r) = *row else { continue };
                for (j, &c) in self.cols.iter().enumerate() {
                    let (at, from) = (out.idx(l, o, j), inner.idx(l, r, c));
                    out.h[at] = inner.h[from];
                    if with_derivatives {
                        out.dh_de[at] = inner.dh_de[from];
                    }
                    if with_sh {
                        out.sh[at] = inner.sh[from];
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A toy engine: H_ij = (i + 1) + 10 (input j + 1) + line, dH/dE' its negative, points
    /// named by `ids` (all in +y, one DOF each).
    struct Toy {
        n_out: usize,
        inputs: Vec<usize>,
        offset: f64,
    }

    impl FrfEngine for Toy {
        fn n_out(&self) -> usize {
            self.n_out
        }
        fn inputs(&self) -> &[usize] {
            &self.inputs
        }
        fn sweep_into(
            &self,
            omega_rad_s: &[f64],
            _modulus_pa: &[C64],
            with_derivatives: bool,
            out: &mut Sweep,
        ) -> Result<(), FrfError> {
            let nl = omega_rad_s.len();
            *out = Sweep::zeros(nl, self.n_out, self.inputs.len(), with_derivatives);
            for l in 0..nl {
                for i in 0..self.n_out {
                    for (jj, &j) in self.inputs.iter().enumerate() {
                        let v = C64::new(
                            self.offset + (i + 1) as f64 + 10.0 * (j + 1) as f64 + l as f64,
                            0.0,
                        );
                        let at = out.idx(l, i, jj);
                        out.h[at] = v;
                        if with_derivatives {
                            out.dh_de[at] = -v;
                            out.sh[at] = 2.0 * v;
                        }
                    }
                }
            }
            Ok(())
        }
    }

    fn point(id: u32, axis: crate::common::Axis, dof: usize) -> ObservationPoint {
        ObservationPoint {
            id,
            position: None,
            direction: crate::common::Direction::new(axis, 1),
            dofs: vec![(dof, 1.0)],
            note: String::new(),
        }
    }

    #[test]
    fn measured_sweeps_come_from_the_first_engine_and_others_from_the_whole() {
        use crate::common::Axis;
        // First pass: points 1 and 2 in y. Second: the same, then 1 and 2 in x.
        let measured_points = vec![point(1, Axis::Y, 10), point(2, Axis::Y, 20)];
        let all_points = vec![
            point(1, Axis::Y, 10),
            point(2, Axis::Y, 20),
            point(1, Axis::X, 11),
            point(2, Axis::X, 21),
        ];
        let measured = Toy {
            n_out: 2,
            inputs: vec![0, 1],
            offset: 0.0,
        };
        let all = Toy {
            n_out: 4,
            inputs: vec![0, 1, 2, 3],
            offset: 1000.0,
        };
        let e = ThreeDirections::new(&all, &all_points, &measured, &measured_points).unwrap();
        let w = [1.0, 2.0];
        let m = [C64::new(1.0, 0.0); 2];
        // Input 1 read at outputs 0 and 1: the first engine's, in the second's layout.
        let narrow = e.with_fewer_points(&[1], &[0, 1]).unwrap();
        assert_eq!(narrow.inputs(), &[1]);
        let s = narrow.sweep(&w, &m, true).unwrap();
        assert_eq!((s.n_out, s.n_in), (4, 1));
        for l in 0..2 {
            for i in 0..2 {
                let want = (i + 1) as f64 + 20.0 + l as f64;
                assert_eq!(s.h[s.idx(l, i, 0)], C64::new(want, 0.0));
                assert_eq!(s.dh_de[s.idx(l, i, 0)], C64::new(-want, 0.0));
            }
            assert!(s.h[s.idx(l, 2, 0)].re.is_nan());
        }
        // An x direction: the whole engine's.
        let wide = e.with_fewer_points(&[1, 2], &[0, 1, 2]);
        let s = match wide {
            Some(w2) => w2.sweep(&w, &m, false).unwrap(),
            None => e.sweep(&w, &m, false).unwrap(),
        };
        assert!(s.h.iter().all(|v| v.is_nan() || v.re > 999.0));
        // A first pass with a point the second lacks is refused.
        let other = vec![
            point(1, Axis::Y, 10),
            point(3, Axis::Y, 30),
            point(1, Axis::X, 11),
            point(2, Axis::X, 21),
        ];
        assert!(ThreeDirections::new(&all, &other, &measured, &measured_points).is_none());
    }
}
