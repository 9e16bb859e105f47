//! Checkpoints of sampler runs: a small exact binary format, written atomically.
//!
//! A file is `MAGIC`, the 32-byte SHA-256 key of the run's settings, then the payload: unsigned
//! integers and `f64` bit patterns as little-endian `u64`, vectors prefixed by their length. Floats
//! round-trip bit for bit (infinities and NaN included), which a resumed run needs to end
//! bit-identical to an uninterrupted one.
//!
//! Writes go to a temporary file in the same directory, which is then renamed over the target:
//! a reader sees either the old file or the new one, never a torn one. A file whose key differs
//! from the current run's (other settings, seed, starts or dimension) or that cannot be decoded
//! is ignored (left in place; file names carry the key, so runs with other settings use other
//! files), never mixed into a result.
//!
//! The key cannot see the posterior itself (the data, the forward model): give each posterior
//! its own checkpoint directory.

use std::fs;
use std::path::Path;

use sha2::{Digest, Sha256};

use super::sampling::SamplerError;

const MAGIC: &[u8; 8] = b"RFMCKPT1";

/// Little-endian encoder of the checkpoint payloads (and of the settings a key hashes).
#[derive(Debug, Default, Clone)]
pub struct Encoder(Vec<u8>);

impl Encoder {
    /// An empty buffer.
    pub fn new() -> Self {
        Self::default()
    }
    /// Appends a `u64`.
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// Appends an `f64` as its bit pattern.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }
    /// Appends a length-prefixed string.
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
        self
    }
    /// Appends a length-prefixed `f64` slice.
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| {
            self.f64(x);
        });
        self
    }
    /// Appends a length-prefixed `u64` slice.
    pub fn u64s(&mut self, v: &[u64]) -> &mut Self {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| {
            self.u64(x);
        });
        self
    }
    /// Appends a length-prefixed `bool` slice.
    pub fn bools(&mut self, v: &[bool]) -> &mut Self {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| {
            self.u64(x as u64);
        });
        self
    }
    /// Appends a length-prefixed list of rows.
    pub fn rows(&mut self, v: &[Vec<f64>]) -> &mut Self {
        self.u64(v.len() as u64);
        v.iter().for_each(|r| {
            self.f64s(r);
        });
        self
    }
    /// The bytes written.
    pub fn bytes(&self) -> &[u8] {
        &self.0
    }
    /// SHA-256 of the bytes written: the key of a run's settings.
    pub fn key(&self) -> [u8; 32] {
        let d = Sha256::digest(&self.0);
        let mut k = [0u8; 32];
        k.copy_from_slice(&d);
        k
    }
}

/// Decoder of [`Encoder`] payloads; every read returns `None` past the end.
#[derive(Debug)]
pub struct Decoder<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Decoder<'a> {
    /// Reads `b` from its start.
    pub fn new(b: &'a [u8]) -> Self {
        Self { b, pos: 0 }
    }
    /// Reads a `u64`.
    pub fn u64(&mut self) -> Option<u64> {
        let s = self.b.get(self.pos..self.pos + 8)?;
        self.pos += 8;
        Some(u64::from_le_bytes(s.try_into().ok()?))
    }
    /// Reads an `f64`.
    pub fn f64(&mut self) -> Option<f64> {
        self.u64().map(f64::from_bits)
    }
    fn len(&mut self) -> Option<usize> {
        let n = usize::try_from(self.u64()?).ok()?;
        // Each element takes at least 8 bytes: a corrupt length cannot allocate wildly.
        (n <= (self.b.len() - self.pos) / 8 + 1).then_some(n)
    }
    /// Reads a string.
    pub fn str(&mut self) -> Option<String> {
        let n = usize::try_from(self.u64()?).ok()?;
        let s = self.b.get(self.pos..self.pos.checked_add(n)?)?;
        self.pos += n;
        String::from_utf8(s.to_vec()).ok()
    }
    /// Reads an `f64` vector.
    pub fn f64s(&mut self) -> Option<Vec<f64>> {
        let n = self.len()?;
        (0..n).map(|_| self.f64()).collect()
    }
    /// Reads a `u64` vector.
    pub fn u64s(&mut self) -> Option<Vec<u64>> {
        let n = self.len()?;
        (0..n).map(|_| self.u64()).collect()
    }
    /// Reads a `bool` vector.
    pub fn bools(&mut self) -> Option<Vec<bool>> {
        let n = self.len()?;
        (0..n).map(|_| self.u64().map(|v| v != 0)).collect()
    }
    /// Reads a list of rows.
    pub fn rows(&mut self) -> Option<Vec<Vec<f64>>> {
        let n = self.len()?;
        (0..n).map(|_| self.f64s()).collect()
    }
    /// Whether every byte was read.
    pub fn at_end(&self) -> bool {
        self.pos == self.b.len()
    }
}

