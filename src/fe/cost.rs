//! Cost of a model before it is built: free DOFs, the peak memory and the time of the
//! engine's first factorisation, from the mesh divisions alone (nothing is allocated).
//!
//! Counts: a structured grid of n_x x n_y x n_z 20-node cells has
//! (n_x + 1)(n_y + 1)(n_z + 1) corner nodes and n_x (n_y + 1)(n_z + 1) + ... mid-edge nodes;
//! the joint is the beam's box plus the adhesive's box minus the bond face they share, and the
//! adhesive's lower face is fixed (3 DOFs per free node).
//!
//! Memory: the sparse matrices hold about `NNZ_PER_DOF` entries per DOF row (16 bytes each with
//! the index, M, K_b and S); a factor of Z = -w^2 M + K_b + E* S in the lattice-x-major
//! ordering has the profile of a banded matrix whose half-bandwidth is the DOFs of one
//! element slab (two lattice planes across the section), so its complex LU holds about
//! 2 n b complex values: memory ~ 16 (3 c n + 2 n b) bytes, with the threads' working copies
//! (`FACTOR_COPIES`). Time: a banded factorisation costs about n b^2 flops.
//! The constants are calibrated on the paper's joint (5 mm and 2.5 mm meshes); the estimate
//! is meant to be right within a factor of about two, enough to refuse what cannot fit.

/// Average stored entries per row of the assembled matrices (20-node hexahedra couple a node
/// with up to 81 nodes, 3 DOFs each; about 60 on average in a structured mesh).
pub const NNZ_PER_DOF: f64 = 180.0;
/// Factors alive at once during the engine's build (one per worker thread, at most 2 here).
pub const FACTOR_COPIES: f64 = 2.0;
/// Effective rate (n b^2 per second) of the complex sparse factorisation: 0.3 s for the
/// paper's 5 mm mesh (10 248 DOFs, b = 390), 37 s for its 2.5 mm mesh (67 000 DOFs).
pub const FLOPS_PER_SECOND: f64 = 5.0e9;

/// Estimated size and cost of a model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostEstimate {
    /// Free DOFs.
    pub n_dof: usize,
    /// Elements.
    pub n_elements: usize,
    /// Peak memory of the assembly plus the engine's complex factorisation (bytes).
    pub memory_bytes: f64,
    /// Time of one complex factorisation (s).
    pub factor_seconds: f64,
}

/// Nodes of a structured 20-node grid of `n` cells per direction (0 in a direction: a face).
pub fn serendipity_nodes(n: [usize; 3]) -> usize {
    let [a, b, c] = n;
    (a + 1) * (b + 1) * (c + 1)
        + a * (b + 1) * (c + 1)
        + (a + 1) * b * (c + 1)
        + (a + 1) * (b + 1) * c
}

/// Cost of the joint with `x_total` cells along the beam, `x_adhesive` of them under the
/// adhesive, `y_beam` / `y_adhesive` through the layers and `z` across the width.
pub fn joint_cost(
    x_total: usize,
    x_adhesive: usize,
    y_beam: usize,
    y_adhesive: usize,
    z: usize,
) -> CostEstimate {
    let beam = serendipity_nodes([x_total, y_beam, z]);
    let adh = serendipity_nodes([x_adhesive, y_adhesive, z]);
    let face = serendipity_nodes([x_adhesive, 0, z]);
    // shared bond face counted once; the adhesive's lower face is fixed
    let free_nodes = (beam + adh).saturating_sub(2 * face);
    let n_dof = 3 * free_nodes;
    let n_elements = x_total * y_beam * z + x_adhesive * y_adhesive * z;
    // one element slab: two lattice planes across the section (its mid-edge nodes are fewer)
    let section = serendipity_nodes([0, y_beam + y_adhesive, z]);
    let band = (3 * 2 * section) as f64;
    cost_of(n_dof, n_elements, band)
}

/// Cost of a model of `n_dof` DOFs whose factor has half-bandwidth `band`.
pub fn cost_of(n_dof: usize, n_elements: usize, band: f64) -> CostEstimate {
    let n = n_dof as f64;
    let band = band.min(n);
    let matrices = 16.0 * 3.0 * NNZ_PER_DOF * n;
    let factor = 16.0 * 2.0 * n * band * FACTOR_COPIES;
    CostEstimate {
        n_dof,
        n_elements,
        memory_bytes: matrices + factor,
        factor_seconds: n * band * band / FLOPS_PER_SECOND,
    }
}

/// Memory this process may use (bytes): `RFMLAB_MEMORY_LIMIT` (bytes) when set, else the
/// system's available memory (`MemAvailable` of /proc/meminfo), else 8 GiB.
pub fn available_memory_bytes() -> f64 {
    if let Some(v) = std::env::var("RFMLAB_MEMORY_LIMIT")
        .ok()
        .and_then(|s| s.trim().parse::<f64>().ok())
        .filter(|v| *v > 0.0)
    {
        return v;
    }
    if let Ok(text) = std::fs::read_to_string("/proc/meminfo") {
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("MemAvailable:") {
                if let Some(kb) = rest
                    .split_whitespace()
                    .next()
                    .and_then(|t| t.parse::<f64>().ok())
                {
                    return kb * 1024.0;
                }
            }
        }
    }
    8.0 * 1024f64.powi(3)
}

/// `bytes` as "12.3 GiB" / "450 MiB".
pub fn format_bytes(bytes: f64) -> String {
    let gib = bytes / 1024f64.powi(3);
    if gib >= 1.0 {
        format!("{gib:.1} GiB")
    } else {
        format!("{:.0} MiB", bytes / 1024f64.powi(2))
    }
}

/// `s` seconds as "12 s" / "3.4 min" / "5.6 h".
pub fn format_seconds(s: f64) -> String {
    if s < 120.0 {
        format!("{s:.0} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}

/// A work size beyond the machine's memory: its `Display` says how much is needed and how
/// much the machine has ("needs an estimated 9.1 GiB of memory, beyond the 4.0 GiB ...").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BeyondMemory {
    /// Estimated bytes (infinite when unbounded).
    pub needed_bytes: f64,
    /// Bytes available.
    pub available_bytes: f64,
}

impl std::fmt::Display for BeyondMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "needs an estimated {} of memory, beyond the {} this machine has available",
            if self.needed_bytes.is_finite() {
                format_bytes(self.needed_bytes)
            } else {
                "unbounded amount".into()
            },
            format_bytes(self.available_bytes)
        )
    }
}

impl std::error::Error for BeyondMemory {}

/// Whether an allocation of `bytes` fits in `available` memory.
pub fn check_memory(bytes: f64, available: f64) -> Result<(), BeyondMemory> {
    if bytes.is_finite() && bytes <= available {
        Ok(())
    } else {
        Err(BeyondMemory {
            needed_bytes: bytes,
            available_bytes: available,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_count_of_one_cell_is_twenty() {
        assert_eq!(serendipity_nodes([1, 1, 1]), 20);
        assert_eq!(serendipity_nodes([1, 0, 1]), 8);
        // two cells side by side share a face of 8 nodes
        assert_eq!(serendipity_nodes([2, 1, 1]), 32);
    }
}
