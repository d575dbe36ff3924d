//! The EXAMPLES section at the end of every subcommand's long help (`gyrocal run --help`) and
//! man page (`gyrocal man`): a few realistic invocations, each with a few words.
//!
//! Why one file: the texts are kept together so they read as a set (the same run directory
//! names, the same serial) and so that the unit test below can parse every one of them with
//! the real argument definitions: an option renamed in `cmd/*.rs` fails that test here, naming
//! the example, instead of leaving a stale example in the help. The subcommands' own modules
//! are not touched; [`attach`] is hooked onto the whole command in `main.rs` (clap's
//! `mut_subcommands`), so `--help`, the man pages and the completions all see one definition.
//!
//! Rules for an example (checked by the tests): it starts with `gyrocal SUBCOMMAND`, its words
//! are separated by single spaces and need no shell quoting or redirection, and a file it names
//! under `configs/` exists in the repository.

use clap::Command;

/// One example: the command line and what it does.
#[derive(Debug, Clone, Copy)]
pub struct Example {
    /// The command as typed (no quotes, no redirection).
    pub command: &'static str,
    /// What it does, in a few words.
    pub what: &'static str,
}

const fn ex(command: &'static str, what: &'static str) -> Example {
    Example { command, what }
}

/// The examples of each subcommand, by its path below `gyrocal` ("run", "catalog import").
pub const EXAMPLES: &[(&str, &[Example])] = &[
    (
        "fit",
        &[
            ex(
                "gyrocal fit runs/paper-2026-04-12T091500.000Z",
                "fit a run directory's steps.csv with every model its rates support",
            ),
            ex(
                "gyrocal fit steps.csv --model linear,quadratic --method least-squares,neuron",
                "only these models and methods (comma lists)",
            ),
            ex(
                "gyrocal fit monday/steps.csv tuesday/steps.csv --json",
                "two calibrations: each fitted, their repeatability, one JSON document",
            ),
            ex(
                "gyrocal fit samples.csv --json --residuals",
                "every point's residual, streamed (for plotting elsewhere)",
            ),
        ],
    ),
    (
        "check",
        &[
            ex(
                "gyrocal check configs/paper.toml",
                "validate a plan; print its schedule, duration and acceptance limits",
            ),
            ex(
                "gyrocal check my-gyro.toml --station station.toml",
                "also read the station file as a run would",
            ),
            ex(
                "gyrocal check my-gyro.toml --probe --dmm-port /dev/ttyUSB0 --table-port /dev/ttyUSB1",
                "ask both instruments who they are, moving nothing",
            ),
            ex(
                "gyrocal check configs/drift.toml --json",
                "a drift plan's schedule as JSON",
            ),
        ],
    ),
    (
        "run",
        &[
            ex(
                "gyrocal run configs/paper.toml --simulate",
                "the full calibration on the simulated bench, in virtual time (seconds)",
            ),
            ex(
                "gyrocal run my-gyro.toml --dmm-port /dev/ttyUSB0 --table-port /dev/ttyUSB1 --dut-serial HRG-0042",
                "on the instruments, naming the gyro under test",
            ),
            ex(
                "gyrocal run --resume runs/my-gyro-2026-04-12T091500.000Z",
                "continue a run stopped by Ctrl-C, a crash or a fault",
            ),
            ex(
                "gyrocal run configs/quick.toml --simulate --sim-fault table:trip@demand3 --fail-on-verdict",
                "rehearse a table trip; in CI, exit 3 on a refused verdict",
            ),
        ],
    ),
    (
        "sim",
        &[
            ex(
                "gyrocal sim --time-scale 50 --seed 7",
                "serve the simulated meter and table on two pseudo-terminals, 50 times faster than real",
            ),
            ex(
                "gyrocal sim --config configs/quick.toml --fault dmm:garble@reading40",
                "the bench a plan describes, with a garbled 40th reading",
            ),
            ex(
                "gyrocal sim --dmm 34461a --link lan --table aerosmith",
                "a Truevolt on its LAN socket and an Aerosmith table",
            ),
        ],
    ),
    (
        "report",
        &[
            ex(
                "gyrocal report runs/paper-2026-04-12T091500.000Z",
                "(re)write report.html in the run directory",
            ),
            ex(
                "gyrocal report runs/monday runs/tuesday -o both.html",
                "one report of two runs, with their repeatability",
            ),
            ex(
                "gyrocal report runs/paper-2026-04-12T091500.000Z --acceptance configs/acceptance.example.toml -o judged.html",
                "judge a run against other limits",
            ),
        ],
    ),
    (
        "verify",
        &[
            ex(
                "gyrocal verify runs/paper-2026-04-12T091500.000Z",
                "check a run's files against the SHA-256 its manifest recorded",
            ),
            ex(
                "gyrocal verify runs/monday runs/tuesday",
                "several runs; exit 1 if any file changed or went missing",
            ),
        ],
    ),
    (
        "runs",
        &[
            ex("gyrocal runs", "every catalogued run, newest first"),
            ex(
                "gyrocal runs --serial HRG-0042 --since 2026-01-01",
                "one gyro's runs this year",
            ),
            ex(
                "gyrocal runs --status running --json",
                "runs still marked running (or killed), as JSON",
            ),
        ],
    ),
    (
        "history",
        &[
            ex(
                "gyrocal history HRG-0042",
                "a gyro's calibrations, repeatability and trend warnings",
            ),
            ex(
                "gyrocal history HRG-0042 -o history.html",
                "the same as a page with trend plots and limits",
            ),
            ex(
                "gyrocal history SIM-HRG-1 --include-simulated --json",
                "count simulated runs too, as JSON",
            ),
        ],
    ),
    (
        "catalog",
        &[
            ex(
                "gyrocal catalog import runs/paper-2026-04-12T091500.000Z",
                "add a run directory to the catalog",
            ),
            ex(
                "gyrocal catalog rebuild runs",
                "rebuild the catalog from every run directory under runs/",
            ),
            ex(
                "gyrocal catalog rebuild runs --catalog postgres://cal@db.lab/gyrocal",
                "fill a lab's shared PostgreSQL catalog",
            ),
        ],
    ),
    (
        "catalog import",
        &[
            ex(
                "gyrocal catalog import runs/paper-2026-04-12T091500.000Z",
                "add one run directory",
            ),
            ex(
                "gyrocal catalog import runs/monday runs/tuesday --catalog sqlite:lab.sqlite",
                "add two, to a catalog file of your choice",
            ),
        ],
    ),
    (
        "catalog rebuild",
        &[
            ex(
                "gyrocal catalog rebuild runs",
                "the default catalog holds exactly the runs under runs/",
            ),
            ex(
                "gyrocal catalog rebuild /data/gyro-runs --catalog postgres://cal@db.lab/gyrocal",
                "add a whole tree to a lab's PostgreSQL catalog",
            ),
        ],
    ),
    (
        "serve",
        &[
            ex(
                "gyrocal serve",
                "the runs under runs/ live at http://127.0.0.1:8737/ (this machine only)",
            ),
            ex(
                "gyrocal serve --root /lab/runs --root /lab/old-runs --port 8080",
                "two run-directory roots on another port",
            ),
            ex(
                "gyrocal serve --bind 0.0.0.0",
                "for the lab's network, with the token from $GYROCAL_SERVE_TOKEN (required off this machine)",
            ),
        ],
    ),
    (
        "allan",
        &[
            ex(
                "gyrocal allan runs/drift-2026-04-12T091500.000Z -o allan.html",
                "a drift run's Allan deviation, noise terms and page",
            ),
            ex(
                "gyrocal allan record.csv --scale-factor 0.3612 --tau0 0.1",
                "a record without a time column, converted to °/h",
            ),
            ex(
                "gyrocal allan runs/drift-2026-04-12T091500.000Z --estimator mdev --taus decade --json",
                "the modified deviation at decade τ, as JSON",
            ),
            ex(
                "gyrocal allan runs/drift-2026-04-12T091500.000Z --join-gaps-below 60",
                "after a resume: join its gap as dead time instead of splitting the record",
            ),
        ],
    ),
    (
        "completions",
        &[
            ex(
                "gyrocal completions bash",
                "print the bash completion script",
            ),
            ex("gyrocal completions zsh", "the same for zsh"),
        ],
    ),
    (
        "man",
        &[
            ex("gyrocal man", "print gyrocal(1) as roff"),
            ex(
                "gyrocal man -o man1",
                "write gyrocal.1, gyrocal-run.1, ... into man1/",
            ),
        ],
    ),
];

