//! Which pixels one part of a split render holds (`rothray render --tile I/N`).
//!
//! The renderer works on chunks of [`CHUNK_ROWS`] image rows; a part is a set of
//! whole chunks, so a part's pixels go through exactly the same packets, tiles
//! and jitter (a hash of the pixel index and the sample) as in the whole image,
//! and a merge of all parts is bit for bit the single render.

/// Rows per chunk: the renderer's unit of work (`ROWS` in `render`).
pub const CHUNK_ROWS: usize = 4;

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

    /// The chunks (of [`CHUNK_ROWS`] rows) of an image `height` rows high that
    /// this part holds, in increasing order.
    pub fn chunks(&self, height: usize) -> Vec<usize> {
        let n = height.div_ceil(CHUNK_ROWS);
        let (i, k) = (self.index as usize, self.count.max(1) as usize);
        match self.split {
            Split::Interleaved => (i..n).step_by(k).collect(),
            Split::Bands => (n * i / k..n * (i + 1) / k).collect(),
        }
    }

    /// The image rows this part holds, in increasing order.
    pub fn rows(&self, height: usize) -> Vec<usize> {
        self.chunks(height).into_iter().flat_map(|c| c * CHUNK_ROWS..((c + 1) * CHUNK_ROWS).min(height)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_cover_every_row_once() {
        for split in [Split::Interleaved, Split::Bands] {
            for h in [1usize, 3, 4, 5, 24, 37, 1080] {
                for n in 1..=9u32 {
                    let mut seen = vec![0u8; h];
                    for i in 0..n {
                        let rows = Part { index: i, count: n, split }.rows(h);
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
