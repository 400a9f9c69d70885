//! The renderer's per-thread memory, kept by the scene from render to
//! render: a tool that syncs and previews every frame reuses its workers'
//! tile programs, each of which follows the scene's program edit by edit
//! (`rothray_csg::EditLog`), instead of copying the whole program per render
//! job per frame.

use std::ops::{Deref, DerefMut};
use std::sync::Mutex;

use crate::render_tile::Worker;

/// Workers not lent out (at most as many as ran at once).
#[derive(Default)]
pub(crate) struct WorkerPool(Mutex<Vec<Worker>>);

/// A worker lent by a [`WorkerPool`], given back when dropped.
pub(crate) struct Lent<'a> {
    pool: &'a WorkerPool,
    worker: Option<Worker>,
}

impl WorkerPool {
    /// A worker of an earlier render, or a new one.
    pub(crate) fn lend(&self) -> Lent<'_> {
        let worker = self.0.lock().map(|mut v| v.pop()).unwrap_or_default().unwrap_or_default();
        Lent { pool: self, worker: Some(worker) }
    }
}

impl Drop for Lent<'_> {
    fn drop(&mut self) {
        if let (Some(w), Ok(mut v)) = (self.worker.take(), self.pool.0.lock()) {
            v.push(w);
        }
    }
}

impl Deref for Lent<'_> {
    type Target = Worker;
    fn deref(&self) -> &Worker {
        self.worker.as_ref().expect("lent until dropped")
    }
}

impl DerefMut for Lent<'_> {
    fn deref_mut(&mut self) -> &mut Worker {
        self.worker.as_mut().expect("lent until dropped")
    }
}
