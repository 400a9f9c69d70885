//! Which pixels one part of a split render holds (`rothray render --tile I/N`).
//!
//! The renderer works on chunks of image rows, one row of tiles each (the
//! tile height of [`crate::tile_size`], 8); a part is a set of whole chunks, so
//! a part's pixels go through exactly the same tiles (and tile programs),
//! packets and jitter (a hash of the pixel index and the sample) as in the
//! whole image, and a merge of all parts is bit for bit the single render.

/// How the chunks are dealt out to the parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Split {
    /// Chunk c goes to part c mod N (the default: cost varies smoothly over the
    /// picture, so every part gets a fair share of the expensive rows).
    Interleaved,
    /// Contiguous bands of about nchunks / N chunks (kept to measure against).
    Bands,
}

impl Split {
    /// The name used on the command line and in part files.
    pub fn name(self) -> &'static str {
        match self {
            Split::Interleaved => "interleaved",
            Split::Bands => "bands",
        }
    }
    /// The inverse of [`name`](Self::name).
    pub fn from_name(s: &str) -> Option<Split> {
        match s {
            "interleaved" => Some(Split::Interleaved),
            "bands" => Some(Split::Bands),
            _ => None,
        }
    }
}

/// Part `index` of `count` (0 <= index < count).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Part {
    /// Which part, 0-based.
    pub index: u32,
    /// How many parts.
    pub count: u32,
    /// How chunks are dealt out.
    pub split: Split,
}

impl Part {
    /// The whole image as one part.
    pub const WHOLE: Part = Part { index: 0, count: 1, split: Split::Interleaved };

    /// The chunks (of `chunk_rows` rows) of an image `height` rows high that
    /// this part holds, in increasing order.
    pub fn chunks(&self, height: usize, chunk_rows: usize) -> Vec<usize> {
        let n = height.div_ceil(chunk_rows.max(1));
        let (i, k) = (self.index as usize, self.count.max(1) as usize);
        match self.split {
            Split::Interleaved => (i..n).step_by(k).collect(),
            Split::Bands => (n * i / k..n * (i + 1) / k).collect(),
        }
    }

    /// The image rows this part holds, in increasing order.
    pub fn rows(&self, height: usize, chunk_rows: usize) -> Vec<usize> {
        let r = chunk_rows.max(1);
        self.chunks(height, r).into_iter().flat_map(|c| c * r..((c + 1) * r).min(height)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_cover_every_row_once() {
        for split in [Split::Interleaved, Split::Bands] {
            for (h, cr) in [(1usize, 8), (3, 4), (4, 4), (5, 2), (24, 8), (37, 8), (1080, 8), (1080, 4)] {
                for n in 1..=9u32 {
                    let mut seen = vec![0u8; h];
                    for i in 0..n {
                        let rows = Part { index: i, count: n, split }.rows(h, cr);
                        assert!(rows.windows(2).all(|w| w[0] < w[1]));
                        for r in rows {
                            seen[r] += 1;
                        }
                    }
                    assert!(seen.iter().all(|&s| s == 1), "{split:?} h {h} n {n}");
                }
            }
        }
    }
}
