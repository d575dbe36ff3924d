//! The chunked reader against a simple reference (the line reader's layer below, `csv-core` on
//! every line, the standard library's number parser), on the edge cases by name and on random
//! inputs with blocks of a few bytes, so that block boundaries fall inside lines, inside quoted
//! fields, between a `\r` and its `\n`, and inside the byte-order mark.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use proptest::prelude::*;

use super::*;

/// What a reader made of an input: the header, each kept row's line and cells (as bits), the
/// skipped count, and the error at the end, if any (its message).
#[derive(Debug, PartialEq)]
struct Outcome {
    header: Option<Vec<String>>,
    rows: Vec<(u64, Vec<u64>)>,
    skipped: u64,
    error: Option<String>,
}

/// The typed columns asked for in the random tests.
const CELLS: [Cell; 3] = [Cell::Number, Cell::OptionalNumber, Cell::Lenient];

fn spec_for(header: &Header) -> Spec {
    let mut spec = Spec::new();
    for (i, cell) in CELLS.iter().enumerate().take(header.names().len()) {
        spec = spec.column(i, *cell);
    }
    if header.names().len() > 3 {
        spec = spec.skip_flagged(3);
    }
    spec.skip_empty_rows()
}

fn bits(v: f64) -> u64 {
    if v.is_nan() {
        f64::NAN.to_bits()
    } else {
        v.to_bits()
    }
}

fn chunked(input: &[u8], opts: Options) -> Outcome {
    let mut out = Outcome {
        header: None,
        rows: Vec::new(),
        skipped: 0,
        error: None,
    };
    let mut r = match ChunkedReader::new(input, "r.csv", opts) {
        Ok(r) => r,
        Err(e) => {
            out.error = Some(e.to_string());
            return out;
        }
    };
    out.header = Some(r.header().names().to_vec());
    let spec = spec_for(r.header());
    loop {
        match r.next_chunk(&spec) {
            Ok(Some(c)) => {
                out.skipped += c.skipped();
                for i in 0..c.len() {
                    let cells = (0..spec.len()).map(|k| bits(c.column(k)[i])).collect();
                    out.rows.push((c.lines()[i], cells));
                }
            }
            Ok(None) => break,
            Err(e) => {
                out.error = Some(e.to_string());
                break;
            }
        }
    }
    // after the end or an error, nothing more
    assert!(matches!(r.next_chunk(&spec), Ok(None)));
    out
}

/// `csv-core` on the whole line, as the reader did before it split plain lines itself.
fn reference_split(text: &[u8]) -> Vec<Vec<u8>> {
    let mut core = csv_core::Reader::new();
    let mut out = vec![0u8; text.len() + 1];
    let mut ends = vec![0usize; text.len() + 2];
    let (mut input, mut nout, mut nend) = (text, 0, 0);
    loop {
        let (res, nin, o, e) = core.read_record(input, &mut out[nout..], &mut ends[nend..]);
        input = &input[nin..];
        nout += o;
        nend += e;
        match res {
            csv_core::ReadRecordResult::InputEmpty => {}
            csv_core::ReadRecordResult::Record | csv_core::ReadRecordResult::End => break,
            other => panic!("{other:?}: the buffers are large enough"),
        }
    }
    let mut start = 0;
    ends[..nend]
        .iter()
        .map(|&end| {
            let f = cell(&out[start..end]).to_vec();
            start = end;
            f
        })
        .collect()
}

fn reference_cell(raw: &[u8], cell: Cell) -> Result<f64, Problem> {
    let parse = |raw: &[u8]| -> Result<f64, Problem> {
        let text = String::from_utf8_lossy(raw);
        let text = text.trim();
        if text.is_empty() {
            return Err(Problem::Empty);
        }
        text.parse::<f64>().map_err(|_| Problem::NotANumber)
    };
    let finite = |raw: &[u8]| match parse(raw)? {
        v if v.is_finite() => Ok(v),
        v => Err(Problem::NotFinite(v)),
    };
    match cell {
        Cell::Number => finite(raw),
        Cell::OptionalNumber | Cell::OptionalNonNegative | Cell::OptionalCount
            if raw.is_empty() =>
        {
            Ok(f64::NAN)
        }
        Cell::OptionalNumber => finite(raw),
        Cell::Lenient => Ok(parse(raw).unwrap_or(f64::NAN)),
        other => unreachable!("{other:?} is not in the random tests"),
    }
}

