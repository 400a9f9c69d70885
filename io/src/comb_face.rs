//! A comb-shaped OBJ face (no fan or halving is valid for it) for the
//! tests of both suites that load one: the io crate's loader test and the
//! CLI's hostile-input test (which includes this file by path).

/// A comb face of `teeth` teeth (heights from `seed`), on integer coordinates:
/// 3 teeth + 2 vertices, counter-clockwise. Returns the OBJ `v` lines, the
/// face's index list, and its shoelace area.
pub fn comb_obj(teeth: usize, seed: u64) -> (String, Vec<usize>, f64) {
    let mut p: Vec<[i64; 2]> = vec![[2 * teeth as i64, 0]];
    let mut h = seed;
    for t in (0..teeth as i64).rev() {
        h = h.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let y = 2 + (h >> 61) as i64;
        p.push([2 * t + 2, y]);
        p.push([2 * t + 1, y]);
        p.push(if t > 0 { [2 * t + 1, 1] } else { [0, y] });
    }
    p.push([0, 0]);
    let area = (0..p.len()).map(|i| (p[i][0] * p[(i + 1) % p.len()][1] - p[i][1] * p[(i + 1) % p.len()][0]) as f64).sum::<f64>() * 0.5;
    let v: String = p.iter().map(|q| format!("v {} {} 0\n", q[0], q[1])).collect();
    (v, (1..=p.len()).collect(), area)
}
