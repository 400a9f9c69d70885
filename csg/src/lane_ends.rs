//! Test inputs shared by the 8-lane sweeps' tests (`small_first8`,
//! `tree_first8`): span ends built to hit every case of a lane's sweep.

use rand::{rngs::SmallRng, Rng};

/// One end: near the range's start `lo`, near a pool value, or anywhere,
/// nudged by multiples of eps; sometimes infinite or NaN.
pub(crate) fn end(rng: &mut SmallRng, lo: f32, eps: f32, pool: &[f32]) -> f32 {
    let nudge = [0.0, 0.5, 1.0, 1.9, 2.0, 2.1, 4.0, 8.0, 8.5, -0.5, -1.0, -2.0, -2.1][rng.gen_range(0..13)];
    match rng.gen_range(0..20) {
        0 => f32::INFINITY,
        1 => f32::NEG_INFINITY,
        2 if rng.gen_bool(0.2) => f32::NAN,
        3..=6 => lo + nudge * eps,
        7..=12 => pool[rng.gen_range(0..pool.len())] + nudge * eps,
        _ => lo + rng.gen_range(-1.0..4.0f32),
    }
}
