//! Which files a scene may read (`docs/scene-format.md`, "Files a scene reads"),
//! and reading them safely.
//!
//! A scene names other files (mesh paths; a glTF file's buffers). Each must lie,
//! after every `..`, percent-escape and symbolic link is resolved, inside the
//! scene file's folder or a folder the user allows ([`LoadOptions::allow_paths`],
//! `--allow-path DIR` on the command line), like POV-Ray's file I/O
//! restrictions. Only regular files are opened: a FIFO would block the reader for
//! ever and `/dev/zero` would fill memory. Every file opened is recorded, so that
//! tests (and callers who audit) can see exactly what a load touched.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Options of a load that reads files.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Folders, besides the scene's (or the mesh's) own, that the files it names
    /// may lie in (`--allow-path DIR`).
    pub allow_paths: Vec<PathBuf>,
}

/// Why a file was not read. Every message names the path and says why.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The path resolves outside every allowed folder; the file was not opened.
    #[error(
        "{path}: refused: it resolves to {resolved}, outside the allowed folders ({roots}); \
         to allow it, pass --allow-path DIR (LoadOptions::allow_paths in the API) with a folder that contains it"
    )]
    Outside {
        /// The path as named.
        path: PathBuf,
        /// Where it leads once `..` and symbolic links are resolved.
        resolved: PathBuf,
        /// The allowed folders, comma-separated.
        roots: String,
    },
    /// Not a regular file (a FIFO, a device, a directory, a socket); not opened.
    #[error("{path}: refused: it is {kind}, not a regular file (only regular files are read)")]
    NotRegular {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// The file cannot be found or read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is larger than the reader accepts.
    #[error("{path}: refused: {len} bytes is more than the {max} bytes accepted")]
    TooLarge {
        /// The path.
        path: PathBuf,
        /// Its size.
        len: u64,
        /// The limit.
        max: u64,
    },
    /// The file is shorter than the bytes its reader was told to expect.
    #[error("{path}: {len} bytes, but {need} are declared")]
    TooShort {
        /// The path.
        path: PathBuf,
        /// Its size.
        len: u64,
        /// Bytes declared.
        need: u64,
    },
}

/// Largest file read (scene, mesh, buffer or ray file): 16 GiB, beyond any real
/// asset; a cap so that no single read can be asked to allocate without bound.
pub const MAX_FILE_BYTES: u64 = 16 << 30;

/// The folders a load may read from, and the record of what it opened.
#[derive(Debug)]
pub struct Files {
    roots: Vec<PathBuf>,
    opened: Mutex<Vec<PathBuf>>,
}

impl Files {
    /// Files inside `base` (the folder of the scene or mesh being loaded) or any of
    /// `opts.allow_paths`. Folders that do not exist are skipped: nothing can be
    /// read from them anyway.
    pub fn new(base: &Path, opts: &LoadOptions) -> Files {
        let base = if base.as_os_str().is_empty() { Path::new(".") } else { base };
        let roots = std::iter::once(base)
            .chain(opts.allow_paths.iter().map(PathBuf::as_path))
            .filter_map(|p| std::fs::canonicalize(p).ok())
            .collect();
        Files { roots, opened: Mutex::new(Vec::new()) }
    }

    /// The canonical allowed folders.
    pub fn roots(&self) -> &[PathBuf] {
        &self.roots
    }

    /// Every file opened so far, canonical, in order.
    pub fn opened(&self) -> Vec<PathBuf> {
        self.opened.lock().map(|v| v.clone()).unwrap_or_default()
    }

    /// Where `path` leads, if that is inside an allowed folder; else why not.
    /// The file is not opened.
    pub fn resolve(&self, path: &Path) -> Result<PathBuf, FileError> {
        let resolved = std::fs::canonicalize(path).map_err(|source| FileError::Io { path: path.into(), source })?;
        if self.roots.iter().any(|r| resolved.starts_with(r)) {
            Ok(resolved)
        } else {
            let roots = self.roots.iter().map(|r| r.display().to_string()).collect::<Vec<_>>().join(", ");
            Err(FileError::Outside { path: path.into(), resolved, roots })
        }
    }

    /// Reads `path` whole, if it is a regular file inside an allowed folder.
    pub fn read(&self, path: &Path) -> Result<Vec<u8>, FileError> {
        let resolved = self.resolve(path)?;
        self.opened.lock().map(|mut v| v.push(resolved.clone())).ok();
        read_regular(&resolved, path, None)
    }

    /// Reads the first `need` bytes of `path` (a glTF buffer of declared
    /// `byteLength`), checking the file's size before allocating anything.
    pub fn read_prefix(&self, path: &Path, need: u64) -> Result<Vec<u8>, FileError> {
        let resolved = self.resolve(path)?;
        self.opened.lock().map(|mut v| v.push(resolved.clone())).ok();
        read_regular(&resolved, path, Some(need))
    }
}

