//! File access: every input file the crate reads and every output file it writes goes
//! through this module, so that the rules below hold everywhere.
//!
//! # Inputs
//!
//! Only regular files are read. [`open_regular`] looks at the path first (`stat`, which
//! follows symbolic links) and refuses a FIFO, a device, a directory or a socket before
//! opening it, naming what it is ("is a FIFO, not a regular file"); it then opens with
//! `O_NONBLOCK | O_NOCTTY`, so that even a path swapped for a FIFO in between cannot block
//! the open (on a regular file the flags change nothing), and checks the opened handle
//! again (`fstat`). `/dev/zero`, `/dev/stdin`, a symbolic link to either and a FIFO are
//! all refused before a byte is read.
//!
//! Reads are bounded: [`read_input`] refuses a file larger than the limit its caller
//! states, before reading, and reads at most the file's size at open plus one byte, so a
//! file that grows while it is read is refused rather than followed. The limits are
//! constants ([`MAX_INPUT_BYTES`] for mesh files, [`MAX_TEXT_BYTES`] for scene files and
//! manifests) rather than `--max-memory`: the loaders (the mesh module's `load_mesh`, the
//! scene module's `load_scene`) are called from scene parsing and from every command
//! without a budget, and a file's bytes are a small part of what loading it builds (that
//! is what the budget's estimates count). Grid files are streamed, not read whole: their
//! header states the size, checked against the file's length before anything is read.
//!
//! Files named *by* an input that comes from a stranger (a glTF file's external buffers)
//! must lie in that input's folder after `..` and symbolic links are resolved
//! ([`resolve_inside`]). Files named by the user's own files (a scene's mesh `path`, the
//! hard-case manifest's inputs) may lie anywhere, but are read by the same rules.
//!
//! # Outputs
//!
//! [`write_atomic`] writes to a temporary file in the target's folder (`.NAME.tmp-PID-N`),
//! syncs it and renames it over the target, so a failure leaves the target as it was; the
//! temporary file is removed on every failure. It refuses to replace anything that is not
//! a regular file (`-o /dev/null`, `-o /dev/full`, a directory, a FIFO): the refusal comes
//! before the temporary file is created, and is checked again just before the rename.
//!
//! A symbolic link as the output is written *through*: the links of the last path
//! component are followed and the temporary file is renamed over the file the link points
//! to, so the link stays a link and readers of the link see the new content (what a
//! shell's `>` does). A dangling link creates its target. The alternative, replacing the
//! link with a regular file, would silently detach whatever the link was for.
//!
//! [`check_outputs`] refuses a command whose output is one of its inputs (or two outputs
//! that are one file), comparing device and inode where the file exists and the canonical
//! path where it does not, so links and `..` do not hide a match, and an output that is
//! there but not a regular file. `main.rs` calls it once for every command, where the
//! command line is turned into options, before any work. Files an input names (a scene's
//! meshes and grids, a glTF file's buffers) are known only once it is read: after
//! [`protect_inputs`] (which `main.rs` calls; a library user's process, which may well save
//! over a file it loaded earlier, is not affected) every file [`open_regular`] opens is
//! remembered (device and inode), and [`write_atomic`] and [`check_not_read`] refuse to
//! replace one of them.

use std::fs::{self, File, FileType, Metadata, OpenOptions};
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};

use crate::error::{Error, Result};

/// Largest mesh file read into memory: 4 GiB (about 80 million triangles of binary STL).
pub const MAX_INPUT_BYTES: u64 = 4 << 30;

/// Largest text file (scene, manifest) read: 64 MiB.
pub const MAX_TEXT_BYTES: u64 = 64 << 20;

/// Most symbolic links followed when resolving an output path (as Linux's `MAXSYMLINKS`).
const MAX_LINKS: usize = 40;

/// Why a file of type `ft` cannot be read or replaced as a regular file, or `None` when it
/// is one.
fn not_regular(ft: FileType) -> Option<&'static str> {
    if ft.is_file() {
        return None;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return Some("is a FIFO, not a regular file");
        }
        if ft.is_char_device() {
            return Some("is a character device, not a regular file");
        }
        if ft.is_block_device() {
            return Some("is a block device, not a regular file");
        }
        if ft.is_socket() {
            return Some("is a socket, not a regular file");
        }
    }
    Some(if ft.is_dir() { "is a directory, not a regular file" } else { "is not a regular file" })
}

