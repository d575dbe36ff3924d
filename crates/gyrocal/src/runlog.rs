//! `DIR/run.log`: the log of a run kept with its data, so an operator who comes back to a
//! stopped overnight run can read what happened, whatever `RUST_LOG` said on the console.
//!
//! The subscriber is installed before the run directory exists, so the file is plugged in
//! later: [`RunLog`] writes to it once [`attach`] has been called, and nowhere before.

use std::fs::File;
use std::io::{self, Write};
use std::path::Path;
use std::sync::Mutex;

use tracing_subscriber::fmt::MakeWriter;

static FILE: Mutex<Option<File>> = Mutex::new(None);

/// Sends the log (info and above) to `path` from now on, appending.
pub fn attach(path: &Path) -> io::Result<()> {
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    let mut slot = FILE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    *slot = Some(file);
    Ok(())
}

/// The `MakeWriter` of the run-log layer.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunLog;

impl<'a> MakeWriter<'a> for RunLog {
    type Writer = RunLogWriter;
    fn make_writer(&'a self) -> Self::Writer {
        RunLogWriter
    }
}

/// Writes one formatted event to the attached file (or drops it when none is attached).
#[derive(Debug)]
pub struct RunLogWriter;

impl Write for RunLogWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut slot = FILE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match slot.as_mut() {
            // a log that cannot be written must not stop a calibration
            Some(f) => Ok(f.write(buf).unwrap_or(buf.len())),
            None => Ok(buf.len()),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        let mut slot = FILE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(f) = slot.as_mut() {
            let _ = f.flush();
        }
        Ok(())
    }
}
