//! The relaxation laws the material-level loop moves through, in one parametrisation:
//!
//! E*(w) = E0 [+ j h] + sum_k E_k j w tau_k / (1 + j w tau_k) [+ E_f (j w tau_f)^a / (1 + (j w tau_f)^a)]
//!
//! with parameters `[E0, (h), E_1, tau_1, ..., E_n, tau_n, (E_f, tau_f, a)]` (Pa, Pa, Pa and s
//! per branch, Pa, s and 1). A Maxwell branch is written with its relaxation time
//! `tau_k = eta_k / E_k` (paper eq. 27 with eta = E tau) because a log-uniform prior on the
//! time is the natural one on a master curve spanning many decades. Special cases:
//! the paper's Model 4 (eq. 33) is `h` + one branch; the fractional Zener law
//! ([`crate::material::FractionalZener`]) is the fractional branch alone; the generalized
//! Maxwell (Prony) series is `n` branches without `h`.

use crate::common::{C64, J};
use crate::material::{ConstitutiveModel, FractionalZener};

/// Which terms a law has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RelaxationLaw {
    /// The structural damper `j h` of Models 1 and 4 (a frequency-independent loss modulus,
    /// which is not causal on its own: see [`super::kk`]).
    pub structural_damper: bool,
    /// Number of Maxwell branches.
    pub n_branches: usize,
    /// A fractional Zener branch.
    pub fractional: bool,
}

/// What a parameter is, for its prior.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// A modulus (Pa).
    Modulus,
    /// A relaxation time (s).
    Time,
    /// The fractional order (1).
    Order,
}

impl RelaxationLaw {
    /// The paper's Model 4: E0 + j h + one Maxwell branch.
    pub fn model4() -> Self {
        RelaxationLaw {
            structural_damper: true,
            n_branches: 1,
            fractional: false,
        }
    }
    /// The fractional Zener law: E0 + a fractional branch.
    pub fn fractional_zener() -> Self {
        RelaxationLaw {
            structural_damper: false,
            n_branches: 0,
            fractional: true,
        }
    }
    /// The generalized Maxwell series with `n` branches.
    pub fn generalized_maxwell(n: usize) -> Self {
        RelaxationLaw {
            structural_damper: false,
            n_branches: n,
            fractional: false,
        }
    }

    /// A short name: "model4", "fractional_zener", "gm3" (generalized Maxwell, 3 branches),
    /// otherwise the terms joined by "+", e.g. "E0+h+3br+frac".
    pub fn label(&self) -> String {
        match (self.structural_damper, self.n_branches, self.fractional) {
            (true, 1, false) => "model4".into(),
            (false, 0, true) => "fractional_zener".into(),
            (false, n, false) => format!("gm{n}"),
            (h, n, f) => {
                let mut s = "E0".to_string();
                if h {
                    s.push_str("+h");
                }
                if n > 0 {
                    s.push_str(&format!("+{n}br"));
                }
                if f {
                    s.push_str("+frac");
                }
                s
            }
        }
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        1 + usize::from(self.structural_damper)
            + 2 * self.n_branches
            + 3 * usize::from(self.fractional)
    }

    /// Index of `E_k` (branch k = 0..n) in the parameter vector; `tau_k` follows it.
    pub fn branch_index(&self, k: usize) -> usize {
        1 + usize::from(self.structural_damper) + 2 * k
    }

    /// Index of `E_f` when the law has a fractional branch.
    pub fn fractional_index(&self) -> Option<usize> {
        self.fractional
            .then(|| 1 + usize::from(self.structural_damper) + 2 * self.n_branches)
    }

    /// Parameter names.
    pub fn param_names(&self) -> Vec<String> {
        let mut v = vec!["E0".to_string()];
        if self.structural_damper {
            v.push("h".into());
        }
        for k in 1..=self.n_branches {
            v.push(format!("E_{k}"));
            v.push(format!("tau_{k}"));
        }
        if self.fractional {
            v.extend(["E_f".to_string(), "tau_f".into(), "alpha".into()]);
        }
        v
    }

    /// Parameter kinds (for priors) in parameter order.
    pub fn param_kinds(&self) -> Vec<ParamKind> {
        let mut v = vec![ParamKind::Modulus];
        if self.structural_damper {
            v.push(ParamKind::Modulus);
        }
        for _ in 0..self.n_branches {
            v.extend([ParamKind::Modulus, ParamKind::Time]);
        }
        if self.fractional {
            v.extend([ParamKind::Modulus, ParamKind::Time, ParamKind::Order]);
        }
        v
    }

