//! Splitting one line into fields: the one place that decides what a field is, for the line
//! reader ([`crate::Reader`]) and the chunked reader ([`crate::ChunkedReader`]) alike.
//!
//! A line with no quote and no carriage return (every line of a data file a logger or gyrocal
//! writes) is split at its commas where it lies, without copying: that is what `csv-core` does
//! with such a line, and it is the fast path. Any other line goes through `csv-core` (the `csv`
//! crate's own parser), which unquotes into a buffer: quoted fields may hold commas and doubled
//! quotes; a carriage return inside a line ends the record there, as `csv-core` reads it.

use crate::Row;

/// Splits lines into [`Row`]s, reusing its buffers (no allocation per line once they have
/// grown to the longest line).
#[derive(Debug)]
pub(crate) struct Splitter {
    core: csv_core::Reader,
    out: Vec<u8>,
    ends: Vec<usize>,
}

impl Default for Splitter {
    fn default() -> Splitter {
        Splitter {
            // `new`, not `default`: `new` builds the parser's state machine
            core: csv_core::Reader::new(),
            out: Vec::new(),
            ends: Vec::new(),
        }
    }
}

impl Splitter {
    /// The fields of `text` (one line, without its `\n`), as read from line `line`.
    pub(crate) fn split<'a>(&'a mut self, text: &'a [u8], line: u64) -> Row<'a> {
        self.ends.clear();
        let mut plain = true;
        for (i, &b) in text.iter().enumerate() {
            match b {
                b',' => self.ends.push(i),
                b'"' | b'\r' => {
                    plain = false;
                    break;
                }
                _ => {}
            }
        }
        if plain {
            self.ends.push(text.len());
            return Row {
                line,
                data: text,
                ends: &self.ends,
                sep: 1,
            };
        }
        self.split_quoted(text);
        Row {
            line,
            data: &self.out,
            ends: &self.ends,
            sep: 0,
        }
    }

    /// `csv-core` on one line: the fields unquoted into `self.out`, their ends in `self.ends`.
    fn split_quoted(&mut self, text: &[u8]) {
        // unquoting only shrinks a field: the line's length is enough output
        self.out.clear();
        self.out.resize(text.len() + 1, 0);
        let commas = text.iter().filter(|&&b| b == b',').count();
        self.ends.clear();
        self.ends.resize(commas + 2, 0);
        self.core.reset();
        let (mut input, mut nout, mut nend) = (text, 0usize, 0usize);
        loop {
            let (res, nin, o, e) =
                self.core
                    .read_record(input, &mut self.out[nout..], &mut self.ends[nend..]);
            input = &input[nin..];
            nout += o;
            nend += e;
            match res {
                // the whole line was given: the next call, with no input, ends the record
                csv_core::ReadRecordResult::InputEmpty => {}
                csv_core::ReadRecordResult::OutputFull => {
                    let n = self.out.len().max(1);
                    self.out.resize(2 * n, 0);
                }
                csv_core::ReadRecordResult::OutputEndsFull => {
                    let n = self.ends.len().max(1);
                    self.ends.resize(2 * n, 0);
                }
                csv_core::ReadRecordResult::Record | csv_core::ReadRecordResult::End => break,
            }
        }
        self.out.truncate(nout);
        self.ends.truncate(nend);
    }
}
