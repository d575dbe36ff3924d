//! Opening a data file only when it is a regular file.
//!
//! Why: a run directory's `samples.csv` replaced by a link to `/dev/zero` would be hashed or
//! read forever, a FIFO would block the `open` itself, and a directory reads as an I/O error
//! that says nothing useful. Every data file gyrocal reads (the run directory's CSV and JSON
//! files, what `verify` hashes, what `report` checks) is opened through [`open_regular`],
//! which refuses at once anything that is not a regular file, a symbolic link to one included,
//! and says what it found instead.

use std::fs::{File, Metadata, OpenOptions};
use std::path::{Path, PathBuf};

/// What kind of [`OpenError`] it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpenErrorKind {
    /// The file does not exist.
    NotFound,
    /// The path is a directory, a FIFO, a device or a socket (or a link to one).
    NotRegular,
    /// Another I/O error (permissions, a failing disk).
    Io,
}

/// Why [`open_regular`] refused or failed; names the file.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// Not a regular file.
    #[error(
        "{}: not a regular file (it is {what}); gyrocal reads data only from regular files",
        path.display()
    )]
    NotRegular {
        /// The path given.
        path: PathBuf,
        /// What it is: `a directory`, `a FIFO (named pipe)`, `a character device`, ...
        what: &'static str,
    },
    /// The file could not be examined or opened.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The path given.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl OpenError {
    /// The kind of error.
    pub fn kind(&self) -> OpenErrorKind {
        match self {
            OpenError::NotRegular { .. } => OpenErrorKind::NotRegular,
            OpenError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
                OpenErrorKind::NotFound
            }
            OpenError::Io { .. } => OpenErrorKind::Io,
        }
    }

    /// The path concerned.
    pub fn path(&self) -> &Path {
        match self {
            OpenError::NotRegular { path, .. } | OpenError::Io { path, .. } => path,
        }
    }
}

/// What a file that is not regular is, in words.
fn what(meta: &Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Opens `path` for reading when it is a regular file (following symbolic links); refuses a
/// directory, a FIFO, a device or a socket, or a link to one, without blocking and without
/// reading a byte.
///
/// The type is checked before opening (a FIFO's `open` would wait for a writer) and again on
/// the file opened (the path may have been replaced in between). On Unix the file is opened
/// with `O_NONBLOCK`, so that even a FIFO swapped in between the two checks cannot block the
/// open; on a regular file the flag changes nothing.
pub fn open_regular(path: &Path) -> Result<File, OpenError> {
    let io = |source| OpenError::Io {
        path: path.to_path_buf(),
        source,
    };
    let not_regular = |meta: &Metadata| OpenError::NotRegular {
        path: path.to_path_buf(),
        what: what(meta),
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    Ok(file)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::io::Read as _;

    use super::*;

    #[test]
    fn a_regular_file_and_a_link_to_one_open() {
        let tmp = tempfile::tempdir().unwrap();
        let f = tmp.path().join("a.csv");
        std::fs::write(&f, "x,y\n").unwrap();
        let mut s = String::new();
        open_regular(&f).unwrap().read_to_string(&mut s).unwrap();
        assert_eq!(s, "x,y\n");
        #[cfg(unix)]
        {
            let l = tmp.path().join("link.csv");
            std::os::unix::fs::symlink(&f, &l).unwrap();
            assert!(open_regular(&l).is_ok());
        }
    }

    #[test]
    fn a_directory_and_a_missing_file_are_refused_by_name() {
        let tmp = tempfile::tempdir().unwrap();
        let e = open_regular(tmp.path()).unwrap_err();
        assert_eq!(e.kind(), OpenErrorKind::NotRegular);
        assert!(e.to_string().contains("a directory"), "{e}");
        let e = open_regular(&tmp.path().join("nope.csv")).unwrap_err();
        assert_eq!(e.kind(), OpenErrorKind::NotFound);
        assert!(e.to_string().contains("nope.csv"), "{e}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_link_to_dev_zero_and_a_fifo_are_refused_at_once() {
        let tmp = tempfile::tempdir().unwrap();
        let l = tmp.path().join("samples.csv");
        std::os::unix::fs::symlink("/dev/zero", &l).unwrap();
        let e = open_regular(&l).unwrap_err();
        assert!(e.to_string().contains("a character device"), "{e}");
        assert!(e.to_string().contains("samples.csv"), "{e}");
        // a FIFO without a writer: opening it for reading would block
        let fifo = tmp.path().join("fifo.csv");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        let e = open_regular(&fifo).unwrap_err();
        assert!(e.to_string().contains("FIFO"), "{e}");
    }
}
