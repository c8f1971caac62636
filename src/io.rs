//! Output helpers: atomic writes (temporary file, then rename) so a failed
//! run never leaves a half-written file behind; the memory the machine has
//! available, against which runs and reads are bounded.

use crate::error::{Result, TacitError};
use std::path::{Path, PathBuf};

/// Write `path` through `writer`, which receives a temporary path in the
/// same directory; on success the temporary file is renamed onto `path`, on
/// failure it is removed.
pub fn write_atomic<F>(path: &Path, writer: F) -> Result<()>
where
    F: FnOnce(&Path) -> Result<()>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(TacitError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "directory does not exist"),
        ));
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    static COUNTER: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let serial = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.{}.{}.tmp", name, std::process::id(), serial));
    let res = writer(&tmp);
    match res {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            TacitError::io(path, e)
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(naming(e, &tmp, path))
        }
    }
}

/// The error of a write to `tmp`, naming the user's `path` instead of the
/// hidden temporary file.
fn naming(e: TacitError, tmp: &Path, path: &Path) -> TacitError {
    let swap = |p: PathBuf| if p == tmp { path.to_path_buf() } else { p };
    let text = |m: String| m.replace(&tmp.display().to_string(), &path.display().to_string());
    match e {
        TacitError::Io { path: p, source } => TacitError::Io {
            path: swap(p),
            source,
        },
        TacitError::Record { path: p, message } => TacitError::Record {
            path: swap(p),
            message: text(message),
        },
        TacitError::Setting(m) => TacitError::Setting(text(m)),
        TacitError::Numerical(m) => TacitError::Numerical(text(m)),
        TacitError::Model {
            source_name,
            message,
        } => TacitError::Model {
            source_name,
            message: text(message),
        },
    }
}

/// Write a string atomically.
pub fn write_string(path: &Path, text: &str) -> Result<()> {
    write_atomic(path, |tmp| {
        std::fs::write(tmp, text).map_err(|e| TacitError::io(tmp, e))
    })
}

/// Write a value as pretty JSON atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| TacitError::Setting(format!("JSON encoding of {}: {e}", path.display())))?;
    write_string(path, &text)
}

/// Create an output directory (and parents).
pub fn ensure_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| TacitError::io(dir, e))
}

/// Memory available to a new process, bytes (`MemAvailable` of
/// /proc/meminfo); `None` where it cannot be read.
pub fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    parse_meminfo(&text)
}

/// `MemAvailable` (kB in the text of /proc/meminfo) in bytes.
pub fn parse_meminfo(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_target_not_the_temporary_file() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("report.md");
        let e = write_atomic(&target, |tmp| {
            Err(TacitError::io(tmp, std::io::Error::other("disk full")))
        })
        .unwrap_err()
        .to_string();
        assert!(e.starts_with(&target.display().to_string()), "{e}");
        assert!(!e.contains(".report.md."), "{e}");
        let e = write_atomic(&target, |tmp| {
            Err(TacitError::record(
                tmp,
                format!("cannot write {}", tmp.display()),
            ))
        })
        .unwrap_err()
        .to_string();
        assert!(!e.contains(".report.md."), "{e}");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
    }
}
