//! Small dense complex kernels (row-major n x n), written out so that results are
//! bit-identical whatever the thread count.

use crate::common::C64;

/// LU with partial pivoting, P A = L U, stored in place (row-major).
pub(crate) struct DenseLu {
    n: usize,
    a: Vec<C64>,
    piv: Vec<usize>,
}

impl DenseLu {
    /// Factor; None when a pivot is exactly zero or not finite.
    pub fn factor(n: usize, mut a: Vec<C64>) -> Option<DenseLu> {
        let mut piv: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let mut p = k;
            let mut best = a[k * n + k].norm_sqr();
            for i in k + 1..n {
                let v = a[i * n + k].norm_sqr();
                if v > best {
                    best = v;
                    p = i;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return None;
            }
            if p != k {
                for j in 0..n {
                    a.swap(k * n + j, p * n + j);
                }
                piv.swap(k, p);
            }
            let inv = C64::new(1.0, 0.0) / a[k * n + k];
            let (top, bottom) = a.split_at_mut((k + 1) * n);
            let rowk = &top[k * n..];
            for i in 0..n - k - 1 {
                let row = &mut bottom[i * n..(i + 1) * n];
                let l = row[k] * inv;
                row[k] = l;
                if l != C64::new(0.0, 0.0) {
                    for j in k + 1..n {
                        row[j] -= l * rowk[j];
                    }
                }
            }
        }
        Some(DenseLu { n, a, piv })
    }

    /// Solve A x = b in place.
    pub fn solve(&self, b: &mut [C64]) {
        let n = self.n;
        let mut x: Vec<C64> = self.piv.iter().map(|&p| b[p]).collect();
        for i in 0..n {
            let mut s = x[i];
            for j in 0..i {
                s -= self.a[i * n + j] * x[j];
            }
            x[i] = s;
        }
        for i in (0..n).rev() {
            let mut s = x[i];
            for j in i + 1..n {
                s -= self.a[i * n + j] * x[j];
            }
            x[i] = s / self.a[i * n + i];
        }
        b.copy_from_slice(&x);
    }
}