/// The heading that starts the section (the tests look for it).
pub const HEADING: &str = "Examples:";

/// The examples of the subcommand at `path` ("run", "catalog import"), if any.
pub fn examples(path: &str) -> Option<&'static [Example]> {
    EXAMPLES
        .iter()
        .find(|(p, _)| *p == path)
        .map(|(_, list)| *list)
}

/// The section's text: the heading, then each example as a comment line and the command.
pub fn section(list: &[Example]) -> String {
    let mut text = String::from(HEADING);
    for e in list {
        text.push_str("\n  # ");
        text.push_str(e.what);
        text.push_str("\n  ");
        text.push_str(e.command);
    }
    text
}

/// Appends the EXAMPLES section to one subcommand's long help (after any text it already has
/// there, such as `gyrocal sim`'s fault grammar), and to its own subcommands'.
fn attach_to(cmd: Command, parent: &str) -> Command {
    let path = if parent.is_empty() {
        cmd.get_name().to_string()
    } else {
        format!("{parent} {}", cmd.get_name())
    };
    let cmd = match examples(&path) {
        Some(list) => {
            let text = match cmd.get_after_long_help() {
                Some(before) => format!("{before}\n\n{}", section(list)),
                None => section(list),
            };
            cmd.after_long_help(text)
        }
        None => cmd,
    };
    cmd.mut_subcommands(|sub| attach_to(sub, &path))
}

