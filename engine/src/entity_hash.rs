//! A fast hasher for maps keyed by `hecs::Entity` (two `u32`s, from a
//! trusted source: the tool's own World), in place of std's SipHash. The
//! first sync of 100 000 objects spent 137 ms filling its entity maps with
//! SipHash.

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// Multiply-rotate hashing (as rustc's FxHash), finished with a shift so
/// the high bits hashbrown uses for its control bytes depend on every input.
#[derive(Default, Clone, Copy)]
pub(crate) struct EntityHasher(u64);

impl Hasher for EntityHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u32(&mut self, x: u32) {
        self.write_u64(x as u64);
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(26) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 31)
    }
}

/// A map keyed by entity.
pub(crate) type EntityMap<V> = HashMap<hecs::Entity, V, BuildHasherDefault<EntityHasher>>;
/// A set of entities.
pub(crate) type EntitySet = HashSet<hecs::Entity, BuildHasherDefault<EntityHasher>>;
