//! Atomic writes: an interrupted run leaves either the old file (or report directory) or the
//! new one, never a torn one or a mix of both. Every result file of the crate goes through here.
//!
//! # Temporary names
//!
//! Everything in flight sits beside its target under a recognisable name:
//! `.<name>.tmp-<pid>-<n>` for a file or directory being written, `.<name>.old-<pid>-<n>` for an
//! old directory moved aside (only on the fallback path of [`replace_dir`]), where `<pid>` is the
//! writing process and `<n>` a counter within it. A process killed with `kill -9` cannot remove
//! its own; the next write to the same target removes every such entry that is *stale*: its pid
//! no longer runs (on Unix), or it is older than an hour whatever its pid (a reused pid, or a
//! platform where liveness cannot be asked). The temporary names of earlier versions
//! (`.<name>.tmp.<pid>`) are recognised and cleaned the same way.

use crate::error::{Error, Result};
use std::ffi::{OsStr, OsString};
use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// A temporary older than this is stale even if a process with its pid runs (pids are reused).
/// No write of this crate takes anywhere near as long.
const STALE_AGE: Duration = Duration::from_secs(3600);

/// Distinguishes the temporaries of one process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// readers see either the old file or the complete new one, never a torn write. Stale
/// temporaries of `path` left by killed writers are removed first (see the module docs).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    fs::create_dir_all(dir).map_err(|e| Error::io(dir.display(), &e))?;
    let name = path.file_name().ok_or_else(|| Error::Io {
        path: path.display().to_string(),
        message: "not a file path".into(),
    })?;
    clean_stale(dir, name);
    let tmp = dir.join(temp_name(name, Kind::Staging, std::process::id(), next()));
    let write = || -> io::Result<()> {
        let mut f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        fs::rename(&tmp, path)?;
        sync_dir(dir);
        Ok(())
    };
    write().map_err(|e| {
        let _ = fs::remove_file(&tmp);
        Error::io(path.display(), &e)
    })
}

/// The files of one report directory, each written with [`write_atomic`] and remembered, so
/// that a report writer can return every path it wrote.
#[derive(Debug)]
pub struct ReportFiles {
    dir: PathBuf,
    written: Vec<PathBuf>,
}

impl ReportFiles {
    /// Files to be written into `dir` (which must exist).
    pub fn new(dir: &Path) -> Self {
        ReportFiles {
            dir: dir.to_path_buf(),
            written: Vec::new(),
        }
    }

    /// Writes `dir/name` atomically.
    ///
    /// # Errors
    ///
    /// As [`write_atomic`].
    pub fn put(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        let path = self.dir.join(name);
        write_atomic(&path, bytes)?;
        self.written.push(path);
        Ok(())
    }

    /// Adds paths written by other means (figures).
    pub fn extend(&mut self, paths: impl IntoIterator<Item = PathBuf>) {
        self.written.extend(paths);
    }

    /// Every path written, in order.
    pub fn into_paths(self) -> Vec<PathBuf> {
        self.written
    }
}

/// Replaces the directory `target` as a unit by the one `fill` writes, and returns what `fill`
/// returned. Afterwards `target` holds exactly what `fill` wrote; whenever the process is
/// killed, `target` holds either its old content, complete, or the new one, complete.
///
/// `fill` writes into a fresh temporary directory beside `target` (same parent, so the same
/// filesystem); it is synced, then swapped in:
///
/// - `target` absent: a plain rename.
/// - Linux, Android and Apple systems: an atomic exchange of the two directories
///   (`renameat2(RENAME_EXCHANGE)`, `renameatx_np(RENAME_SWAP)`), then the old content, now
///   under the temporary name, is removed.
/// - elsewhere, or where the filesystem refuses the exchange: the old directory is renamed
///   aside (`.<name>.old-<pid>-<n>`), then the new one renamed in. A kill between these two
///   renames leaves no directory at `target` for that short window, with both complete
///   directories beside it; the next write to `target` (or [`prepare_dir`]) finishes the swap
///   (it renames the new one in) before anything else.
///
/// An error from `fill` or from the swap leaves `target` as it was and removes the temporary.
/// `target` must not be the root directory, nor the current directory or one holding it (the
/// process would be left in a deleted directory), nor an existing non-directory; a symbolic link
/// to a directory is followed (the directory it names is replaced, the link kept). Every error
/// names `target` as given.
pub fn replace_dir<T>(target: &Path, fill: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
    replace_dir_with(target, fill, Swap::Exchange)
}