/// `Err` naming what `meta` is when it is not a regular file.
fn require_regular(meta: &Metadata) -> io::Result<()> {
    match not_regular(meta.file_type()) {
        None => Ok(()),
        Some(what) => Err(io::Error::other(what)),
    }
}

/// Opens `path` for reading when it is a regular file (after following links), without
/// ever blocking; returns the file and its size. See the module documentation.
///
/// # Errors
/// The open's own errors, or one naming what the file is instead of a regular file.
pub fn open_regular(path: &Path) -> io::Result<(File, u64)> {
    require_regular(&fs::metadata(path)?)?;
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    require_regular(&meta)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        remember_read(FileId::Inode(meta.dev(), meta.ino()));
    }
    Ok((file, meta.len()))
}

/// Every file [`open_regular`] opened since [`protect_inputs`] (few: the inputs of one
/// command); `None` before it, when nothing is remembered.
static READ: Mutex<Option<Vec<FileId>>> = Mutex::new(None);

/// The files read, locked (a panic while it was held leaves it as usable as before).
fn read_files() -> std::sync::MutexGuard<'static, Option<Vec<FileId>>> {
    READ.lock().unwrap_or_else(PoisonError::into_inner)
}

/// From now on, no file this process reads may be written by it (one command's process:
/// its inputs, including the files they name, are never its outputs).
pub fn protect_inputs() {
    read_files().get_or_insert_with(Vec::new);
}

fn remember_read(id: FileId) {
    if let Some(read) = read_files().as_mut()
        && !read.contains(&id)
    {
        read.push(id);
    }
}

/// Refuses `path` as an output when this process has read it as an input (a scene's mesh
/// or grid file, a glTF buffer: inputs that the command line does not name).
///
/// # Errors
/// [`Error::Usage`] naming `path`.
pub fn check_not_read(path: &Path) -> Result<()> {
    if read_files().is_none() {
        return Ok(());
    }
    let Some(id) = file_id(path) else { return Ok(()) };
    if read_files().as_ref().is_some_and(|read| read.contains(&id)) {
        return Err(Error::Usage(format!(
            "{}: the output is a file this command read as an input; refusing to overwrite an input",
            path.display()
        )));
    }
    Ok(())
}

/// [`open_regular`], with errors naming `path` ("PATH: cannot read: ...").
pub fn open_input(path: &Path) -> Result<(File, u64)> {
    open_regular(path).map_err(|e| read_error(path, e))
}

/// The error for a failed read of `path`.
fn read_error(path: &Path, e: io::Error) -> Error {
    Error::io(path, format!("cannot read: {e}"))
}

/// Reads at most `max` bytes of an opened file of size `len`, refusing a file that turns
/// out longer than `len` when `whole`.
fn read_bounded(file: File, len: u64, max: u64, whole: bool) -> io::Result<Vec<u8>> {
    let want = len.min(max);
    let mut out = Vec::new();
    out.try_reserve_exact(want as usize)
        .map_err(|_| io::Error::other(format!("cannot hold {want} bytes")))?;
    let extra = u64::from(whole);
    file.take(want + extra).read_to_end(&mut out)?;
    if out.len() as u64 > want {
        return Err(io::Error::other(format!("the file grew while it was read (from {len} bytes)")));
    }
    Ok(out)
}

/// The whole of the regular file `path`, refused when larger than `limit` bytes.
///
/// # Errors
/// As [`open_regular`]; also when the file is larger than `limit` or grows while read.
pub fn read_regular(path: &Path, limit: u64) -> io::Result<Vec<u8>> {
    let (file, len) = open_regular(path)?;
    if len > limit {
        return Err(io::Error::other(format!(
            "the file is {len} bytes, more than the limit of {limit} bytes"
        )));
    }
    read_bounded(file, len, len, true)
}

/// The first `max` bytes of the regular file `path` (all of it when shorter); bytes past
/// `max` are never read.
///
/// # Errors
/// As [`open_regular`].
pub fn read_regular_prefix(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    let (file, len) = open_regular(path)?;
    read_bounded(file, len, max, false)
}

/// [`read_regular`], with errors naming `path` ("PATH: cannot read: ...").
pub fn read_input(path: &Path, limit: u64) -> Result<Vec<u8>> {
    read_regular(path, limit).map_err(|e| read_error(path, e))
}

