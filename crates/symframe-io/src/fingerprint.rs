//! A small, stable 64-bit fingerprint (FNV-1a) for telling whether a cache or a partial result
//! still belongs to the same inputs and parameters.
//!
//! Not cryptographic: it guards against stale files, not against tampering. Every value is fed
//! as explicit little-endian bytes (strings length-prefixed), so a fingerprint does not depend on
//! the compiler version or the platform's `Hash` implementations.

use std::path::Path;

/// An FNV-1a 64-bit hasher over explicitly encoded values.
#[derive(Debug, Clone, Copy)]
pub struct Fingerprint(u64);

impl Default for Fingerprint {
    fn default() -> Self {
        Self::new()
    }
}

impl Fingerprint {
    /// A hasher with nothing fed yet.
    pub fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    /// Feeds raw bytes.
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        for &b in bytes {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }

    /// Feeds an integer.
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.bytes(&v.to_le_bytes())
    }

    /// Feeds a float by its bits.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }

    /// Feeds a string, length first (so `"ab","c"` and `"a","bc"` differ).
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64).bytes(s.as_bytes())
    }

    /// Feeds a path (its lossy UTF-8 form).
    pub fn path(&mut self, p: &Path) -> &mut Self {
        self.str(&p.to_string_lossy())
    }

    /// The fingerprint so far.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_value_and_separation() {
        // FNV-1a 64 of "a" (reference value).
        assert_eq!(
            Fingerprint::new().bytes(b"a").finish(),
            0xaf63_dc4c_8601_ec8c
        );
        let ab_c = Fingerprint::new().str("ab").str("c").finish();
        let a_bc = Fingerprint::new().str("a").str("bc").finish();
        assert_ne!(ab_c, a_bc);
    }
}
