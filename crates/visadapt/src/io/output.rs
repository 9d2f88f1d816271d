//! How every output file of the library is written, and what it must never replace.
//!
//! * **All or nothing.** An output is filled in a temporary file in its destination's
//!   directory and moved into place only when it is complete ([`PendingFile::commit`]);
//!   on an error, or when the [`PendingFile`] is dropped, it disappears and a previous
//!   file at the destination survives. On Linux the temporary file is created unnamed
//!   (`O_TMPFILE`) and given its name with `linkat` only when complete, so even a
//!   `SIGKILL` leaves nothing behind; elsewhere (or on file systems without `O_TMPFILE`)
//!   it is a named `.visadapt-*.tmp` file, listed while it exists so that
//!   [`remove_in_flight_files`] can delete it when the process is interrupted. Setting
//!   the environment variable `VISADAPT_NAMED_TEMPORARIES=1` makes every output take the
//!   named path (for file systems that mishandle unnamed files; the tests use it to
//!   exercise interruption).
//! * **Permissions.** A new file gets `0666` less the process's umask, as `open(2)` gives
//!   any new file; a replaced file keeps its permission bits, without setuid, setgid or
//!   sticky bits.
//! * **Never an input.** Every file read through [`read`](super::read) (or passed to
//!   [`protect_input`]) is remembered, by device and inode and by canonical path, for the
//!   life of the process; an output that is the same file (under any name: the same path,
//!   a symbolic link, a hard link) is refused with [`Error::InvalidParameter`] before
//!   anything is written, and checked again just before it is moved into place.

use crate::{Error, Result};
use std::fs::File;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// The identity of a file: device and inode where the platform has them, and the
/// canonical path.
#[derive(Debug, Clone, PartialEq, Eq)]
struct FileId {
    /// `(st_dev, st_ino)`.
    inode: Option<(u64, u64)>,
    canonical: Option<PathBuf>,
}

impl FileId {
    fn of(meta: &std::fs::Metadata, path: &Path) -> Self {
        #[cfg(unix)]
        let inode = {
            use std::os::unix::fs::MetadataExt;
            Some((meta.dev(), meta.ino()))
        };
        #[cfg(not(unix))]
        let inode = {
            let _ = meta;
            None
        };
        FileId {
            inode,
            canonical: path.canonicalize().ok(),
        }
    }

    /// The file at `path` (following symbolic links), if there is one.
    fn at(path: &Path) -> Option<Self> {
        std::fs::metadata(path).ok().map(|m| Self::of(&m, path))
    }

    fn same(&self, other: &FileId) -> bool {
        match (self.inode, other.inode) {
            (Some(a), Some(b)) => a == b,
            _ => self.canonical.is_some() && self.canonical == other.canonical,
        }
    }
}

/// The inputs of this process: files no output may replace.
static INPUTS: Mutex<Vec<(FileId, PathBuf)>> = Mutex::new(Vec::new());

/// Named temporary files that exist right now (only where unnamed files are not
/// available, and for the instant between naming and renaming an unnamed one).
static IN_FLIGHT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Remember the open file `file`, read from `path`, as an input that no output of this
/// process may replace. [`read`](super::read) calls it for every file it opens.
pub fn protect_input(path: &Path, file: &File) -> Result<()> {
    let id = FileId::of(&file.metadata()?, path);
    let mut inputs = lock(&INPUTS);
    if !inputs.iter().any(|(known, _)| known.same(&id)) {
        inputs.push((id, path.to_path_buf()));
    }
    Ok(())
}

/// Whether `a` and `b` name the same existing file (same device and inode, so also
/// through symbolic and hard links).
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (FileId::at(a), FileId::at(b)) {
        (Some(a), Some(b)) => a.same(&b),
        _ => false,
    }
}

/// The error for an output that is an input.
fn would_overwrite(output: &Path, input: &Path) -> Error {
    Error::invalid(
        "output",
        output.display(),
        format!(
            "would overwrite the input {} (it is the same file)",
            input.display()
        ),
    )
}