/// [`read_input`] as UTF-8 text.
///
/// # Errors
/// As [`read_input`]; [`Error::Input`] giving the offset of the first byte that is not
/// UTF-8 (never the bytes themselves).
pub fn read_input_text(path: &Path, limit: u64) -> Result<String> {
    String::from_utf8(read_input(path, limit)?).map_err(|e| {
        Error::input(
            path,
            None,
            format!("not UTF-8 text: invalid byte at offset {}", e.utf8_error().valid_up_to()),
        )
    })
}

/// `folder.join(relative)` with `..` and symbolic links resolved, when that is a regular
/// file inside `folder` (also resolved); for the files a stranger's file names (glTF
/// buffers), which must not reach out of its folder.
///
/// # Errors
/// When the file does not exist, is not a regular file (wherever it is), or lies outside
/// `folder`; the message names the folder, never the file's content.
pub fn resolve_inside(folder: &Path, relative: &Path) -> io::Result<PathBuf> {
    let folder = if folder.as_os_str().is_empty() { Path::new(".") } else { folder };
    let root = folder.canonicalize()?;
    let real = folder.join(relative).canonicalize()?;
    require_regular(&fs::metadata(&real)?)?;
    if !real.starts_with(&root) {
        return Err(io::Error::other(format!(
            "resolves to a file outside the folder {} (external files must lie in the folder of \
             the file that names them)",
            root.display()
        )));
    }
    Ok(real)
}

// ---------------------------------------------------------------- outputs

/// `path` with the symbolic links of its last component followed: the file a write to
/// `path` should replace (`path` itself when it is not a link or does not exist).
fn resolve_links(path: &Path) -> io::Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) => dir.join(link),
                    None => link,
                };
            }
            Ok(_) => return Ok(p),
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(p),
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::other("too many levels of symbolic links"))
}

