//! Giving freed memory back to the system during a large bake.
//!
//! glibc's malloc raises its mmap threshold (up to 32 MB) each time a large
//! block is freed, so the blocks of a bake that follow land in its heaps,
//! and the pages of the blocks freed there (build scratch, vectors that
//! grew) stay resident until something trims them. `malloc_trim` hands the
//! whole free pages back (`madvise`), in every arena.

/// Returns the allocator's free pages to the system (glibc's `malloc_trim`;
/// nothing elsewhere). For large bakes only: it walks every free block.
pub fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: malloc_trim takes no pointer and only reorganises the
        // allocator's own free lists, under its locks.
        unsafe {
            malloc_trim(0);
        }
    }
}
