//! JSON paths (`objects[2].shape.difference[1].sphere.radius`) kept implicit,
//! through parent links on the parser's stack, and spelled out only when an
//! error or a leaf's default name needs them.
//!
//! Keeping each node's full path as a string made memory and time grow with the
//! square of the nesting depth (980 MB at depth 10 000). A spelled-out path is
//! at most [`MAX_PATH_CHARS`] characters: longer ones keep their first and last
//! segments and say how many levels were left out, and building one costs time
//! in proportion to that bound, not to the depth.

/// Longest path spelled out in full; longer ones are elided in the middle.
pub const MAX_PATH_CHARS: usize = 240;
/// Characters kept from the start of an elided path (whole segments, at most).
const HEAD_CHARS: usize = 80;
/// Characters kept from the end of an elided path (whole segments, at least).
const TAIL_CHARS: usize = 120;

/// One step of a path.
#[derive(Clone, Copy, Debug)]
enum Seg<'a> {
    Root,
    Key(&'a str),
    Index(usize),
}

/// A place in the scene's JSON: a segment and a link to its parent.
#[derive(Clone, Copy, Debug)]
pub struct At<'a> {
    parent: Option<&'a At<'a>>,
    seg: Seg<'a>,
    /// Levels below the root.
    depth: usize,
    /// Characters of the full path up to here.
    len: usize,
    /// The deepest strict ancestor whose full path fits in `HEAD_CHARS`: the head
    /// of an elided path, found without walking to the root.
    head: Option<&'a At<'a>>,
}

fn digits(mut i: usize) -> usize {
    let mut n = 1;
    while i >= 10 {
        i /= 10;
        n += 1;
    }
    n
}

impl<'a> At<'a> {
    /// The document root (an empty path).
    pub fn root() -> At<'static> {
        At { parent: None, seg: Seg::Root, depth: 0, len: 0, head: None }
    }

    fn child(&'a self, seg: Seg<'a>) -> At<'a> {
        let own = match seg {
            Seg::Root => 0,
            Seg::Key(k) if self.len == 0 => k.len(),
            Seg::Key(k) => k.len() + 1,
            Seg::Index(i) => digits(i) + 2,
        };
        let head = if self.len <= HEAD_CHARS { Some(self) } else { self.head };
        At { parent: Some(self), seg, depth: self.depth + 1, len: self.len + own, head }
    }

    /// The member `k` of the object here.
    pub fn key(&'a self, k: &'a str) -> At<'a> {
        self.child(Seg::Key(k))
    }

    /// The element `i` of the array here.
    pub fn index(&'a self, i: usize) -> At<'a> {
        self.child(Seg::Index(i))
    }

    /// Nesting depth (levels below the root).
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Segments from `stop` (exclusive) down to `self`, root first.
    fn segments_from(&self, stop: usize) -> Vec<&At<'a>> {
        let mut v = Vec::new();
        let mut n = Some(self);
        while let Some(a) = n {
            if a.depth <= stop {
                break;
            }
            v.push(a);
            n = a.parent;
        }
        v.reverse();
        v
    }

    fn push_seg(out: &mut String, a: &At) {
        match a.seg {
            Seg::Root => {}
            Seg::Key(k) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(k);
            }
            Seg::Index(i) => {
                out.push('[');
                out.push_str(&i.to_string());
                out.push(']');
            }
        }
    }

    fn full(&self) -> String {
        let mut s = String::with_capacity(self.len);
        for a in self.segments_from(0) {
            Self::push_seg(&mut s, a);
        }
        s
    }

    /// The path as text: in full up to [`MAX_PATH_CHARS`], else its head, the
    /// number of levels left out, and its tail.
    pub fn render(&self) -> String {
        if self.len <= MAX_PATH_CHARS {
            return self.full();
        }
        let head = self.head.map(|h| h.full()).unwrap_or_default();
        let head_depth = self.head.map_or(0, |h| h.depth);
        // The tail: whole segments from the end until TAIL_CHARS are covered.
        let mut tail_top = self;
        let mut covered = 0;
        while covered < TAIL_CHARS {
            match tail_top.parent {
                Some(p) if p.depth > head_depth => {
                    covered = self.len - p.len;
                    tail_top = p;
                }
                _ => break,
            }
        }
        let left_out = tail_top.depth - head_depth - 1;
        if left_out == 0 {
            // A few long keys, not depth: nothing to elide between the ends.
            return self.full();
        }
        let mut tail = String::new();
        for a in self.segments_from(tail_top.depth - 1) {
            Self::push_seg(&mut tail, a);
        }
        let tail = tail.strip_prefix('.').unwrap_or(&tail);
        let sep = if tail.starts_with('[') { "" } else { "." };
        format!("{head}.<{left_out} levels>{sep}{tail}")
    }
}

impl std::fmt::Display for At<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_paths_are_spelled_in_full() {
        let r = At::root();
        let o = r.key("objects");
        let i = o.index(2);
        let s = i.key("shape");
        let d = s.key("difference");
        let k = d.index(1);
        assert_eq!(k.render(), "objects[2].shape.difference[1]");
        assert_eq!(k.render().len(), k.len);
    }

    /// The elided path of a 100 000-deep node is short, keeps both ends and
    /// counts the levels between exactly; and it is built without a walk to
    /// the root (checked through its size only: the walk is what `head` avoids).
    #[test]
    fn deep_paths_are_elided_with_their_level_count() {
        fn go(a: &At, left: usize, out: &mut Vec<String>) {
            if left == 0 {
                let l = a.key("sphere");
                out.push(l.render());
                out.push(l.full());
                return;
            }
            let u = a.key("union");
            let i = u.index(0);
            go(&i, left - 1, out);
        }
        // The links live on the stack, as in the parser: a big one.
        let out = std::thread::Builder::new()
            .stack_size(1 << 29)
            .spawn(|| {
                let r = At::root();
                let o = r.key("objects");
                let i = o.index(0);
                let s = i.key("shape");
                let mut out = Vec::new();
                go(&s, 100_000, &mut out);
                out
            })
            .unwrap()
            .join()
            .unwrap();
        let (short, full) = (&out[0], &out[1]);
        assert!(short.len() <= MAX_PATH_CHARS + 40, "{} chars", short.len());
        assert!(short.starts_with("objects[0].shape.union[0]"), "{short}");
        assert!(short.ends_with(".union[0].sphere"), "{short}");
        // Levels spelled out plus those left out add up to the real depth.
        let spelled = short.matches('.').count() + short.matches('[').count();
        let left: usize = short.split(".<").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
        let full_levels = full.matches('.').count() + full.matches('[').count();
        assert_eq!(spelled - 1 + left, full_levels, "{short}");
    }
}