    /// SI unit of each parameter.
    pub fn param_units(&self) -> Vec<String> {
        self.param_kinds()
            .iter()
            .map(|k| match k {
                ParamKind::Modulus => "Pa",
                ParamKind::Time => "s",
                ParamKind::Order => "1",
            })
            .map(String::from)
            .collect()
    }

    /// E*(w; p) in Pa (w in rad/s, w >= 0; `p` of length [`Self::n_params`]).
    pub fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        let mut e = C64::new(p[0], 0.0);
        if self.structural_damper {
            e += J * p[1];
        }
        for k in 0..self.n_branches {
            let i = self.branch_index(k);
            let s = J * (omega_rad_s * p[i + 1]);
            e += p[i] * s / (1.0 + s);
        }
        if let Some(i) = self.fractional_index() {
            e += FractionalZener.modulus(&[0.0, p[i], p[i + 1], p[i + 2]], omega_rad_s);
        }
        e
    }

    /// dE*/dp_k for every parameter, into `out` (length [`Self::n_params`]):
    /// a branch gives dM/dE = s / (1 + s) and dM/dtau = E j w / (1 + s)^2 with s = j w tau;
    /// the fractional branch's derivatives are [`FractionalZener`]'s.
    pub fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        out[0] = C64::new(1.0, 0.0);
        if self.structural_damper {
            out[1] = J;
        }
        for k in 0..self.n_branches {
            let i = self.branch_index(k);
            let s = J * (omega_rad_s * p[i + 1]);
            let d = 1.0 + s;
            out[i] = s / d;
            out[i + 1] = p[i] * J * omega_rad_s / (d * d);
        }
        if let Some(i) = self.fractional_index() {
            let mut f = [C64::new(0.0, 0.0); 4];
            FractionalZener.jacobian(&[0.0, p[i], p[i + 1], p[i + 2]], omega_rad_s, &mut f);
            out[i] = f[1];
            out[i + 1] = f[2];
            out[i + 2] = f[3];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{GeneralizedMaxwell, Model4};

    #[test]
    fn special_cases_equal_the_material_laws() {
        let w = [0.3, 7.0, 1e3];
        // Model 4 with eta1 = E1 tau1.
        let p = [6.67e6, 0.944e6, 3.1487e6, 4181.0 / 3.1487e6];
        for &o in &w {
            let a = RelaxationLaw::model4().modulus(&p, o);
            let b = Model4.modulus(&[p[0], p[1], p[2], p[2] * p[3]], o);
            assert!((a - b).norm() <= 1e-12 * b.norm());
        }
        let gm = RelaxationLaw::generalized_maxwell(2);
        let p = [1e6, 2e6, 1e-2, 5e6, 3e-4];
        for &o in &w {
            let a = gm.modulus(&p, o);
            let b = GeneralizedMaxwell::new(2).modulus(&[1e6, 2e6, 2e4, 5e6, 1.5e3], o);
            assert!((a - b).norm() <= 1e-12 * b.norm());
        }
        let fz = RelaxationLaw::fractional_zener();
        let p = [1e6, 2e6, 1e-2, 0.4];
        for &o in &w {
            let a = fz.modulus(&p, o);
            let b = FractionalZener.modulus(&p, o);
            assert!((a - b).norm() <= 1e-12 * b.norm());
        }
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let law = RelaxationLaw {
            structural_damper: true,
            n_branches: 2,
            fractional: true,
        };
        let p = [1e6, 2e5, 3e6, 1e-2, 4e6, 2e-4, 5e6, 3e-3, 0.45];
        let mut jac = vec![C64::new(0.0, 0.0); law.n_params()];
        for &o in &[0.5, 60.0, 4e3] {
            law.jacobian(&p, o, &mut jac);
            for k in 0..p.len() {
                let e = 1e-6 * p[k];
                let mut a = p;
                a[k] += e;
                let mut b = p;
                b[k] -= e;
                let fd = (law.modulus(&a, o) - law.modulus(&b, o)) / (2.0 * e);
                let scale = law.modulus(&p, o).norm() / p[k];
                assert!(
                    (fd - jac[k]).norm() <= 1e-6 * scale,
                    "param {k} at w {o}: fd {fd} analytic {}",
                    jac[k]
                );
            }
        }
    }
}