/// Refuse `output` if it is the same file as one of `inputs` (checked before any work, so
/// that nothing is computed for an output that cannot be written).
pub fn refuse_same_file(output: &Path, inputs: &[&Path]) -> Result<()> {
    match inputs.iter().find(|i| same_file(output, i)) {
        Some(input) => Err(would_overwrite(output, input)),
        None => Ok(()),
    }
}

/// Refuse `output` if it is (or is a link to) a file this process has read.
pub fn check_output(output: &Path) -> Result<()> {
    let inputs = lock(&INPUTS);
    // The file a symbolic link points to, and the link itself (which the rename would
    // replace).
    let followed = FileId::at(output);
    let link = std::fs::symlink_metadata(output)
        .ok()
        .map(|m| FileId::of(&m, output));
    for (id, path) in inputs.iter() {
        if followed.as_ref().is_some_and(|f| f.same(id))
            || link.as_ref().is_some_and(|l| l.same(id))
        {
            return Err(would_overwrite(output, path));
        }
    }
    Ok(())
}

/// Delete every named temporary file of this process that exists right now, and keep any
/// other from being created or moved into place: for a signal handler that is about to
/// end the process (after this call, [`PendingFile::create`] and [`PendingFile::commit`]
/// block forever).
pub fn remove_in_flight_files() {
    let guard = lock(&IN_FLIGHT);
    for path in guard.iter() {
        let _ = std::fs::remove_file(path);
    }
    // Held until the process ends.
    std::mem::forget(guard);
}

/// Whether `VISADAPT_NAMED_TEMPORARIES` asks for named temporary files only.
#[cfg(target_os = "linux")]
fn named_temporaries_forced() -> bool {
    std::env::var_os("VISADAPT_NAMED_TEMPORARIES").is_some_and(|v| !v.is_empty() && v != "0")
}

/// The directory a file at `path` goes into.
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// A named temporary file beside `target`, listed in [`IN_FLIGHT`] until dropped.
#[derive(Debug)]
struct NamedTemp {
    path: PathBuf,
}

impl NamedTemp {
    /// Create it with `0666` less the umask (the mode the finished file keeps).
    fn create(dir: &Path) -> Result<(File, Self)> {
        let mut in_flight = lock(&IN_FLIGHT);
        let mut builder = tempfile::Builder::new();
        builder.prefix(".visadapt-").suffix(".tmp");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let (file, path) = builder
            .tempfile_in(dir)?
            .keep()
            .map_err(|e| Error::Io(e.error))?;
        in_flight.push(path.clone());
        Ok((file, NamedTemp { path }))
    }

    /// Rename over `target`; the temporary name is gone either way.
    fn rename_to(self, target: &Path) -> Result<()> {
        let result = std::fs::rename(&self.path, target);
        drop(self);
        Ok(result?)
    }
}

impl Drop for NamedTemp {
    fn drop(&mut self) {
        let mut in_flight = lock(&IN_FLIGHT);
        let _ = std::fs::remove_file(&self.path);
        in_flight.retain(|p| *p != self.path);
    }
}

/// An output file being written: complete it with [`PendingFile::commit`]; dropping it
/// removes it.
#[derive(Debug)]
pub struct PendingFile {
    file: File,
    target: PathBuf,
    /// `None`: an unnamed (`O_TMPFILE`) file.
    named: Option<NamedTemp>,
}

