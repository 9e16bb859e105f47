//! Small types shared by every module: the complex scalar, axis directions, a memo of recent
//! results.

pub use num_complex::Complex64 as C64;

/// Imaginary unit.
pub const J: C64 = C64::new(0.0, 1.0);

/// A global Cartesian axis.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// 0 for x, 1 for y, 2 for z.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
    pub fn from_index(i: usize) -> Option<Axis> {
        match i {
            0 => Some(Axis::X),
            1 => Some(Axis::Y),
            2 => Some(Axis::Z),
            _ => None,
        }
    }
}

/// A signed measurement or excitation direction along a global axis (UFF: +-1..+-3).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct Direction {
    pub axis: Axis,
    /// +1 or -1.
    pub sign: i8,
}

impl Direction {
    pub const fn new(axis: Axis, sign: i8) -> Self {
        Direction { axis, sign }
    }
    pub const PX: Direction = Direction::new(Axis::X, 1);
    pub const PY: Direction = Direction::new(Axis::Y, 1);
    pub const PZ: Direction = Direction::new(Axis::Z, 1);

    /// UFF direction code: 1,2,3 for +x,+y,+z and -1,-2,-3 for the negative ones.
    pub fn uff_code(self) -> i32 {
        (self.axis.index() as i32 + 1) * self.sign as i32
    }
    /// From a UFF direction code (+-1..+-3); 4..6 (rotations) and 0 give None.
    pub fn from_uff_code(code: i32) -> Option<Direction> {
        let axis = Axis::from_index((code.unsigned_abs() as usize).checked_sub(1)?)?;
        Some(Direction::new(axis, if code < 0 { -1 } else { 1 }))
    }
    /// Parse "+y", "y", "-Z", "Y+".
    pub fn parse(s: &str) -> Option<Direction> {
        let t = s.trim().to_ascii_lowercase();
        let (sign, rest) = if let Some(r) = t.strip_prefix('-') {
            (-1, r.to_string())
        } else if let Some(r) = t.strip_prefix('+') {
            (1, r.to_string())
        } else if let Some(r) = t.strip_suffix('-') {
            (-1, r.to_string())
        } else if let Some(r) = t.strip_suffix('+') {
            (1, r.to_string())
        } else {
            (1, t)
        };
        let axis = match rest.as_str() {
            "x" => Axis::X,
            "y" => Axis::Y,
            "z" => Axis::Z,
            _ => return None,
        };
        Some(Direction::new(axis, sign))
    }
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = if self.sign < 0 { '-' } else { '+' };
        let a = match self.axis {
            Axis::X => 'x',
            Axis::Y => 'y',
            Axis::Z => 'z',
        };
        write!(f, "{s}{a}")
    }
}

/// Quantile `p` in `[0, 1]` of already sorted values, linear interpolation between order
/// statistics (numpy's default "linear" method, Hyndman & Fan type 7); NaN for no values.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let h = (n - 1) as f64 * p.clamp(0.0, 1.0);
    let lo = h.floor();
    let i = (lo as usize).min(n - 1);
    let j = (i + 1).min(n - 1);
    // numpy's form of the interpolation, exact at both ends
    let (a, b, t) = (sorted[i], sorted[j], h - lo);
    if t >= 0.5 {
        b - (b - a) * (1.0 - t)
    } else {
        a + (b - a) * t
    }
}

/// The last `N` results of a computation, returned again when asked with an equal key: a small
/// first-in-first-out memo behind a lock, for an object asked the same question repeatedly
/// through a shared reference (a term ROM's sweeps, a simulated plant's grids). A copy starts
/// empty; a poisoned lock only turns the memo off.
pub struct Recent<K, V, const N: usize>(std::sync::Mutex<Vec<(K, V)>>);

impl<K, V, const N: usize> Default for Recent<K, V, N> {
    fn default() -> Self {
        Recent(std::sync::Mutex::new(Vec::new()))
    }
}

impl<K, V, const N: usize> Clone for Recent<K, V, N> {
    fn clone(&self) -> Self {
        Recent::default()
    }
}

impl<K, V, const N: usize> std::fmt::Debug for Recent<K, V, N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Recent<{N}>")
    }
}

impl<K: PartialEq, V: Clone, const N: usize> Recent<K, V, N> {
    /// The kept result for `key`, else `compute()`'s, kept (the oldest dropped beyond `N`).
    pub fn get_or_try<E>(&self, key: K, compute: impl FnOnce() -> Result<V, E>) -> Result<V, E> {
        if let Ok(m) = self.0.lock() {
            if let Some((_, v)) = m.iter().find(|(k, _)| *k == key) {
                return Ok(v.clone());
            }
        }
        let v = compute()?;
        if let Ok(mut m) = self.0.lock() {
            if m.len() >= N {
                m.remove(0);
            }
            m.push((key, v.clone()));
        }
        Ok(v)
    }
}
