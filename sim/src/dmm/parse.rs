//! The simulator's SCPI parser: program messages split into units, headers resolved against the
//! 34401A's command tree with long and short forms, optional nodes, `;` chaining relative to the
//! current subsystem and `;:` back to the root.

/// A command of the simulated meter's tree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Cmd {
    Idn,
    Rst,
    Cls,
    Opc,
    Esr,
    Stb,
    Ese,
    Sre,
    Tst,
    Trg,
    Remote,
    Rwlock,
    Local,
    Error,
    Version,
    Configure,
    Measure,
    Function,
    Range,
    RangeAuto,
    Nplc,
    Resolution,
    ZeroAuto,
    ImpedanceAuto,
    TrigSource,
    TrigDelay,
    TrigDelayAuto,
    TrigCount,
    SampleCount,
    Init,
    Read,
    Fetch,
    DataPoints,
    Display,
    DisplayText,
    DisplayTextClear,
}

/// The command tree: patterns with `[optional]` nodes; upper case letters are the short form.
const TREE: &[(&str, Cmd)] = &[
    ("SYSTem:REMote", Cmd::Remote),
    ("SYSTem:RWLock", Cmd::Rwlock),
    ("SYSTem:LOCal", Cmd::Local),
    ("SYSTem:ERRor[:NEXT]", Cmd::Error),
    ("SYSTem:VERSion", Cmd::Version),
    ("CONFigure:VOLTage[:DC]", Cmd::Configure),
    ("CONFigure", Cmd::Configure),
    ("MEASure:VOLTage[:DC]", Cmd::Measure),
    ("[SENSe:]FUNCtion", Cmd::Function),
    ("[SENSe:]VOLTage[:DC]:RANGe", Cmd::Range),
    ("[SENSe:]VOLTage[:DC]:RANGe:AUTO", Cmd::RangeAuto),
    ("[SENSe:]VOLTage[:DC]:NPLCycles", Cmd::Nplc),
    ("[SENSe:]VOLTage[:DC]:RESolution", Cmd::Resolution),
    ("[SENSe:]ZERO:AUTO", Cmd::ZeroAuto),
    ("INPut:IMPedance:AUTO", Cmd::ImpedanceAuto),
    ("TRIGger:SOURce", Cmd::TrigSource),
    ("TRIGger:DELay", Cmd::TrigDelay),
    ("TRIGger:DELay:AUTO", Cmd::TrigDelayAuto),
    ("TRIGger:COUNt", Cmd::TrigCount),
    ("SAMPle:COUNt", Cmd::SampleCount),
    ("INITiate[:IMMediate]", Cmd::Init),
    ("READ", Cmd::Read),
    ("FETCh", Cmd::Fetch),
    ("DATA:POINts", Cmd::DataPoints),
    ("DISPlay[:WINDow][:STATe]", Cmd::Display),
    ("DISPlay[:WINDow]:TEXT[:DATA]", Cmd::DisplayText),
    ("DISPlay[:WINDow]:TEXT:CLEar", Cmd::DisplayTextClear),
];

const COMMON: &[(&str, Cmd)] = &[
    ("*IDN", Cmd::Idn),
    ("*RST", Cmd::Rst),
    ("*CLS", Cmd::Cls),
    ("*OPC", Cmd::Opc),
    ("*ESR", Cmd::Esr),
    ("*STB", Cmd::Stb),
    ("*ESE", Cmd::Ese),
    ("*SRE", Cmd::Sre),
    ("*TST", Cmd::Tst),
    ("*TRG", Cmd::Trg),
];

/// One program message unit, resolved.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Unit {
    /// The command, or `None` for an undefined header (-113).
    pub cmd: Option<Cmd>,
    /// Ends in `?`.
    pub query: bool,
    /// Parameters, trimmed, quotes kept.
    pub params: Vec<String>,
    /// The header as sent, for logs.
    pub header: String,
}

/// Splits a line at `;` outside quotes.
fn split_units(line: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    let mut quote: Option<char> = None;
    for (i, c) in line.char_indices() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, ';') => {
                out.push(&line[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(&line[start..]);
    out
}

/// Splits parameters at `,` outside quotes.
fn split_params(text: &str) -> Vec<String> {
    let text = text.trim();
    if text.is_empty() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quote: Option<char> = None;
    for c in text.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => {
                quote = None;
                cur.push(c);
            }
            (None, '"' | '\'') => {
                quote = Some(c);
                cur.push(c);
            }
            (None, ',') => out.push(std::mem::take(&mut cur).trim().to_string()),
            _ => cur.push(c),
        }
    }
    out.push(cur.trim().to_string());
    out
}

/// Whether `given` (upper case) names the mnemonic `pattern` (short form in upper case letters).
fn mnemonic_matches(pattern: &str, given: &str) -> bool {
    let short: String = pattern.chars().filter(|c| c.is_ascii_uppercase()).collect();
    given == short || given == pattern.to_ascii_uppercase()
}