impl PendingFile {
    /// Start writing the file that will appear at `target`. Refuses a `target` that is an
    /// input of this process ([`check_output`]).
    pub fn create(target: &Path) -> Result<Self> {
        check_output(target)?;
        let dir = parent_dir(target);
        // Name the folder the caller gave, not a temporary file's random name.
        if !dir.is_dir() {
            return Err(Error::Io(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("the output folder {} does not exist", dir.display()),
            )));
        }
        #[cfg(target_os = "linux")]
        if !named_temporaries_forced()
            && let Some(file) = unnamed::create(dir)
        {
            return Ok(PendingFile {
                file,
                target: target.to_path_buf(),
                named: None,
            });
        }
        let (file, named) = NamedTemp::create(dir)?;
        Ok(PendingFile {
            file,
            target: target.to_path_buf(),
            named: Some(named),
        })
    }

    /// The file to write into.
    pub fn file(&self) -> &File {
        &self.file
    }

    /// Flush the file to disk and move it into place, replacing any file at the target
    /// (whose permission bits it takes, less setuid, setgid and sticky).
    pub fn commit(self) -> Result<()> {
        let PendingFile {
            mut file,
            target,
            named,
        } = self;
        check_output(&target)?;
        #[cfg(unix)]
        if let Ok(old) = std::fs::metadata(&target) {
            use std::os::unix::fs::PermissionsExt;
            let mode = old.permissions().mode() & 0o777;
            file.set_permissions(std::fs::Permissions::from_mode(mode))?;
        }
        file.flush()?;
        file.sync_all()?;
        if let Some(named) = named {
            return named.rename_to(&target);
        }
        #[cfg(target_os = "linux")]
        {
            if unnamed::link(&file, &target)? {
                return Ok(());
            }
            // The unnamed file cannot be given a name here (no /proc, no privilege):
            // copy it into a named one.
            let (mut copy, named) = NamedTemp::create(parent_dir(&target))?;
            file.rewind()?;
            std::io::copy(&mut file, &mut copy)?;
            copy.sync_all()?;
            named.rename_to(&target)
        }
        #[cfg(not(target_os = "linux"))]
        unreachable!("unnamed files exist only on Linux")
    }
}

/// Unnamed files: `O_TMPFILE`, named with `linkat` (through the safe `rustix` wrappers).
#[cfg(target_os = "linux")]
mod unnamed {
    use super::{IN_FLIGHT, NamedTemp, lock};
    use crate::Result;
    use rustix::fs::{AtFlags, CWD, Mode, OFlags};
    use std::fs::File;
    use std::os::fd::AsRawFd;
    use std::path::Path;

    /// An unnamed regular file in `dir`, mode `0666` less the umask; `None` where the
    /// kernel or the file system does not offer them.
    pub(super) fn create(dir: &Path) -> Option<File> {
        let flags = OFlags::TMPFILE | OFlags::WRONLY | OFlags::CLOEXEC;
        rustix::fs::openat(CWD, dir, flags, Mode::from_raw_mode(0o666))
            .ok()
            .map(File::from)
    }

    /// Give `file` the name `target`: directly when nothing is there (atomic, no window
    /// at all), else under a temporary name renamed over `target`. `Ok(false)` when the
    /// kernel refuses to name it at all.
    pub(super) fn link(file: &File, target: &Path) -> Result<bool> {
        let proc_path = format!("/proc/self/fd/{}", file.as_raw_fd());
        let name_it = |to: &Path| -> std::io::Result<()> {
            rustix::fs::linkat(CWD, proc_path.as_str(), CWD, to, AtFlags::SYMLINK_FOLLOW)
                .or_else(|_| rustix::fs::linkat(file, "", CWD, to, AtFlags::EMPTY_PATH))
                .map_err(std::io::Error::from)
        };
        match name_it(target) {
            Ok(()) => return Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(_) => return Ok(false),
        }
        // Replace an existing file: link under a fresh temporary name, then rename.
        let dir = super::parent_dir(target);
        for attempt in 0..16u32 {
            let tmp = dir.join(format!(
                ".visadapt-{}-{}-{attempt}.tmp",
                std::process::id(),
                unique()
            ));
            let named = {
                let mut in_flight = lock(&IN_FLIGHT);
                match name_it(&tmp) {
                    Ok(()) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                    Err(_) => return Ok(false),
                }
                in_flight.push(tmp.clone());
                NamedTemp { path: tmp }
            };
            named.rename_to(target)?;
            return Ok(true);
        }
        Ok(false)
    }

    /// A number that differs between calls of this process.
    fn unique() -> u64 {
        use std::sync::atomic::{AtomicU64, Ordering};
        static NEXT: AtomicU64 = AtomicU64::new(0);
        NEXT.fetch_add(1, Ordering::Relaxed)
    }
}