/// Checks, before a long computation, that [`replace_dir`] could replace `target`: the checks
/// of [`replace_dir`], and that a temporary directory can be created beside it (created and
/// removed again; `target` itself is neither created nor touched). Removes stale temporaries of
/// `target` and finishes a swap that a killed writer left half-done.
pub fn prepare_dir(target: &Path) -> Result<()> {
    let t = DirTarget::resolve(target)?;
    t.clean();
    let probe = t.temp(Kind::Staging, next());
    fs::create_dir(&probe).map_err(|e| t.error(&e))?;
    remove_any(&probe);
    Ok(())
}

/// Whether `name` is one of the temporary names of this module (for any target); see the
/// module docs. What carries such a name is debris of a write, never a result.
pub fn is_temp_name(name: &OsStr) -> bool {
    let Some(name) = name.to_str() else {
        return false;
    };
    let Some(rest) = name.strip_prefix('.') else {
        return false;
    };
    ["tmp-", "old-", "tmp."].iter().any(|marker| {
        rest.match_indices(&format!(".{marker}"))
            .any(|(i, _)| i > 0 && parse_temp(name, &rest[..i]).is_some())
    })
}

/// How [`replace_dir_with`] swaps an existing directory.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Swap {
    /// Atomic exchange where the platform and filesystem allow it, else [`Swap::Aside`].
    Exchange,
    /// Rename the old directory aside, then the new one in (the portable fallback, which
    /// [`Swap::Exchange`] falls back to by itself; chosen directly only by the tests).
    #[cfg_attr(not(test), allow(dead_code))]
    Aside,
}

fn replace_dir_with<T>(
    target: &Path,
    fill: impl FnOnce(&Path) -> Result<T>,
    swap: Swap,
) -> Result<T> {
    let t = DirTarget::resolve(target)?;
    t.clean();
    let n = next();
    let staging = t.temp(Kind::Staging, n);
    fs::create_dir(&staging).map_err(|e| t.error(&e))?;
    let value = match fill(&staging) {
        Ok(value) => value,
        Err(e) => {
            remove_any(&staging);
            return Err(e);
        }
    };
    sync_dir(&staging);
    if let Err(e) = t.swap_in(&staging, n, swap) {
        remove_any(&staging);
        return Err(t.error(&e));
    }
    Ok(value)
}

/// Why the root (or a path ending in `..` that does not exist) cannot be replaced.
const ROOT: &str = "names no directory of its own (the root, or a path ending in `..`); a \
                    report directory is replaced as a whole, so give one of its own";

/// A directory to be replaced: where it is, and how errors name it.
struct DirTarget {
    /// The path as the user gave it, for messages.
    shown: PathBuf,
    /// The directory holding it (symbolic links, `.` and `..` resolved where it exists).
    parent: PathBuf,
    /// Its name in `parent`.
    name: OsString,
}