/// Reads a file the user named directly (a scene or a ray file on the command
/// line): no folder rule, but only a regular file.
pub fn read_user_file(path: &Path) -> Result<Vec<u8>, FileError> {
    // Resolved first: the file is opened without following a final link.
    let real = std::fs::canonicalize(path).map_err(|source| FileError::Io { path: path.into(), source })?;
    read_regular(&real, path, None)
}

/// [`read_user_file`] as UTF-8 text.
pub fn read_user_text(path: &Path) -> Result<String, FileError> {
    let bytes = read_user_file(path)?;
    String::from_utf8(bytes).map_err(|e| FileError::Io {
        path: path.into(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to())),
    })
}

fn kind_of(ft: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    if ft.is_dir() {
        "a directory"
    } else if ft.is_symlink() {
        "a symbolic link"
    } else {
        "not a regular file"
    }
}

/// `O_NONBLOCK`: opening a FIFO with it returns at once instead of waiting for a
/// writer. The value is fixed per platform ABI; it is spelled here rather than
/// pulling in the libc crate for one constant.
#[cfg(all(
    any(target_os = "linux", target_os = "android"),
    not(any(target_arch = "mips", target_arch = "mips64", target_arch = "sparc64"))
))]
const O_NONBLOCK: i32 = 0o4000;
#[cfg(any(target_os = "macos", target_os = "ios", target_os = "freebsd", target_os = "openbsd", target_os = "netbsd"))]
const O_NONBLOCK: i32 = 0x4;

/// `O_NOFOLLOW`, where its value is known here: the path opened is canonical,
/// so its last component is no link; one swapped in between the check and the
/// open makes the open fail instead of being followed. (A swapped directory
/// higher up is not caught: that would need openat2's RESOLVE_BENEATH.)
#[cfg(all(any(target_os = "linux", target_os = "android"), any(target_arch = "x86_64", target_arch = "x86", target_arch = "riscv64")))]
const O_NOFOLLOW: i32 = 0o400000;
#[cfg(all(any(target_os = "linux", target_os = "android"), any(target_arch = "aarch64", target_arch = "arm")))]
const O_NOFOLLOW: i32 = 0o100000;
#[cfg(any(target_os = "macos", target_os = "ios", target_os = "freebsd"))]
const O_NOFOLLOW: i32 = 0x100;
#[cfg(not(any(
    all(
        any(target_os = "linux", target_os = "android"),
        any(target_arch = "x86_64", target_arch = "x86", target_arch = "riscv64", target_arch = "aarch64", target_arch = "arm")
    ),
    target_os = "macos",
    target_os = "ios",
    target_os = "freebsd"
)))]
#[allow(dead_code)]
const O_NOFOLLOW: i32 = 0;

fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    let mut o = std::fs::OpenOptions::new();
    o.read(true);
    #[cfg(any(
        all(
            any(target_os = "linux", target_os = "android"),
            not(any(target_arch = "mips", target_arch = "mips64", target_arch = "sparc64"))
        ),
        target_os = "macos",
        target_os = "ios",
        target_os = "freebsd",
        target_os = "openbsd",
        target_os = "netbsd"
    ))]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.custom_flags(O_NONBLOCK | O_NOFOLLOW);
    }
    o.open(path)
}

/// Checks that `path` is a regular file, opens it non-blocking, checks again on
/// the open file (the path may have been swapped in between), then reads it.
/// `named` is the path as the user or the scene wrote it, for messages.
fn read_regular(path: &Path, named: &Path, need: Option<u64>) -> Result<Vec<u8>, FileError> {
    let io = |source| FileError::Io { path: named.into(), source };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.file_type().is_file() {
        return Err(FileError::NotRegular { path: named.into(), kind: kind_of(meta.file_type()) });
    }
    let file = open_nonblocking(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.file_type().is_file() {
        return Err(FileError::NotRegular { path: named.into(), kind: kind_of(meta.file_type()) });
    }
    let len = meta.len();
    let want = match need {
        Some(n) if n > len => return Err(FileError::TooShort { path: named.into(), len, need: n }),
        Some(n) => n,
        None => len,
    };
    if want > MAX_FILE_BYTES {
        return Err(FileError::TooLarge { path: named.into(), len: want, max: MAX_FILE_BYTES });
    }
    let mut out = Vec::with_capacity(want as usize);
    // `take` bounds the read even if the file grows while it is read; a file in
    // /proc reports size 0 and is read up to the cap.
    let limit = if need.is_some() { want } else { MAX_FILE_BYTES };
    file.take(limit).read_to_end(&mut out).map_err(io)?;
    if let Some(n) = need {
        if (out.len() as u64) < n {
            return Err(FileError::TooShort { path: named.into(), len: out.len() as u64, need: n });
        }
    }
    Ok(out)
}
