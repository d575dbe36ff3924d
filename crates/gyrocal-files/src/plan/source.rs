//! Reading a plan's text (bounded, regular files only) and placing a byte offset of it: the
//! line and column, and the `[section]` in force, for error messages.

use std::path::Path;

use super::error::PlanError;

/// The largest plan file read: 1 MiB. A plan is a few kilobytes; anything larger (or an
/// endless file such as `/dev/zero`) is refused after reading at most this much.
pub const MAX_PLAN_BYTES: u64 = 1024 * 1024;

/// Converts a byte offset into a 1-based (line, column in characters).
pub(crate) fn line_col(src: &str, offset: usize) -> (u32, u32) {
    let offset = offset.min(src.len());
    let before = src.get(..offset).unwrap_or(src);
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before.get(line_start..).map_or(0, |s| s.chars().count()) + 1;
    (to_u32(line), to_u32(column))
}

fn to_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// The `[section]` header in force at a byte offset (a heuristic for error messages only).
pub(super) fn section_at(src: &str, offset: usize) -> Option<String> {
    let before = src.get(..offset.min(src.len()))?;
    before.lines().rev().find_map(|line| {
        let t = line.trim();
        let inner = t.strip_prefix('[')?.split(']').next()?.trim();
        let is_header = !inner.is_empty()
            && inner
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '"'));
        is_header.then(|| inner.to_string())
    })
}

/// Why [`read_capped_text`] failed.
pub(crate) enum ReadFailure {
    /// Opening or reading, or not UTF-8 text (as [`std::io::ErrorKind::InvalidData`]).
    Io(std::io::Error),
    /// Longer than the cap.
    TooLarge,
}

/// Reads a text file of at most `cap` bytes, reading no more than `cap + 1` of it (so an
/// endless file such as `/dev/zero` is refused quickly). Only a regular file is opened: a
/// named pipe would block the open until a writer comes (forever), a device may never end.
pub(crate) fn read_capped_text(path: &Path, cap: u64) -> Result<String, ReadFailure> {
    use std::io::Read as _;
    // stat first: opening a FIFO for reading blocks until someone writes to it
    let meta = std::fs::metadata(path).map_err(ReadFailure::Io)?;
    if !meta.is_file() {
        return Err(ReadFailure::Io(not_a_regular_file(&meta.file_type())));
    }
    let file = std::fs::File::open(path).map_err(ReadFailure::Io)?;
    // and again on what was opened, in case the path was replaced in between
    let meta = file.metadata().map_err(ReadFailure::Io)?;
    if !meta.is_file() {
        return Err(ReadFailure::Io(not_a_regular_file(&meta.file_type())));
    }
    let mut bytes = Vec::new();
    file.take(cap.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(ReadFailure::Io)?;
    if bytes.len() as u64 > cap {
        return Err(ReadFailure::TooLarge);
    }
    String::from_utf8(bytes).map_err(|e| {
        ReadFailure::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        ))
    })
}

/// The error for a path that is not a regular file, saying what it is.
pub(crate) fn not_a_regular_file(t: &std::fs::FileType) -> std::io::Error {
    #[cfg(unix)]
    let what = {
        use std::os::unix::fs::FileTypeExt as _;
        if t.is_fifo() {
            "a named pipe (FIFO)"
        } else if t.is_char_device() || t.is_block_device() {
            "a device"
        } else if t.is_socket() {
            "a socket"
        } else if t.is_dir() {
            "a directory"
        } else {
            "not a regular file"
        }
    };
    #[cfg(not(unix))]
    let what = if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    };
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{what}: gyrocal reads this file only from a regular file"),
    )
}

/// A plan or acceptance file's text, at most [`MAX_PLAN_BYTES`].
pub(super) fn read_document(path: &Path, document: &'static str) -> Result<String, PlanError> {
    read_capped_text(path, MAX_PLAN_BYTES).map_err(|f| match f {
        ReadFailure::Io(source) => PlanError::Read {
            path: path.to_path_buf(),
            document,
            source,
        },
        ReadFailure::TooLarge => PlanError::TooLarge {
            path: path.to_path_buf(),
            document,
            cap: MAX_PLAN_BYTES,
        },
    })
}