impl DirTarget {
    fn resolve(target: &Path) -> Result<DirTarget> {
        let fail = |message: &str| Error::Io {
            path: target.display().to_string(),
            message: message.to_string(),
        };
        if target.as_os_str().is_empty() {
            return Err(fail("an empty path names no directory"));
        }
        let resolved = match fs::symlink_metadata(target) {
            Ok(_) => {
                let real = fs::canonicalize(target).map_err(|e| Error::io(target.display(), &e))?;
                if !fs::metadata(&real)
                    .map_err(|e| Error::io(target.display(), &e))?
                    .is_dir()
                {
                    return Err(fail("exists and is not a directory"));
                }
                if real.parent().is_none() {
                    return Err(fail(ROOT));
                }
                let cwd = std::env::current_dir().and_then(fs::canonicalize);
                if cwd.is_ok_and(|cwd| cwd.starts_with(&real)) {
                    return Err(fail(
                        "is the current directory or holds it; a report directory is replaced \
                         as a whole, so give one of its own",
                    ));
                }
                real
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => target.to_path_buf(),
            Err(e) => return Err(Error::io(target.display(), &e)),
        };
        let Some(name) = resolved.file_name() else {
            return Err(fail(ROOT));
        };
        let parent = match resolved.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        fs::create_dir_all(&parent).map_err(|e| Error::io(target.display(), &e))?;
        Ok(DirTarget {
            shown: target.to_path_buf(),
            parent,
            name: name.to_os_string(),
        })
    }

    fn path(&self) -> PathBuf {
        self.parent.join(&self.name)
    }

    fn temp(&self, kind: Kind, n: u64) -> PathBuf {
        self.parent
            .join(temp_name(&self.name, kind, std::process::id(), n))
    }

    fn error(&self, e: &io::Error) -> Error {
        Error::io(self.shown.display(), e)
    }

    fn clean(&self) {
        clean_stale(&self.parent, &self.name);
    }

    /// Puts the complete directory `staging` (temporary number `n`) at the target.
    fn swap_in(&self, staging: &Path, n: u64, swap: Swap) -> io::Result<()> {
        let target = self.path();
        let old = match fs::symlink_metadata(&target) {
            Ok(m) => m,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                fs::rename(staging, &target)?;
                sync_dir(&self.parent);
                return Ok(());
            }
            Err(e) => return Err(e),
        };
        if !old.is_dir() {
            return Err(io::Error::other("exists and is not a directory"));
        }
        // The new directory takes the old one's permissions, as an in-place rewrite would.
        let _ = fs::set_permissions(staging, old.permissions());
        if swap == Swap::Exchange && exchange(staging, &target)? {
            sync_dir(&self.parent);
            // The old content is now at the temporary name; a kill while removing it leaves a
            // stale temporary that the next write removes.
            remove_any(staging);
            return Ok(());
        }
        let aside = self.temp(Kind::Aside, n);
        fs::rename(&target, &aside)?;
        // The window: no directory at the target until the next rename. A kill here leaves both
        // complete directories beside it, and `clean_stale` renames `staging` in.
        if let Err(e) = fs::rename(staging, &target) {
            let _ = fs::rename(&aside, &target);
            return Err(e);
        }
        sync_dir(&self.parent);
        remove_any(&aside);
        Ok(())
    }
}

/// Atomically exchanges the directories `a` and `b`; `Ok(false)` where the platform or the
/// filesystem cannot.
#[cfg(any(target_os = "linux", target_os = "android", target_vendor = "apple"))]
fn exchange(a: &Path, b: &Path) -> io::Result<bool> {
    use rustix::fs::{CWD, RenameFlags, renameat_with};
    use rustix::io::Errno;
    match renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE) {
        Ok(()) => Ok(true),
        Err(e) if e == Errno::INVAL || e == Errno::NOSYS => Ok(false),
        Err(e) => {
            let e = io::Error::from(e);
            if e.kind() == io::ErrorKind::Unsupported {
                Ok(false)
            } else {
                Err(e)
            }
        }
    }
}

#[cfg(not(any(target_os = "linux", target_os = "android", target_vendor = "apple")))]
fn exchange(_: &Path, _: &Path) -> io::Result<bool> {
    Ok(false)
}

/// The two kinds of temporaries.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// A file or directory being written: `.<name>.tmp-<pid>-<n>`.
    Staging,
    /// An old directory moved aside: `.<name>.old-<pid>-<n>`.
    Aside,
}

fn next() -> u64 {
    COUNTER.fetch_add(1, Ordering::Relaxed)
}