/// First 16 hex digits of a key, for file names.
pub fn key_hex(key: &[u8; 32]) -> String {
    key[..8].iter().map(|b| format!("{b:02x}")).collect()
}

fn io_err(path: &Path, op: &'static str, source: std::io::Error) -> SamplerError {
    SamplerError::Checkpoint {
        path: path.to_path_buf(),
        op,
        source,
    }
}

/// Creates the checkpoint directory (and its parents) if needed.
pub fn ensure_dir(dir: &Path) -> Result<(), SamplerError> {
    fs::create_dir_all(dir).map_err(|e| io_err(dir, "create directory", e))
}

/// Writes `MAGIC`, `key` and `payload` to `path` atomically ([`crate::fs_atomic`]: a uniquely
/// named temporary file in the same directory, fsynced, then renamed over `path`).
pub fn write_atomic(path: &Path, key: &[u8; 32], payload: &[u8]) -> Result<(), SamplerError> {
    crate::fs_atomic::write_atomic(path, |w| {
        w.write_all(MAGIC)?;
        w.write_all(key)?;
        w.write_all(payload)
    })
    .map_err(|e| io_err(path, "write", e))
}

/// The payload of the checkpoint at `path` if it exists and was written under `key`; `None`
/// when it is absent, foreign (another key) or truncated. Other I/O errors are returned.
pub fn read_matching(path: &Path, key: &[u8; 32]) -> Result<Option<Vec<u8>>, SamplerError> {
    let bytes = match fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io_err(path, "read", e)),
    };
    let head = MAGIC.len() + 32;
    if bytes.len() < head || &bytes[..MAGIC.len()] != MAGIC || &bytes[MAGIC.len()..head] != key {
        return Ok(None);
    }
    Ok(Some(bytes[head..].to_vec()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payload_round_trips_bit_for_bit_including_non_finite_values() {
        let mut e = Encoder::new();
        let floats = [0.1, -0.0, f64::NEG_INFINITY, f64::MIN_POSITIVE / 3.0, 1e300];
        e.u64(7)
            .f64s(&floats)
            .rows(&[vec![1.5], vec![]])
            .bools(&[true, false])
            .u64s(&[3, 4])
            .str("a_b");
        let mut d = Decoder::new(e.bytes());
        assert_eq!(d.u64(), Some(7));
        let back = d.f64s().unwrap();
        assert!(back
            .iter()
            .zip(&floats)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(d.rows(), Some(vec![vec![1.5], vec![]]));
        assert_eq!(d.bools(), Some(vec![true, false]));
        assert_eq!(d.u64s(), Some(vec![3, 4]));
        assert_eq!(d.str().as_deref(), Some("a_b"));
        assert!(d.at_end());
        assert_eq!(d.u64(), None);
    }

    #[test]
    fn a_file_under_another_key_is_ignored_and_a_missing_one_is_none() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.bin");
        let k1 = Encoder::new().u64(1).key();
        let k2 = Encoder::new().u64(2).key();
        assert_eq!(read_matching(&path, &k1).unwrap(), None);
        write_atomic(&path, &k1, &[1, 2, 3]).unwrap();
        assert_eq!(read_matching(&path, &k1).unwrap(), Some(vec![1, 2, 3]));
        assert_eq!(read_matching(&path, &k2).unwrap(), None);
        // No temporary file is left behind.
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn an_unwritable_directory_names_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no").join("such").join("c.bin");
        let err = write_atomic(&missing, &[0; 32], &[]).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("checkpoint write failed") && msg.contains("no"),
            "{msg}"
        );
    }
}
