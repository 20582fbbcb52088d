//! SplitMix64 with Box–Muller normals: a tiny deterministic generator so
//! that tests, benches and examples need no RNG crate. Shared by `#[path]`
//! (tests/common/mod.rs, benches/learned/data.rs and the examples that draw
//! random data), so every one of them draws the same stream from a seed.

#![allow(dead_code)] // each includer uses its own part of this file

/// SplitMix64 (Steele, Lea & Flood 2014); the field is the state.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi) with 53 random bits.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    /// A standard normal draw (Box–Muller, cosine branch; two uniforms).
    pub fn normal(&mut self) -> f64 {
        let u = self.uniform(f64::MIN_POSITIVE, 1.0);
        let v = self.uniform(0.0, 1.0);
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }

    /// Uniform in 0..n (by the remainder: a bias below 2⁻⁶⁴·n).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}