fn temp_name(name: &OsStr, kind: Kind, pid: u32, n: u64) -> OsString {
    let mut s = OsString::from(".");
    s.push(name);
    s.push(match kind {
        Kind::Staging => format!(".tmp-{pid}-{n}"),
        Kind::Aside => format!(".old-{pid}-{n}"),
    });
    s
}

/// A temporary of a given target, parsed from its name.
#[derive(Debug, Clone, PartialEq)]
struct Temp {
    kind: Kind,
    pid: u32,
    /// `None` for the legacy `.<name>.tmp.<pid>`.
    n: Option<u64>,
}

/// Parses `entry` as a temporary of the target called `name`.
fn parse_temp(entry: &str, name: &str) -> Option<Temp> {
    let rest = entry.strip_prefix('.')?.strip_prefix(name)?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if let Some(pid) = rest.strip_prefix(".tmp.") {
        return digits(pid)
            .then(|| pid.parse().ok())
            .flatten()
            .map(|pid| Temp {
                kind: Kind::Staging,
                pid,
                n: None,
            });
    }
    let (kind, rest) = if let Some(r) = rest.strip_prefix(".tmp-") {
        (Kind::Staging, r)
    } else {
        (Kind::Aside, rest.strip_prefix(".old-")?)
    };
    let (pid, n) = rest.split_once('-')?;
    if !digits(pid) || !digits(n) {
        return None;
    }
    Some(Temp {
        kind,
        pid: pid.parse().ok()?,
        n: Some(n.parse().ok()?),
    })
}

/// Removes the stale temporaries of `dir/name` (see the module docs), after finishing a
/// fallback swap that a killed writer left without a directory at the target. Best effort:
/// what cannot be removed stays for the next write.
fn clean_stale(dir: &Path, name: &OsStr) {
    let Some(name_str) = name.to_str() else {
        return;
    };
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    let mut stale: Vec<(PathBuf, Temp)> = entries
        .flatten()
        .filter_map(|e| {
            let temp = parse_temp(e.file_name().to_str()?, name_str)?;
            let path = e.path();
            is_stale(&path, temp.pid).then_some((path, temp))
        })
        .collect();
    stale.sort_by_key(|(_, t)| (t.pid, t.n));
    let target = dir.join(name);
    if fs::symlink_metadata(&target).is_err_and(|e| e.kind() == io::ErrorKind::NotFound) {
        // Only the fallback swap leaves an old directory aside, and only once the new one is
        // complete: put the new one in, or failing that the old one back.
        let asides: Vec<Temp> = stale
            .iter()
            .filter(|(_, t)| t.kind == Kind::Aside)
            .map(|(_, t)| t.clone())
            .collect();
        for aside in asides.iter().rev() {
            let new = stale
                .iter()
                .find(|(_, t)| t.kind == Kind::Staging && t.pid == aside.pid && t.n == aside.n);
            let old = stale.iter().find(|(_, t)| t == aside);
            let restored = [new, old]
                .into_iter()
                .flatten()
                .find(|(path, _)| fs::rename(path, &target).is_ok());
            if let Some((path, _)) = restored.cloned() {
                stale.retain(|(p, _)| *p != path);
                sync_dir(dir);
                break;
            }
        }
    }
    for (path, _) in stale {
        remove_any(&path);
    }
}

/// Whether the temporary at `path`, written by process `pid`, is stale.
fn is_stale(path: &Path, pid: u32) -> bool {
    let old = fs::symlink_metadata(path)
        .and_then(|m| m.modified())
        .is_ok_and(|t| t.elapsed().is_ok_and(|age| age > STALE_AGE));
    // This process's own temporaries are in flight (another thread's) unless old.
    old || (pid != std::process::id() && !process_runs(pid))
}

