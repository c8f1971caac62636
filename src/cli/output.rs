//! Outputs whole or not at all.
//!
//! A command that writes a directory of results first checks the location
//! ([`Staging::begin`], before any work), takes a lock beside it (so two
//! runs cannot write one directory), writes everything into a hidden
//! temporary directory beside the target and, at the end, renames it into
//! place ([`Staging::commit`]). A directory that already holds tacit output
//! is refused unless `--force`, which replaces it whole (nothing stale is
//! left). On an error, and on SIGINT or SIGTERM, the temporary directory
//! and the lock are removed.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Files by which a directory is recognised as tacit output.
const MARKERS: [&str; 5] = [
    ".tacit-output",
    "report.json",
    "summary.json",
    "estimate.json",
    "report.md",
];

/// Paths to remove if the process is interrupted.
static CLEANUP: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Install the SIGINT/SIGTERM handler that removes registered temporary
/// paths and exits with 130.
pub fn install_signal_cleanup() {
    let _ = ctrlc::set_handler(|| {
        remove_registered();
        eprintln!("tacit: interrupted; temporary files removed");
        std::process::exit(130);
    });
}

/// Remove every registered temporary path (files or directories).
pub fn remove_registered() {
    let paths = match CLEANUP.lock() {
        Ok(mut g) => std::mem::take(&mut *g),
        Err(p) => std::mem::take(&mut *p.into_inner()),
    };
    for p in paths.iter().rev() {
        remove_path(p);
    }
}

fn remove_path(p: &Path) {
    if p.is_dir() {
        let _ = std::fs::remove_dir_all(p);
    } else {
        let _ = std::fs::remove_file(p);
    }
}

/// Register a temporary path for removal on a signal.
pub fn register(p: &Path) {
    if let Ok(mut g) = CLEANUP.lock() {
        g.push(p.to_path_buf());
    }
}

/// Forget a registered path (it was renamed into place or removed).
pub fn unregister(p: &Path) {
    if let Ok(mut g) = CLEANUP.lock() {
        g.retain(|q| q != p);
    }
}

/// The directory holding `target` (`.` for a bare name).
pub fn parent_of(target: &Path) -> PathBuf {
    match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A hidden sibling of `target`: `.<name>.<tag>`.
fn sibling(target: &Path, tag: &str) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    parent_of(target).join(format!(".{name}.{tag}"))
}

/// A lock file beside the target: created exclusively, holding the PID;
/// removed on drop. A lock whose process is gone is taken over.
pub struct Lock {
    path: PathBuf,
}

impl Lock {
    /// Take the lock of `target`.
    pub fn acquire(target: &Path) -> Result<Lock> {
        let path = sibling(target, "lock");
        for _ in 0..2 {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut f) => {
                    use std::io::Write;
                    let _ = writeln!(f, "{}", std::process::id());
                    register(&path);
                    return Ok(Lock { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let holder = std::fs::read_to_string(&path).unwrap_or_default();
                    let pid = holder.trim().parse::<u32>().ok();
                    if pid.is_some_and(process_alive) {
                        bail!(
                            "{}: another tacit run (process {}) is writing there; wait for it or choose another directory",
                            target.display(),
                            pid.unwrap_or(0)
                        );
                    }
                    let _ = std::fs::remove_file(&path);
                }
                Err(e) => {
                    return Err(e).with_context(|| {
                        format!("{}: cannot create the lock file", target.display())
                    })
                }
            }
        }
        bail!(
            "{}: cannot take the lock {}",
            target.display(),
            path.display()
        )
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
        unregister(&self.path);
    }
}

/// True when a process with this PID exists (Linux: /proc/<pid>).
fn process_alive(pid: u32) -> bool {
    pid == std::process::id() || Path::new(&format!("/proc/{pid}")).exists()
}

/// What is at the target location.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Existing {
    /// Nothing there.
    Absent,
    /// An empty directory.
    Empty,
    /// A directory of tacit output.
    Output,
    /// A directory holding other files.
    Foreign,
}