/// The reference: the line layer ([`Lines`]), `csv-core` on each line, the standard library's
/// parser, one row at a time.
fn reference(input: &[u8], max_line: usize, max_bytes: Option<u64>) -> Outcome {
    let mut out = Outcome {
        header: None,
        rows: Vec::new(),
        skipped: 0,
        error: None,
    };
    let mut lines = Lines::new(input, "r.csv").with_max_line(max_line);
    if let Some(cap) = max_bytes {
        lines = lines.with_max_bytes(cap);
    }
    let mut header: Option<Header> = None;
    loop {
        let (line, text) = match lines.next_line() {
            Ok(Some(l)) => l,
            Ok(None) => break,
            Err(e) => {
                out.error = Some(e.to_string());
                return out;
            }
        };
        if is_comment_or_blank(text) {
            continue;
        }
        let fields = reference_split(text);
        let Some(h) = &header else {
            let ends: Vec<usize> = fields
                .iter()
                .scan(0, |end, f| {
                    *end += f.len();
                    Some(*end)
                })
                .collect();
            let data = fields.concat();
            let row = Row {
                line,
                data: &data,
                ends: &ends,
                sep: 0,
            };
            match Header::of_row(&row, "r.csv") {
                Ok(h) => {
                    out.header = Some(h.names().to_vec());
                    header = Some(h);
                }
                Err(e) => {
                    out.error = Some(e.to_string());
                    return out;
                }
            }
            continue;
        };
        if fields.len() != h.names().len() {
            out.error = Some(
                Error::FieldCount {
                    file: "r.csv".into(),
                    line,
                    expected: h.names().len(),
                    found: fields.len(),
                }
                .to_string(),
            );
            return out;
        }
        if h.names().len() > 3 && fields[3] == b"1" {
            out.skipped += 1;
            continue;
        }
        if fields.iter().all(Vec::is_empty) {
            continue;
        }
        let mut cells = Vec::new();
        for (k, cell) in CELLS.iter().enumerate().take(h.names().len()) {
            match reference_cell(&fields[k], *cell) {
                Ok(v) => cells.push(bits(v)),
                Err(problem) => {
                    out.error = Some(
                        Error::Value {
                            file: "r.csv".into(),
                            line,
                            column: h.names()[k].clone(),
                            text: String::from_utf8_lossy(&fields[k]).into_owned(),
                            problem,
                        }
                        .to_string(),
                    );
                    return out;
                }
            }
        }
        out.rows.push((line, cells));
    }
    if header.is_none() {
        out.error = Some(
            Error::NoHeader {
                file: "r.csv".into(),
            }
            .to_string(),
        );
    }
    out
}

fn small(chunk_bytes: usize, threads: usize, max_line: usize) -> Options {
    Options {
        max_line,
        max_bytes: None,
        chunk_bytes,
        threads,
    }
}

/// Both readers on `input`, with every block size from 1 byte up and 1 to 3 threads.
fn agree(input: &[u8]) {
    let expected = reference(input, MAX_LINE_BYTES, None);
    for chunk in [1, 2, 3, 5, 8, 13, 64, 1 << 20] {
        for threads in 1..=3 {
            assert_eq!(
                chunked(input, small(chunk, threads, MAX_LINE_BYTES)),
                expected,
                "blocks of {chunk} bytes, {threads} threads, input {:?}",
                String::from_utf8_lossy(input)
            );
        }
    }
}