/// Whether a process with this pid runs (or cannot be told: then `true`).
#[cfg(unix)]
fn process_runs(pid: u32) -> bool {
    use rustix::process::{Pid, test_kill_process};
    let Some(pid) = i32::try_from(pid).ok().and_then(Pid::from_raw) else {
        return false;
    };
    // `kill(pid, 0)`: ESRCH means no such process; EPERM means it runs as another user.
    !matches!(test_kill_process(pid), Err(e) if e == rustix::io::Errno::SRCH)
}

#[cfg(not(unix))]
fn process_runs(_: u32) -> bool {
    true
}

/// Removes a file, link or whole directory; best effort.
fn remove_any(path: &Path) {
    match fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            let _ = fs::remove_dir_all(path);
        }
        Ok(_) => {
            let _ = fs::remove_file(path);
        }
        Err(_) => {}
    }
}

/// Flushes a directory's entries to disk (Unix; best effort: some filesystems refuse it, and a
/// kill, unlike a power cut, loses nothing that was renamed).
fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;
    use std::fs;

    /// A pid no process can have (above Linux's largest `pid_max`, 2^22).
    const DEAD: u32 = i32::MAX as u32;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "fireflies-atomic-{name}-{}-{}",
            std::process::id(),
            next()
        ));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn names(dir: &Path) -> BTreeSet<String> {
        fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    }

    fn fill_with(files: &[(&str, &str)]) -> impl FnOnce(&Path) -> Result<()> {
        move |dir| {
            for (name, text) in files {
                write_atomic(&dir.join(name), text.as_bytes())?;
            }
            Ok(())
        }
    }

    #[test]
    fn replaces_whole_file_and_leaves_no_temporary() {
        let dir = scratch("file");
        let path = dir.join("out.txt");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        let leftovers = fs::read_dir(&dir).unwrap().count();
        assert_eq!(leftovers, 1);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let e = write_atomic(Path::new("/proc/fireflies/x.csv"), b"x").unwrap_err();
        assert!(e.to_string().contains("/proc/fireflies"), "{e}");
    }

    #[test]
    fn temporary_names_parse_and_only_they_do() {
        let t = |kind, pid, n| Some(Temp { kind, pid, n });
        assert_eq!(
            parse_temp(".a.csv.tmp-12-3", "a.csv"),
            t(Kind::Staging, 12, Some(3))
        );
        assert_eq!(
            parse_temp(".a.csv.old-12-3", "a.csv"),
            t(Kind::Aside, 12, Some(3))
        );
        assert_eq!(
            parse_temp(".a.csv.tmp.12", "a.csv"),
            t(Kind::Staging, 12, None)
        );
        for other in [
            "a.csv",
            ".a.csv",
            ".a.csv.tmp-12",
            ".a.csv.tmp-12-",
            ".a.csv.tmp-x-3",
            ".a.csv.tmp.12.3",
            ".b.csv.tmp-12-3",
            ".a.csv.tmp-12-3.png",
        ] {
            assert_eq!(parse_temp(other, "a.csv"), None, "{other}");
        }
        assert!(is_temp_name(OsStr::new(".results.csv.tmp.77")));
        assert!(is_temp_name(OsStr::new(".report.tmp-1-2")));
        assert!(is_temp_name(OsStr::new(".my.report.old-1-2")));
        assert!(!is_temp_name(OsStr::new("results.csv")));
        assert!(!is_temp_name(OsStr::new(".tmp-1-2")));
        assert!(!is_temp_name(OsStr::new(".x.tmp-1-2b")));
    }

    #[test]
    fn stale_file_temporaries_are_removed_and_live_ones_kept() {
        let dir = scratch("stale-files");
        let path = dir.join("out.txt");
        let dead = dir.join(format!(".out.txt.tmp-{DEAD}-5"));
        let legacy = dir.join(format!(".out.txt.tmp.{DEAD}"));
        let mine = dir.join(format!(".out.txt.tmp-{}-999999", std::process::id()));
        let unrelated = dir.join(format!(".other.txt.tmp-{DEAD}-5"));
        for p in [&dead, &legacy, &mine, &unrelated] {
            fs::write(p, b"orphan").unwrap();
        }
        write_atomic(&path, b"x").unwrap();
        assert!(!dead.exists() && !legacy.exists());
        assert!(mine.exists() && unrelated.exists());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn both_swaps_replace_a_directory_as_a_unit() {
        for swap in [Swap::Exchange, Swap::Aside] {
            let dir = scratch("swap");
            let target = dir.join("report");
            replace_dir_with(&target, fill_with(&[("a", "old"), ("b", "old")]), swap).unwrap();
            assert_eq!(names(&dir), BTreeSet::from(["report".to_string()]));
            replace_dir_with(&target, fill_with(&[("b", "new"), ("c", "new")]), swap).unwrap();
            assert_eq!(
                names(&dir),
                BTreeSet::from(["report".to_string()]),
                "{swap:?}"
            );
            assert_eq!(
                names(&target),
                BTreeSet::from(["b".to_string(), "c".to_string()])
            );
            assert_eq!(fs::read_to_string(target.join("b")).unwrap(), "new");
            fs::remove_dir_all(&dir).unwrap();
        }
    }

    #[test]
    fn a_failing_fill_leaves_the_old_directory_and_no_temporary() {
        let dir = scratch("fail");
        let target = dir.join("report");
        replace_dir(&target, fill_with(&[("a", "old")])).unwrap();
        let e = replace_dir(&target, |staging| {
            fs::write(staging.join("half"), b"x").unwrap();
            Err::<(), _>(Error::io("boom", &io::Error::other("failed")))
        })
        .unwrap_err();
        assert!(e.to_string().contains("boom"));
        assert_eq!(names(&dir), BTreeSet::from(["report".to_string()]));
        assert_eq!(names(&target), BTreeSet::from(["a".to_string()]));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_fallback_swap_killed_midway_is_finished_by_the_next_write() {
        let dir = scratch("recover");
        let target = dir.join("report");
        // What a kill between the fallback's two renames leaves: the old directory aside, the
        // complete new one staged, nothing at the target.
        let aside = dir.join(format!(".report.old-{DEAD}-4"));
        let staged = dir.join(format!(".report.tmp-{DEAD}-4"));
        fs::create_dir(&aside).unwrap();
        fs::write(aside.join("a"), b"old").unwrap();
        fs::create_dir(&staged).unwrap();
        fs::write(staged.join("a"), b"new").unwrap();
        prepare_dir(&target).unwrap();
        assert_eq!(names(&dir), BTreeSet::from(["report".to_string()]));
        assert_eq!(fs::read_to_string(target.join("a")).unwrap(), "new");
        // With only the old one aside (no staged one), it is put back.
        fs::remove_dir_all(&target).unwrap();
        fs::create_dir(&aside).unwrap();
        fs::write(aside.join("a"), b"old").unwrap();
        prepare_dir(&target).unwrap();
        assert_eq!(fs::read_to_string(target.join("a")).unwrap(), "old");
        assert_eq!(names(&dir), BTreeSet::from(["report".to_string()]));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_targets_are_errors_naming_them() {
        let dir = scratch("bad");
        let file = dir.join("file");
        fs::write(&file, b"x").unwrap();
        let cwd = std::env::current_dir().unwrap();
        let cases = [
            file.clone(),
            PathBuf::from("/"),
            PathBuf::from(""),
            cwd.clone(),
            cwd.parent().unwrap().to_path_buf(),
            PathBuf::from("/proc/fireflies-not-writable"),
        ];
        for target in cases {
            let shown = target.display().to_string();
            for e in [
                prepare_dir(&target).unwrap_err(),
                replace_dir(&target, fill_with(&[("a", "x")])).unwrap_err(),
            ] {
                assert!(
                    matches!(&e, Error::Io { path, .. } if *path == shown),
                    "{e}"
                );
            }
        }
        assert_eq!(fs::read(&file).unwrap(), b"x");
        fs::remove_dir_all(&dir).unwrap();
    }
}