fn existing(target: &Path) -> Result<Existing> {
    let meta = match std::fs::symlink_metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Existing::Absent),
        Err(e) => return Err(e).with_context(|| format!("{}", target.display())),
    };
    if !meta.is_dir() {
        bail!(
            "{}: exists and is not a directory; give a directory for the output",
            target.display()
        );
    }
    let mut entries = std::fs::read_dir(target)
        .with_context(|| format!("{}: cannot list the directory", target.display()))?;
    if entries.next().is_none() {
        return Ok(Existing::Empty);
    }
    if MARKERS.iter().any(|m| target.join(m).exists()) {
        return Ok(Existing::Output);
    }
    Ok(Existing::Foreign)
}

/// A run's output directory being written: the hidden temporary directory
/// and the lock, until [`Staging::commit`] renames it onto the target.
pub struct Staging {
    target: PathBuf,
    tmp: PathBuf,
    replace: bool,
    _lock: Lock,
}

impl Staging {
    /// Check the location, take the lock and create the temporary
    /// directory (parents of the target are created). `force` allows
    /// replacing a directory of earlier tacit output.
    pub fn begin(target: &Path, force: bool) -> Result<Staging> {
        let parent = parent_of(target);
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("{}: cannot create the directory", parent.display()))?;
        let state = existing(target)?;
        match (state, force) {
            (Existing::Output, false) => bail!(
                "{}: already holds a tacit report; give --force to replace it or choose another directory",
                target.display()
            ),
            (Existing::Foreign, _) => bail!(
                "{}: holds files tacit did not write; choose an empty or new directory",
                target.display()
            ),
            _ => {}
        }
        let lock = Lock::acquire(target)?;
        let tmp = sibling(target, &format!("tmp-{}", std::process::id()));
        if tmp.exists() {
            let _ = std::fs::remove_dir_all(&tmp);
        }
        register(&tmp);
        std::fs::create_dir(&tmp).with_context(|| {
            format!("{}: cannot create a directory beside it", target.display())
        })?;
        std::fs::write(
            tmp.join(".tacit-output"),
            format!("tacit {}\n", env!("CARGO_PKG_VERSION")),
        )
        .with_context(|| format!("{}: cannot write in its directory", target.display()))?;
        Ok(Staging {
            target: target.to_path_buf(),
            tmp,
            replace: state != Existing::Absent,
            _lock: lock,
        })
    }

    /// Where the run writes its files.
    pub fn dir(&self) -> &Path {
        &self.tmp
    }

    /// A message naming the temporary directory rewritten to name the
    /// target instead.
    pub fn user_message(&self, e: anyhow::Error) -> anyhow::Error {
        let msg = super::out::error_message(&e);
        let tmp = self.tmp.display().to_string();
        anyhow::anyhow!(msg.replace(&tmp, &self.target.display().to_string()))
    }

    /// Move the finished directory into place (replacing the old one).
    pub fn commit(self) -> Result<PathBuf> {
        let old = sibling(&self.target, &format!("old-{}", std::process::id()));
        if self.replace {
            register(&old);
            std::fs::rename(&self.target, &old).with_context(|| {
                format!(
                    "{}: cannot move the old output aside",
                    self.target.display()
                )
            })?;
        }
        if let Err(e) = std::fs::rename(&self.tmp, &self.target) {
            if self.replace {
                let _ = std::fs::rename(&old, &self.target);
            }
            return Err(e).with_context(|| {
                format!(
                    "{}: cannot move the output into place",
                    self.target.display()
                )
            });
        }
        unregister(&self.tmp);
        if self.replace {
            let _ = std::fs::remove_dir_all(&old);
            unregister(&old);
        }
        Ok(self.target.clone())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if self.tmp.exists() {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
        unregister(&self.tmp);
    }
}

/// Writes one file to the path it is given.
pub type FileWriter<'a> = dyn Fn(&Path) -> Result<()> + 'a;