/// Matches `given` nodes against a pattern's `(mnemonic, optional)` nodes.
fn matches(pattern: &[(&str, bool)], given: &[String]) -> bool {
    match (pattern.split_first(), given.split_first()) {
        (None, None) => true,
        (None, Some(_)) => false,
        (Some(((_, true), rest)), None) => matches(rest, given),
        (Some(_), None) => false,
        (Some(((m, opt), prest)), Some((g, grest))) => {
            (mnemonic_matches(m, g) && matches(prest, grest)) || (*opt && matches(prest, given))
        }
    }
}

fn parse_pattern(p: &str) -> Vec<(&str, bool)> {
    let mut nodes = Vec::new();
    let mut rest = p;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix('[') {
            let end = r.find(']').unwrap_or(r.len());
            let node = r[..end].trim_matches(':');
            nodes.push((node, true));
            rest = r.get(end + 1..).unwrap_or("");
        } else {
            let r = rest.trim_start_matches(':');
            let end = r.find([':', '[']).unwrap_or(r.len());
            nodes.push((&r[..end], false));
            rest = &r[end..];
        }
    }
    nodes
}

fn lookup(nodes: &[String]) -> Option<Cmd> {
    TREE.iter()
        .find(|(p, _)| matches(&parse_pattern(p), nodes))
        .map(|&(_, c)| c)
}

/// Parses one program message (a line) into units. `path` is the current subsystem path,
/// updated as SCPI says (a new line starts at the root).
pub(crate) fn parse_line(line: &str) -> Vec<Unit> {
    let mut path: Vec<String> = Vec::new();
    let mut out = Vec::new();
    for raw in split_units(line) {
        let raw = raw.trim_start();
        if raw.trim().is_empty() {
            continue;
        }
        let (header, params) = match raw.find(char::is_whitespace) {
            Some(i) => (&raw[..i], &raw[i..]),
            None => (raw, ""),
        };
        let query = header.ends_with('?');
        let name = header.trim_end_matches('?').to_ascii_uppercase();
        let params = split_params(params);
        let cmd = if name.starts_with('*') {
            COMMON.iter().find(|(n, _)| *n == name).map(|&(_, c)| c)
        } else {
            let absolute = name.starts_with(':');
            let given: Vec<String> = name
                .trim_start_matches(':')
                .split(':')
                .map(str::to_string)
                .collect();
            let mut full = if absolute { Vec::new() } else { path.clone() };
            full.extend(given);
            let found = lookup(&full);
            if found.is_some() {
                full.pop();
                path = full;
            }
            found
        };
        out.push(Unit {
            cmd,
            query,
            params,
            header: header.to_string(),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmds(line: &str) -> Vec<(Option<Cmd>, bool)> {
        parse_line(line)
            .into_iter()
            .map(|u| (u.cmd, u.query))
            .collect()
    }

    #[test]
    fn long_short_case_and_optional_nodes() {
        assert_eq!(cmds("SYST:REM"), [(Some(Cmd::Remote), false)]);
        assert_eq!(cmds("system:remote"), [(Some(Cmd::Remote), false)]);
        assert_eq!(cmds("SYSTEM:REMOTE"), [(Some(Cmd::Remote), false)]);
        assert_eq!(cmds("SYSTEM:REMOT"), [(None, false)]);
        assert_eq!(cmds("VOLTAG:DC:NPLC 1"), [(None, false)]);
        assert_eq!(cmds("SENS:VOLT:DC:NPLC 1"), [(Some(Cmd::Nplc), false)]);
        assert_eq!(cmds("volt:nplc?"), [(Some(Cmd::Nplc), true)]);
        assert_eq!(cmds("SYST:ERR?"), [(Some(Cmd::Error), true)]);
        assert_eq!(cmds("SYST:ERR:NEXT?"), [(Some(Cmd::Error), true)]);
        assert_eq!(cmds("*idn?"), [(Some(Cmd::Idn), true)]);
        assert_eq!(cmds("*WAI"), [(None, false)]);
        assert_eq!(cmds("ABOR"), [(None, false)]);
    }

    #[test]
    fn chaining_is_relative_and_colon_returns_to_root() {
        assert_eq!(
            cmds("TRIG:SOUR IMM;DEL 0.1;COUN 1"),
            [
                (Some(Cmd::TrigSource), false),
                (Some(Cmd::TrigDelay), false),
                (Some(Cmd::TrigCount), false)
            ]
        );
        assert_eq!(
            cmds("TRIG:SOUR IMM;SAMP:COUN 5"),
            [(Some(Cmd::TrigSource), false), (None, false)]
        );
        assert_eq!(
            cmds("TRIG:SOUR IMM;:SAMP:COUN 5;*OPC?;COUN?"),
            [
                (Some(Cmd::TrigSource), false),
                (Some(Cmd::SampleCount), false),
                (Some(Cmd::Opc), true),
                (Some(Cmd::SampleCount), true)
            ]
        );
        assert_eq!(
            cmds("INIT;*OPC?"),
            [(Some(Cmd::Init), false), (Some(Cmd::Opc), true)]
        );
        let u = parse_line("DISP:TEXT \"A;B,C\"");
        assert_eq!(u.len(), 1);
        assert_eq!(u[0].params, ["\"A;B,C\""]);
    }
}