/// `Ok` when `target` (no link) does not exist or is a regular file.
fn require_replaceable(target: &Path) -> io::Result<()> {
    match fs::symlink_metadata(target) {
        Ok(m) => require_regular(&m),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
}

/// The folder of `path` (`.` for a bare file name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes a file through `body` to a temporary file in the target's folder and renames it
/// over `path` (through a symbolic link, to the file it points to); see the module
/// documentation. On failure the temporary file is removed and the target is untouched.
///
/// # Errors
/// [`Error::Io`] naming `path` when its folder does not exist, the target is not a regular
/// file, or writing, syncing or renaming fails.
pub fn write_atomic(path: &Path, body: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>) -> Result<()> {
    let fail = |e: &dyn std::fmt::Display| Error::io(path, format!("cannot write: {e}"));
    let target = resolve_links(path).map_err(|e| fail(&e))?;
    require_replaceable(&target).map_err(|e| fail(&e))?;
    check_not_read(&target)?;
    let name = target.file_name().ok_or_else(|| fail(&"the path names no file"))?;
    let dir = folder_of(&target);
    if !dir.is_dir() {
        return Err(fail(&format_args!("the directory does not exist ({})", dir.display())));
    }
    let tmp = dir.join(format!(
        ".{}.tmp-{}-{}",
        name.to_string_lossy(),
        std::process::id(),
        TMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let file = OpenOptions::new().write(true).create_new(true).open(&tmp).map_err(|e| fail(&e))?;
    let result = (|| {
        let mut w = BufWriter::with_capacity(1 << 16, file);
        body(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        // Again, just before the rename: the target may have changed while we wrote.
        require_replaceable(&target)?;
        fs::rename(&tmp, &target)
    })();
    result.map_err(|e| {
        let _ = fs::remove_file(&tmp);
        fail(&e)
    })
}

/// [`write_atomic`] of `bytes`.
pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// What identifies a file: device and inode where it exists, else the canonical path it
/// would be created at.
#[derive(Debug, PartialEq, Eq)]
enum FileId {
    #[cfg(unix)]
    Inode(u64, u64),
    Path(PathBuf),
}

fn file_id(path: &Path) -> Option<FileId> {
    #[cfg(unix)]
    if let Ok(m) = fs::metadata(path) {
        use std::os::unix::fs::MetadataExt;
        return Some(FileId::Inode(m.dev(), m.ino()));
    }
    if let Ok(p) = path.canonicalize() {
        return Some(FileId::Path(p));
    }
    // Not there (or a dangling link): where a write would create it.
    let target = resolve_links(path).ok()?;
    let dir = folder_of(&target).canonicalize().ok()?;
    Some(FileId::Path(dir.join(target.file_name()?)))
}

/// Refuses `outputs` of one command when one of them is one of its `inputs` or two of
/// them are the same file, after resolving links (see the module documentation), or when
/// one is there but not a regular file (writers that append, such as `compare`'s CSV,
/// would otherwise block on a FIFO or write into a device).
///
/// # Errors
/// [`Error::Usage`] naming both paths; [`Error::Io`] naming an output that is not a
/// regular file.
pub fn check_outputs(inputs: &[&Path], outputs: &[&Path]) -> Result<()> {
    let inputs: Vec<(&Path, FileId)> = inputs.iter().filter_map(|p| Some((*p, file_id(p)?))).collect();
    let mut seen: Vec<(&Path, FileId)> = Vec::new();
    for &out in outputs {
        resolve_links(out)
            .and_then(|target| require_replaceable(&target))
            .map_err(|e| Error::io(out, format!("cannot write: {e}")))?;
        let Some(id) = file_id(out) else { continue };
        if let Some((input, _)) = inputs.iter().find(|(_, i)| *i == id) {
            return Err(Error::Usage(format!(
                "{}: the output is the input {} of this command; refusing to overwrite an input",
                out.display(),
                input.display()
            )));
        }
        if let Some((other, _)) = seen.iter().find(|(_, i)| *i == id) {
            return Err(Error::Usage(format!(
                "{}: the output is also the output {}; give each output its own file",
                out.display(),
                other.display()
            )));
        }
        seen.push((out, id));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_at_most_the_limit_and_names_devices() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        fs::write(&p, b"hello").unwrap();
        assert_eq!(read_regular(&p, 5).unwrap(), b"hello");
        let e = read_regular(&p, 4).unwrap_err().to_string();
        assert!(e.contains("5 bytes, more than the limit of 4"), "{e}");
        assert_eq!(read_regular_prefix(&p, 2).unwrap(), b"he");
        assert_eq!(read_regular_prefix(&p, 99).unwrap(), b"hello");
        let e = read_regular(dir.path(), 99).unwrap_err().to_string();
        assert_eq!(e, "is a directory, not a regular file");
        #[cfg(unix)]
        {
            let e = read_regular(Path::new("/dev/zero"), u64::MAX).unwrap_err().to_string();
            assert_eq!(e, "is a character device, not a regular file");
        }
        let e = read_input_text(&p.with_file_name("missing"), 9).unwrap_err().to_string();
        assert!(e.contains("missing: cannot read:"), "{e}");
        fs::write(&p, b"ok\xFF").unwrap();
        let e = read_input_text(&p, 9).unwrap_err().to_string();
        assert!(e.ends_with("not UTF-8 text: invalid byte at offset 2"), "{e}");
    }

    #[test]
    fn resolve_inside_keeps_to_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let inner = dir.path().join("model");
        fs::create_dir(&inner).unwrap();
        fs::write(inner.join("a.bin"), b"x").unwrap();
        fs::write(dir.path().join("b.bin"), b"x").unwrap();
        assert!(resolve_inside(&inner, Path::new("a.bin")).is_ok());
        assert!(resolve_inside(&inner, Path::new("./../model/a.bin")).is_ok());
        let e = resolve_inside(&inner, Path::new("../b.bin")).unwrap_err().to_string();
        assert!(e.contains("outside the folder"), "{e}");
        let abs = dir.path().join("b.bin");
        assert!(resolve_inside(&inner, &abs).unwrap_err().to_string().contains("outside"));
    }

    #[test]
    fn outputs_are_not_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.toml");
        fs::write(&a, b"x").unwrap();
        let dotted = dir.path().join(".").join("a.toml");
        assert!(check_outputs(&[&a], &[&dotted]).is_err());
        let b = dir.path().join("b.csv");
        assert!(check_outputs(&[&a], &[&b]).is_ok());
        // Two outputs that do not exist yet, one through `..`.
        let sub = dir.path().join("sub");
        fs::create_dir(&sub).unwrap();
        let b2 = sub.join("..").join("b.csv");
        let e = check_outputs(&[&a], &[&b, &b2]).unwrap_err();
        assert!(e.to_string().contains("also the output"), "{e}");
        assert_eq!(e.exit_code(), 2);
        let e = check_outputs(&[&a], &[dir.path()]).unwrap_err().to_string();
        assert!(e.ends_with("cannot write: is a directory, not a regular file"), "{e}");
    }
}
