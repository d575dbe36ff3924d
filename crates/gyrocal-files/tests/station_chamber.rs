//! The station's `[chamber]` (issue 26): parsed and refused like the meter and the table,
//! counted among the missing sections and the overdue instruments only for a plan that needs
//! it, and its record compared with the controller that answered.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;

use gyrocal_files::station::{Needs, SerialCheck, Station};
use jiff::civil::date;

const WITH_CHAMBER: &str = r#"id = "bench-2"
lab = "Lab"
address = "1 Road"

[multimeter]
model = "HP 34401A"
asset_id = "DMM-07"
serial = "3146A12345"
certificate = "C-1"
calibrated = 2025-04-12
due = 2027-04-12

[table]
model = "ACL"
asset_id = "RT-01"
serial = "T-1"
certificate = "C-2"
calibrated = 2024-11-07
due = 2027-11-07

[chamber]
model = "Thermotron SE-600 (Watlow F4)"
asset_id = "TC-03"
serial = "SE600-1187"
certificate = "C-3"
calibrated = 2025-09-30
due = 2026-09-30
"#;

const SERIES: Needs = Needs {
    table: true,
    chamber: true,
};
const SWEEP: Needs = Needs {
    table: true,
    chamber: false,
};

fn parse(src: &str) -> Station {
    Station::from_toml_str_on(src, Path::new("station.toml"), date(2026, 6, 1))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn err(src: &str) -> String {
    Station::from_toml_str_on(src, Path::new("station.toml"), date(2026, 6, 1))
        .expect_err("must be refused")
        .to_string()
}

/// WITH_CHAMBER without its `[chamber]` section.
fn without_chamber() -> String {
    let at = WITH_CHAMBER.find("\n[chamber]").unwrap();
    WITH_CHAMBER[..=at].to_string()
}

#[test]
fn the_chamber_is_an_instrument_like_the_table() {
    let s = parse(WITH_CHAMBER);
    let c = s.chamber.as_ref().expect("a [chamber]");
    assert_eq!(c.asset_id, "TC-03");
    assert_eq!(c.due, date(2026, 9, 30));
    let roles: Vec<&str> = s.instruments().iter().map(|(r, _)| *r).collect();
    assert_eq!(roles, vec!["multimeter", "table", "chamber"]);
    // its JSON (the manifest's station) reads back; a station without one writes no key
    let back: Station = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
    assert_eq!(back, s);
    let plain = parse(&without_chamber());
    assert!(!serde_json::to_string(&plain).unwrap().contains("chamber"));
}

#[test]
fn a_chamber_key_that_is_wrong_is_refused_naming_the_line_and_key() {
    let cases = [
        (
            "serial = \"SE600-1187\"",
            "serail = \"SE600-1187\"",
            "station.toml:24:1: [chamber] serail is an unknown key: did you mean `serial`?",
        ),
        (
            "certificate = \"C-3\"\n",
            "certificate = \"C-3\"\nrate_accuracy_ppm = 10\n",
            "station.toml:26:21: [chamber] rate_accuracy_ppm belongs to the table",
        ),
        (
            "certificate = \"C-3\"\n",
            "certificate = \"C-3\"\naccuracy = \"1y\"\n",
            "[chamber] accuracy belongs to the multimeter",
        ),
        (
            "due = 2026-09-30",
            "due = 2025-01-01",
            "station.toml:27:7: [chamber] due = 2025-01-01 is before calibrated = 2025-09-30",
        ),
        (
            "calibrated = 2025-09-30",
            "calibrated = 2026-07-01",
            "[chamber] calibrated = 2026-07-01 is after today (2026-06-01): the chamber TC-03",
        ),
        (
            "asset_id = \"TC-03\"\n",
            "",
            "[chamber] asset_id is missing (required): add `asset_id = ...` under [chamber]",
        ),
    ];
    for (from, to, says) in cases {
        let at = WITH_CHAMBER.rfind(from).unwrap();
        let src = format!(
            "{}{to}{}",
            &WITH_CHAMBER[..at],
            &WITH_CHAMBER[at + from.len()..]
        );
        let e = err(&src);
        assert!(
            e.contains(says),
            "{from:?} -> {to:?}:\n{e}\nshould say\n{says}"
        );
    }
    // `chamber = "x"` (at the top, before any section) is not a section
    let e = err(&format!("chamber = \"x\"\n{}", without_chamber()));
    assert!(e.contains("chamber must be a section"), "{e}");
}

#[test]
fn a_series_needs_a_chamber_and_a_sweep_does_not() {
    let plain = parse(&without_chamber());
    assert_eq!(plain.missing_sections(SERIES), vec!["chamber"]);
    assert!(plain.missing_sections(SWEEP).is_empty());
    assert!(parse(WITH_CHAMBER).missing_sections(SERIES).is_empty());
    // a drift record without a table needs only the meter
    let meter_only = Station {
        table: None,
        ..plain
    };
    assert!(meter_only.missing_sections(Needs::default()).is_empty());
    assert_eq!(
        meter_only.missing_sections(SERIES),
        vec!["table", "chamber"]
    );
}

#[test]
fn an_overdue_chamber_refuses_a_series_only() {
    let s = parse(WITH_CHAMBER);
    // valid through its due date
    assert!(s.overdue_for(date(2026, 9, 30), SERIES).is_empty());
    let late = s.overdue_for(date(2026, 10, 1), SERIES);
    assert_eq!(late.len(), 1);
    assert_eq!(late[0].role, "chamber");
    assert_eq!(
        late[0].to_string(),
        "the chamber TC-03 was due for calibration on 2026-09-30"
    );
    // a sweep on the same bench does not use the chamber
    assert!(s.overdue_for(date(2026, 10, 1), SWEEP).is_empty());
    // and overdue() still lists every instrument
    assert_eq!(s.overdue(date(2026, 10, 1)).len(), 1);
}

#[test]
fn the_controller_that_answered_is_checked_against_the_record() {
    let s = parse(WITH_CHAMBER);
    let c = s.check_chamber(Some("Watlow F4"), None);
    assert!(
        matches!(&c[0], SerialCheck::ModelMatch { role: "chamber", model } if model == "Watlow F4")
    );
    // neither dialect reports a serial: said, never a mismatch
    assert!(matches!(&c[1], SerialCheck::NotCompared { why, .. } if why.contains("no serial")));
    assert!(!c.iter().any(SerialCheck::is_mismatch));

    // an Espec on the port of a chamber the station says has a Watlow: a warning naming both
    let c = s.check_chamber(Some("Espec SH-641"), None);
    assert!(c[0].is_mismatch());
    assert_eq!(c[0].key(), "model-mismatch");
    let w = c[0].words("bench-2");
    assert!(
        w.contains("TC-03")
            && w.contains("Thermotron SE-600 (Watlow F4)")
            && w.contains("Espec SH-641")
            && w.contains("thermal chamber"),
        "{w}"
    );

    // a serial, when a controller reports one, is compared like the table's
    let c = s.check_chamber(Some("Watlow F4"), Some(" se600-1187 "));
    assert!(matches!(&c[1], SerialCheck::Match { .. }), "{c:?}");
    let c = s.check_chamber(Some("Watlow F4"), Some("OTHER-9"));
    assert!(c[1].is_mismatch());

    // no [chamber]: nothing to compare, said
    let plain = parse(&without_chamber());
    let c = plain.check_chamber(Some("Watlow F4"), None);
    assert_eq!(c.len(), 1);
    assert!(matches!(&c[0], SerialCheck::NotCompared { why, .. } if why.contains("[chamber]")));
}

#[test]
fn the_simulated_bench_with_a_chamber_names_its_controller() {
    let today = date(2026, 5, 1);
    let s = Station::simulated_with_chamber(3, today, "Watlow F4");
    let c = s.chamber.as_ref().unwrap();
    assert_eq!(c.serial, "SIM-CH-0003");
    assert_eq!(c.certificate, "SIMULATED");
    assert!(s.missing_sections(SERIES).is_empty());
    assert!(s.overdue_for(date(2035, 1, 1), SERIES).is_empty());
    assert!(
        !s.check_chamber(Some("Watlow F4"), None)
            .iter()
            .any(SerialCheck::is_mismatch)
    );
    // the plain simulated bench has none (a sweep's certificate names no chamber)
    assert!(Station::simulated(3, today).chamber.is_none());
}

/// A plan of the repository's configs.
fn config_plan(name: &str) -> gyrocal_files::Plan {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../configs")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    gyrocal_files::Plan::from_toml_str(&text, &path).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn the_series_plan_needs_a_chamber_and_the_sweep_plan_does_not() {
    let series = config_plan("series.toml");
    assert_eq!(Needs::of_plan(&series), SERIES);
    let sweep = config_plan("quick.toml");
    assert_eq!(Needs::of_plan(&sweep), SWEEP);
    // so a station without [chamber] lacks it for the one and not the other
    let plain = parse(&without_chamber());
    assert_eq!(
        plain.missing_sections(Needs::of_plan(&series)),
        vec!["chamber"]
    );
    assert!(plain.missing_sections(Needs::of_plan(&sweep)).is_empty());
    // the simulated bench of a series records its chamber, the sweep's none
    let today = date(2026, 5, 1);
    let sim = Station::simulated_for(5, today, &series);
    assert!(sim.missing_sections(SERIES).is_empty());
    assert!(Station::simulated_for(5, today, &sweep).chamber.is_none());
}