/// The hook for `main.rs`: every subcommand of `gyrocal` gets its examples.
pub fn attach(cmd: Command) -> Command {
    attach_to(cmd, "")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use super::*;
    use clap::{CommandFactory as _, Parser as _};

    /// Every subcommand's path below `gyrocal` ("run", "catalog import"), except `help`.
    fn paths(cmd: &Command, parent: &str, out: &mut Vec<String>) {
        for sub in cmd.get_subcommands() {
            if sub.get_name() == "help" {
                continue;
            }
            let path = if parent.is_empty() {
                sub.get_name().to_string()
            } else {
                format!("{parent} {}", sub.get_name())
            };
            paths(sub, &path, out);
            out.push(path);
        }
    }

    /// Each subcommand has 2 to 4 examples, and no examples are kept for a subcommand that is
    /// gone (they would never be shown).
    #[test]
    fn every_subcommand_has_two_to_four_examples_and_none_is_orphaned() {
        let mut all = Vec::new();
        paths(&crate::Cli::command(), "", &mut all);
        for path in &all {
            let n = examples(path).map_or(0, <[Example]>::len);
            assert!(
                (2..=4).contains(&n),
                "`gyrocal {path}` has {n} examples in src/examples.rs (2 to 4 wanted)"
            );
        }
        for (path, _) in EXAMPLES {
            assert!(
                all.iter().any(|p| p == path),
                "src/examples.rs has examples for `gyrocal {path}`, which is not a subcommand"
            );
        }
    }

    /// Every example parses with the real argument definitions, as the subcommand it is
    /// listed under: an option renamed or removed fails here, naming the example.
    #[test]
    fn every_example_parses_as_its_own_subcommand() {
        for (path, list) in EXAMPLES {
            for e in *list {
                let words: Vec<&str> = e.command.split(' ').collect();
                assert!(
                    !e.command
                        .contains(['\'', '"', '>', '<', '|', '\\', '$', '*', '`'])
                        && !words.iter().any(|w| w.is_empty()),
                    "example needs no quoting, no redirection, single spaces: {}",
                    e.command
                );
                let expected: Vec<&str> =
                    std::iter::once("gyrocal").chain(path.split(' ')).collect();
                assert_eq!(
                    &words[..expected.len()],
                    &expected[..],
                    "example listed under `gyrocal {path}` runs another command: {}",
                    e.command
                );
                if let Err(err) = crate::Cli::try_parse_from(&words) {
                    panic!("example `{}` does not parse:\n{err}", e.command);
                }
            }
        }
    }

    /// A file an example names under `configs/` is in the repository.
    #[test]
    fn the_configs_the_examples_name_exist() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        for (_, list) in EXAMPLES {
            for e in *list {
                for word in e.command.split(' ').filter(|w| w.starts_with("configs/")) {
                    assert!(
                        root.join(word).is_file(),
                        "example `{}` names {word}, which is not in the repository",
                        e.command
                    );
                }
            }
        }
    }

    /// The section ends the long help of the subcommand and keeps what was there before
    /// (`gyrocal sim`'s fault grammar).
    #[test]
    fn the_section_ends_the_long_help_after_any_text_already_there() {
        let mut cmd = crate::Cli::command();
        let sim = cmd.find_subcommand_mut("sim").unwrap();
        let help = sim.render_long_help().to_string();
        let at = help.find(HEADING).expect("sim's help has examples");
        assert!(
            help[..at].contains("Fault specs"),
            "the fault grammar is kept:\n{help}"
        );
        assert!(help[at..].contains("gyrocal sim --time-scale 50 --seed 7"));
        let import = crate::Cli::command()
            .find_subcommand("catalog")
            .unwrap()
            .find_subcommand("import")
            .unwrap()
            .clone()
            .render_long_help()
            .to_string();
        assert!(
            import.contains("gyrocal catalog import runs/monday"),
            "{import}"
        );
    }
}