#[test]
fn the_edge_cases_read_as_the_line_reader_reads_them() {
    for input in [
        &b"t_s,volts\n0,1\n0.01,2\n"[..],
        b"\xEF\xBB\xBFt_s,volts\r\n0,1\r\n0.01,2\r\n",
        b"\xEF\xBB\xBF# a comment first\nt_s,volts\n1,2",
        b"# c\n\n Rate_DPS , \"volts\"\r\n1,2\n# mid\n\n  \n\"3\", \"4\" \n5,\"6\"",
        b"a,b\n\"1\",\"2,5\"\n",
        b"a,b\n1,\"2\"\"\"\n",
        b"a,b\n1,2\r3,4\n5,6\n",
        b"a,b\n1,2\n3\n",
        b"a,b\n1,x\n",
        b"a,b\n1,inf\n",
        b"a,b\n,\n1,\n",
        b"a,b,c,overload\n1,2,3,0\n1,x,3,1\n1,2,x,0\n",
        b"a,b\n\xC2\xA01,2\n",
        b"",
        b"# only\n\n",
        b",,\n",
        b"a,A\n",
        b"\xFF,a\n",
        b"a\n1\n2\n3",
    ] {
        agree(input);
    }
}

#[test]
fn errors_name_the_file_and_the_line_across_blocks() {
    let input = b"# c\nt_s,volts\n0,1\n0.01,2\n# note\n0.02,x\n0.03,4\n";
    for chunk in [1, 4, 1 << 20] {
        let out = chunked(input, small(chunk, 2, MAX_LINE_BYTES));
        assert_eq!(
            out.rows.len(),
            2,
            "the rows before the bad line are handed out"
        );
        assert_eq!(
            out.error.as_deref(),
            Some("r.csv: line 6: column `volts`: not a number: `x`")
        );
    }
    let out = chunked(b"t_s,volts\n0,1\n0.01\n", Options::default());
    assert_eq!(
        out.error.as_deref(),
        Some("r.csv: line 3: expected 2 fields like the header, found 1")
    );
}

#[test]
fn a_long_line_is_refused_after_reading_at_most_the_limit() {
    // an endless input without a newline, before and after a valid header
    let e = ChunkedReader::new(std::io::repeat(b'7'), "big.csv", small(1024, 2, 4096))
        .err()
        .expect("refused");
    assert_eq!((e.kind(), e.line()), (ErrorKind::LineTooLong, Some(1)));
    let after = (&b"t_s,volts\n0,1\n"[..]).chain(std::io::repeat(b'7'));
    let mut r = ChunkedReader::new(after, "big.csv", small(1024, 2, 4096)).unwrap();
    let spec = Spec::new().column(0, Cell::Number);
    let first = r.next_chunk(&spec).unwrap().unwrap();
    assert_eq!(first.lines(), [2]);
    let e = r.next_chunk(&spec).unwrap_err();
    assert_eq!(
        e.to_string(),
        "big.csv: line 3: longer than the 4 KiB limit for a line; is it a CSV data file?"
    );
    // a long line within a block, then more lines
    let mut input = b"a,b\n1,2\n".to_vec();
    input.extend(std::iter::repeat_n(b'9', 5000));
    input.extend(b"\n3,4\n");
    let out = chunked(&input, small(1 << 20, 1, 4096));
    assert_eq!(out.rows.len(), 1);
    assert_eq!(
        out.error.as_deref(),
        Some("r.csv: line 3: longer than the 4 KiB limit for a line; is it a CSV data file?")
    );
    assert_eq!(out, reference(&input, 4096, None));
}

#[test]
fn a_byte_cap_refuses_the_rest() {
    let mut input = b"a\n".to_vec();
    input.extend(b"1\n".repeat(1000));
    let opts = Options {
        max_bytes: Some(100),
        ..small(16, 2, MAX_LINE_BYTES)
    };
    let out = chunked(&input, opts);
    assert_eq!(
        out.error.as_deref(),
        Some("r.csv: larger than the 0 MiB limit for a data file; is it the right file?")
    );
    assert!(out.rows.len() < 100);
}

