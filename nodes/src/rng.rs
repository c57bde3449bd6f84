//! Seeded, order-free randomness: every draw is a hash of (seed, index), so results do not depend
//! on thread count or iteration order.

/// SplitMix64 finaliser: a fast, well-mixed 64-bit hash for seeded, order-free randomness.
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from a hash.
pub fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// A standard normal number from a hash (Box–Muller on two halves of the mixed hash).
pub fn gaussian(h: u64) -> f64 {
    let u1 = unit(h).max(1e-300);
    let u2 = unit(mix(h));
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Hashes keys word by word with [`mix`], for maps and sets keyed by the scene's own numbers
/// (cells, triangle sequences). The standard SipHash guards against keys chosen to collide,
/// which these are not, and cost a tenth of the street registration's time and a tenth of the
/// link tracer's. A map hashed so must never be iterated into a result in its own order (sort
/// first): its order is the hash's.
#[derive(Default)]
pub struct MixHasher(u64);

/// [`MixHasher`] as a `HashMap`/`HashSet` hasher parameter.
pub type MixState = std::hash::BuildHasherDefault<MixHasher>;

impl std::hash::Hasher for MixHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for word in bytes.chunks(8) {
            let mut w = [0u8; 8];
            w[..word.len()].copy_from_slice(word);
            self.0 = mix(self.0 ^ u64::from_le_bytes(w));
        }
    }
}