/// Write one or more files whole: each is written to a hidden temporary
/// beside it; all are renamed into place only when every one succeeded.
/// Parent directories are created.
pub fn write_files(files: &[(&Path, &FileWriter)]) -> Result<()> {
    let mut tmps: Vec<(PathBuf, &Path)> = vec![];
    let result = (|| -> Result<()> {
        for (path, write) in files {
            let parent = parent_of(path);
            std::fs::create_dir_all(&parent)
                .with_context(|| format!("{}: cannot create the directory", parent.display()))?;
            if path.is_dir() {
                bail!("{}: is a directory", path.display());
            }
            let tmp = temp_file_beside(path);
            register(&tmp);
            tmps.push((tmp.clone(), path));
            write(&tmp).map_err(|e| {
                let msg = super::out::error_message(&e);
                anyhow::anyhow!(msg.replace(&tmp.display().to_string(), &path.display().to_string()))
            })?;
        }
        for (tmp, path) in &tmps {
            std::fs::rename(tmp, path)
                .with_context(|| format!("{}: cannot move into place", path.display()))?;
            unregister(tmp);
        }
        Ok(())
    })();
    if result.is_err() {
        for (tmp, _) in &tmps {
            remove_path(tmp);
            unregister(tmp);
        }
    }
    result
}

/// Write a text file whole (parents created).
pub fn save_text(path: &Path, text: &str) -> Result<()> {
    write_files(&[(path, &|tmp: &Path| Ok(std::fs::write(tmp, text)?))])
}

/// A hidden temporary name beside `path` keeping its extension (the
/// record writers choose the format from it): `.rec.tmp-<pid>.h5`.
fn temp_file_beside(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    parent_of(path).join(format!(".{stem}.tmp-{}{ext}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staging_commits_whole_and_refuses_reuse_without_force() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("sub/out");
        let s = Staging::begin(&target, false).unwrap();
        std::fs::write(s.dir().join("report.json"), "{}").unwrap();
        std::fs::write(s.dir().join("old.png"), "x").unwrap();
        s.commit().unwrap();
        assert!(target.join("report.json").exists());
        let e = Staging::begin(&target, false).err().unwrap().to_string();
        assert!(e.contains("--force"), "{e}");
        let s = Staging::begin(&target, true).unwrap();
        std::fs::write(s.dir().join("report.json"), "{\"new\":1}").unwrap();
        s.commit().unwrap();
        assert!(!target.join("old.png").exists(), "stale file left");
        let names: Vec<_> = std::fs::read_dir(d.path().join("sub"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["out"], "only the output is left: {names:?}");
    }

    #[test]
    fn dropped_staging_leaves_nothing_and_lock_blocks_a_second_run() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("out");
        {
            let s = Staging::begin(&target, false).unwrap();
            std::fs::write(s.dir().join("report.json"), "{}").unwrap();
            let e = Staging::begin(&target, false).err().unwrap().to_string();
            assert!(e.contains("another tacit run"), "{e}");
        }
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
        // a stale lock of a process that is gone is taken over
        std::fs::write(d.path().join(".out.lock"), "4294967295\n").unwrap();
        let s = Staging::begin(&target, false).unwrap();
        drop(s);
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
    }

    #[test]
    fn foreign_directory_and_file_are_refused() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("notes.txt"), "mine").unwrap();
        let e = Staging::begin(d.path(), true).err().unwrap().to_string();
        assert!(e.contains("did not write"), "{e}");
        let f = d.path().join("file");
        std::fs::write(&f, "x").unwrap();
        let e = Staging::begin(&f, false).err().unwrap().to_string();
        assert!(e.contains("not a directory"), "{e}");
    }

    #[test]
    fn write_files_keeps_none_when_one_fails() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("new/rec.csv");
        let b = d.path().join("new/rec-truth.csv");
        let ok = |p: &Path| -> Result<()> { Ok(std::fs::write(p, "x")?) };
        let bad = |p: &Path| -> Result<()> { bail!("{}: disk full", p.display()) };
        let e = write_files(&[(&a, &ok), (&b, &bad)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("rec-truth.csv: disk full") && !e.contains("tmp-"),
            "{e}"
        );
        assert!(!a.exists());
        assert_eq!(std::fs::read_dir(d.path().join("new")).unwrap().count(), 0);
        write_files(&[(&a, &ok), (&b, &ok)]).unwrap();
        assert!(a.exists() && b.exists());
    }
}