#[test]
fn only_regular_files_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let e = read_columns(dir.path(), &["a"], Options::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NotAFile);
    let e = read_columns(&dir.path().join("none.csv"), &["a"], Options::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::NotFound);
    #[cfg(unix)]
    {
        let e = read_columns(Path::new("/dev/zero"), &["a"], Options::default()).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::NotAFile);
        assert!(e.to_string().contains("a device"), "{e}");
        let fifo = dir.path().join("pipe.csv");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // refused before it is opened: opening a FIFO would block until a writer comes
            let e = read_columns(&fifo, &["a"], Options::default()).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::NotAFile);
            assert!(e.to_string().contains("named pipe"), "{e}");
        }
    }
    let path = dir.path().join("ok.csv");
    std::fs::write(&path, "t_s,volts\n0,1\n1,2\n").unwrap();
    let e = read_columns(&path, &["t_s", "value"], Options::default()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: line 1: the header has no `value` column (columns: t_s, volts)",
            path.display()
        )
    );
    let cols = read_columns(&path, &["VOLTS", "t_s"], Options::default()).unwrap();
    assert_eq!(cols.values, [vec![1.0, 2.0], vec![0.0, 1.0]]);
    assert_eq!(cols.get("volts"), Some(&[1.0, 2.0][..]));
}

#[test]
fn counts_and_non_negative_cells() {
    let input = b"n,s\n5,0.1\n,\n+7,\n";
    let mut r = ChunkedReader::new(&input[..], "c.csv", Options::default()).unwrap();
    let spec = Spec::new()
        .column(0, Cell::OptionalCount)
        .column(1, Cell::OptionalNonNegative);
    let c = r.next_chunk(&spec).unwrap().unwrap();
    assert_eq!(
        (0..c.len()).map(|i| c.count(0, i)).collect::<Vec<_>>(),
        [Some(5), None, Some(7)]
    );
    assert_eq!(c.column(1)[0], 0.1);
    assert!(c.column(1)[2].is_nan());
    for (input, message) in [
        (
            &b"n,s\n0,1\n"[..],
            "c.csv: line 2: column `n`: not a positive whole number: `0`",
        ),
        (b"n,s\n1,-1\n", "c.csv: line 2: column `s`: negative: `-1`"),
    ] {
        let mut r = ChunkedReader::new(input, "c.csv", Options::default()).unwrap();
        // the rows before the bad line (none) come first, then the error
        let e = loop {
            match r.next_chunk(&spec) {
                Ok(Some(c)) => assert!(c.is_empty()),
                Ok(None) => panic!("no error"),
                Err(e) => break e,
            }
        };
        assert_eq!(e.to_string(), message);
    }
}

/// A random line of a small CSV: numbers, empties, quotes, comments, blanks, `\r`s.
fn line() -> impl Strategy<Value = String> {
    let cell = prop_oneof![
        4 => "-?[0-9]{1,4}(\\.[0-9]{0,3})?(e-?[0-9])?",
        1 => Just(String::new()),
        1 => Just(" 1 ".to_string()),
        1 => Just("\"2,5\"".to_string()),
        1 => Just("\"\"\"3\"".to_string()),
        1 => Just("x".to_string()),
        1 => Just("inf".to_string()),
        1 => Just("1".to_string()),
    ];
    prop_oneof![
        8 => prop::collection::vec(cell, 1..5).prop_map(|c| c.join(",")),
        1 => Just("# comment, with \"quotes\"".to_string()),
        1 => Just("  ".to_string()),
        1 => Just(String::new()),
        1 => Just("1,2\r3".to_string()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_inputs_read_as_the_reference_reads_them(
        bom in any::<bool>(),
        header in prop::sample::select(vec!["a", "a,b", "a,b,c", "a,b,c,overload"]),
        lines in prop::collection::vec(line(), 0..40),
        crlf in any::<bool>(),
        final_newline in any::<bool>(),
        chunk in 1usize..40,
        threads in 1usize..4,
    ) {
        let eol = if crlf { "\r\n" } else { "\n" };
        let mut text = String::new();
        if bom {
            text.push('\u{feff}');
        }
        text.push_str(header);
        for l in &lines {
            text.push_str(eol);
            text.push_str(l);
        }
        if final_newline {
            text.push_str(eol);
        }
        let input = text.as_bytes();
        prop_assert_eq!(
            chunked(input, small(chunk, threads, MAX_LINE_BYTES)),
            reference(input, MAX_LINE_BYTES, None)
        );
        // a line limit that some lines pass
        prop_assert_eq!(
            chunked(input, small(chunk, threads, 12)),
            reference(input, 12, None)
        );
    }
}
