//! Station files: parsing, refusals with file/line/key, calibration due dates, where the file
//! is found, and the simulated bench's record.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use gyrocal_files::station::{
    MeterAccuracySpec, STATION_ENV, SpecPeriod, Station, StationErrorKind,
};
use jiff::civil::{Date, date};

fn example_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/station.example.toml")
}

const GOOD: &str = r#"id = "bench-2"
lab = "Lab"
address = "1 Road"

[multimeter]
model = "HP 34401A"
asset_id = "DMM-07"
serial = "3146A12345"
certificate = "C-1"
calibrated = 2025-04-12
due = 2026-04-12
accuracy = "90d"

[table]
model = "ACL"
asset_id = "RT-01"
serial = "T-1"
certificate = "C-2"
calibrated = "2024-11-07"
due = "2026-11-07"
rate_accuracy_ppm = 10
"#;

fn parse(src: &str) -> Station {
    Station::from_toml_str(src, Path::new("station.toml")).unwrap_or_else(|e| panic!("{e}"))
}

fn err(src: &str) -> String {
    Station::from_toml_str(src, Path::new("station.toml"))
        .expect_err("must be refused")
        .to_string()
}

/// GOOD with `from` (which must occur) replaced.
fn bad(from: &str, to: &str) -> String {
    assert!(GOOD.contains(from), "{from}");
    err(&GOOD.replacen(from, to, 1))
}

#[test]
fn the_example_parses() {
    let s = Station::from_file(&example_path()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.id, "bench-2");
    assert_eq!(s.ambient_c, Some(23.0));
    assert_eq!(s.humidity_pct, Some(45.0));
    assert_eq!(s.catalog, None);
    let m = s.multimeter.as_ref().unwrap();
    assert_eq!(m.model, "HP 34401A");
    assert_eq!(m.due, date(2026, 4, 12));
    assert_eq!(
        s.meter_accuracy(),
        Some(MeterAccuracySpec::Period(SpecPeriod::Year1))
    );
    assert_eq!(s.table_rate_accuracy_ppm(), Some(10.0));
    let roles: Vec<&str> = s.instruments().iter().map(|(r, _)| *r).collect();
    assert_eq!(roles, ["multimeter", "table"]);
}

#[test]
fn text_and_toml_dates_and_json_round_trip() {
    let s = parse(GOOD);
    assert_eq!(s.multimeter.as_ref().unwrap().calibrated, date(2025, 4, 12));
    assert_eq!(s.table.as_ref().unwrap().calibrated, date(2024, 11, 7));
    assert_eq!(
        s.meter_accuracy(),
        Some(MeterAccuracySpec::Period(SpecPeriod::Days90))
    );
    let json = serde_json::to_value(&s).unwrap();
    assert_eq!(json["multimeter"]["due"], "2026-04-12");
    assert_eq!(json["multimeter"]["accuracy"], "90d");
    assert!(json.get("catalog").is_none());
    let back: Station = serde_json::from_value(json).unwrap();
    assert_eq!(back, s);
    // instruments are optional; catalog is kept
    let bare =
        parse("id = \"b\"\nlab = \"L\"\naddress = \"A\"\ncatalog = \"https://lims.example.org\"\n");
    assert!(bare.instruments().is_empty());
    assert_eq!(bare.meter_accuracy(), None);
    assert_eq!(bare.catalog.as_deref(), Some("https://lims.example.org"));
}

#[test]
fn explicit_meter_accuracy_overrides_the_period() {
    let s = parse(&GOOD.replace(
        "accuracy = \"90d\"",
        "accuracy = \"90d\"\ngain_pct = 0.003\noffset_pct = 0.0004",
    ));
    assert_eq!(
        s.meter_accuracy(),
        Some(MeterAccuracySpec::Explicit {
            gain_pct: 0.003,
            offset_pct: 0.0004
        })
    );
    let e = bad("accuracy = \"90d\"", "gain_pct = 0.003");
    assert!(
        e.contains("[multimeter] offset_pct is missing: gain_pct and offset_pct go together"),
        "{e}"
    );
}

#[test]
fn overdue_is_after_the_due_date() {
    let s = parse(GOOD);
    assert!(
        s.overdue(date(2026, 4, 12)).is_empty(),
        "the due date is still valid"
    );
    let o = s.overdue(date(2026, 4, 13));
    assert_eq!(o.len(), 1);
    assert_eq!(o[0].role, "multimeter");
    assert_eq!(o[0].asset_id, "DMM-07");
    assert_eq!(o[0].due, date(2026, 4, 12));
    assert_eq!(
        o[0].to_string(),
        "the multimeter DMM-07 was due for calibration on 2026-04-12"
    );
    assert_eq!(s.overdue(date(2030, 1, 1)).len(), 2);
    assert!(s.overdue(date(2025, 1, 1)).is_empty());
}

#[test]
fn refusals_name_the_file_line_and_key() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "id = \"bench-2\"",
            "idd = \"x\"",
            "station.toml:1:1: idd is an unknown key: did you mean `id`?",
        ),
        (
            "serial = \"3146A12345\"",
            "seriel = \"3146A12345\"",
            "station.toml:8:1: [multimeter] seriel is an unknown key: did you mean `serial`?",
        ),
        (
            "[table]",
            "[tabel]",
            "station.toml:14:2: tabel is an unknown section",
        ),
        ("due = 2026-04-12", "due = 2026-13-12", "station.toml:"),
        (
            "due = 2026-04-12",
            "due = \"12.04.2026\"",
            "station.toml:11:7: [multimeter] due = \"12.04.2026\" is not a date: write YYYY-MM-DD",
        ),
        (
            "due = 2026-04-12",
            "due = 2026-04-12T10:00:00",
            "station.toml:11:7: [multimeter] due = 2026-04-12T10:00:00 has a time of day",
        ),
        (
            "due = 2026-04-12",
            "due = 2020-01-01",
            "station.toml:11:7: [multimeter] due = 2020-01-01 is before calibrated = 2025-04-12",
        ),
        (
            "due = 2026-04-12",
            "due = 20260412",
            "station.toml:11:7: [multimeter] due = 20260412 is integer: write a date",
        ),
        (
            "accuracy = \"90d\"",
            "accuracy = \"2y\"",
            "station.toml:12:12: [multimeter] accuracy = \"2y\" is not a specification period: write \"24h\", \"90d\" or \"1y\"",
        ),
        (
            "rate_accuracy_ppm = 10",
            "rate_accuracy_ppm = -1",
            "station.toml:21:21: [table] rate_accuracy_ppm = -1 is out of range",
        ),
        (
            "rate_accuracy_ppm = 10",
            "rate_accuracy_ppm = \"10\"",
            "station.toml:21:21: [table] rate_accuracy_ppm = \"10\" is text, not a number",
        ),
        (
            "rate_accuracy_ppm = 10",
            "accuracy = \"1y\"",
            "station.toml:21:12: [table] accuracy belongs to the multimeter",
        ),
        (
            "accuracy = \"90d\"",
            "rate_accuracy_ppm = 5",
            "station.toml:12:21: [multimeter] rate_accuracy_ppm belongs to the table",
        ),
        (
            "model = \"ACL\"\n",
            "",
            "station.toml:14:2: [table] model is missing (required)",
        ),
        (
            "certificate = \"C-1\"",
            "certificate = \"\"",
            "station.toml:9:15: [multimeter] certificate must not be empty",
        ),
        (
            "serial = \"3146A12345\"",
            "serial = 3146",
            "station.toml:8:10: [multimeter] serial = 3146 is integer: write text in quotes",
        ),
        (
            "lab = \"Lab\"\n",
            "",
            "station.toml: lab is missing (required)",
        ),
        (
            "address = \"1 Road\"",
            "address = \"1 Road\"\nhumidity_pct = 120",
            "station.toml:4:16: humidity_pct = 120 is out of range: write a number from 0 to 100",
        ),
        (
            "address = \"1 Road\"",
            "address = \"1 Road\"\nambient_c = nan",
            "station.toml:4:13: ambient_c = nan is out of range",
        ),
        ("id = \"bench-2\"", "id = \"bench-2", "station.toml:1:"),
    ];
    for (from, to, want) in cases {
        let e = bad(from, to);
        assert!(
            e.starts_with(want),
            "{from} -> {to}:\n  got  {e}\n  want {want}..."
        );
    }
    let e = err("id = \"b\"\nlab = \"L\"\naddress = \"A\"\ntable = 5\n");
    assert!(
        e.starts_with("station.toml:4:1: table must be a section"),
        "{e}"
    );
    // the first problem in the file is the one reported
    let e = err(&GOOD
        .replace("serial = \"T-1\"", "serial = 1")
        .replace("model = \"HP 34401A\"", "model = 2"));
    assert!(e.starts_with("station.toml:6:9: [multimeter] model"), "{e}");
    let k = Station::from_toml_str("id = [", Path::new("s.toml")).unwrap_err();
    assert_eq!(k.kind(), StationErrorKind::Syntax);
    let k = Station::from_toml_str("x = 1", Path::new("s.toml")).unwrap_err();
    assert_eq!(k.kind(), StationErrorKind::Invalid);
}

#[test]
fn reading_is_capped_and_names_the_file() {
    // a device (or a named pipe) is refused before it is opened
    let e = Station::from_file(Path::new("/dev/zero")).unwrap_err();
    assert_eq!(e.kind(), StationErrorKind::Read);
    assert!(
        e.to_string()
            .starts_with("/dev/zero: cannot read the station file: a device"),
        "{e}"
    );
    let tmp = tempfile::tempdir().unwrap();
    let sparse = tmp.path().join("huge.toml");
    std::fs::File::create(&sparse)
        .unwrap()
        .set_len(8 << 20)
        .unwrap();
    let e = Station::from_file(&sparse).unwrap_err();
    assert_eq!(e.kind(), StationErrorKind::TooLarge);
    assert!(
        e.to_string()
            .ends_with("larger than the 1024 KiB limit for a station file (a station file is a few hundred bytes); is it the right file?"),
        "{e}"
    );
    let e = Station::from_file(Path::new("/nonexistent/station.toml")).unwrap_err();
    assert_eq!(e.kind(), StationErrorKind::Read);
    assert!(
        e.to_string()
            .starts_with("/nonexistent/station.toml: cannot read the station file"),
        "{e}"
    );
}

/// An environment of the given variables only.
fn env_of(vars: &[(&str, &Path)]) -> impl Fn(&str) -> Option<OsString> + use<> {
    let vars: Vec<(String, OsString)> = vars
        .iter()
        .map(|(k, v)| (k.to_string(), v.as_os_str().to_owned()))
        .collect();
    move |k| vars.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone())
}

#[test]
fn resolve_prefers_the_flag_then_the_variable_then_the_default() {
    let tmp = tempfile::tempdir().unwrap();
    let write = |name: &str, id: &str| {
        let p = tmp.path().join(name);
        std::fs::write(&p, GOOD.replace("bench-2", id)).unwrap();
        p
    };
    let flag = write("flag.toml", "from-flag");
    let var = write("var.toml", "from-env");
    let default = write("default.toml", "from-default");
    let missing = tmp.path().join("missing.toml");
    let id = |r: Option<(PathBuf, Station)>| r.map(|(_, s)| s.id);

    let env = env_of(&[(STATION_ENV, &var)]);
    let got = Station::resolve_with(Some(&flag), &env, Some(default.clone())).unwrap();
    assert_eq!(id(got).as_deref(), Some("from-flag"));
    let got = Station::resolve_with(None, &env, Some(default.clone())).unwrap();
    assert_eq!(got.as_ref().map(|(p, _)| p.clone()), Some(var.clone()));
    assert_eq!(id(got).as_deref(), Some("from-env"));
    let none = env_of(&[]);
    let got = Station::resolve_with(None, &none, Some(default.clone())).unwrap();
    assert_eq!(id(got).as_deref(), Some("from-default"));
    // no default file: no station
    assert!(
        Station::resolve_with(None, &none, Some(missing.clone()))
            .unwrap()
            .is_none()
    );
    assert!(Station::resolve_with(None, &none, None).unwrap().is_none());
    // an empty variable is unset
    let empty = |k: &str| (k == STATION_ENV).then(OsString::new);
    let got = Station::resolve_with(None, empty, Some(default.clone())).unwrap();
    assert_eq!(id(got).as_deref(), Some("from-default"));
    // a named file that does not exist is an error, naming where the name came from
    let e = Station::resolve_with(Some(&missing), &none, Some(default.clone())).unwrap_err();
    assert_eq!(e.kind(), StationErrorKind::NotFound);
    assert!(
        e.to_string()
            .ends_with("no such station file (given by --station)"),
        "{e}"
    );
    let e =
        Station::resolve_with(None, env_of(&[(STATION_ENV, &missing)]), Some(default)).unwrap_err();
    assert!(e.to_string().ends_with("(given by GYROCAL_STATION)"), "{e}");
    // a bad file is its own error
    std::fs::write(&missing, "id = 1").unwrap();
    let e = Station::resolve_with(Some(&missing), &none, None).unwrap_err();
    assert_eq!(e.kind(), StationErrorKind::Invalid);
}

#[test]
fn the_default_path_follows_xdg() {
    let xdg = Station::default_path_from(env_of(&[
        ("XDG_CONFIG_HOME", Path::new("/cfg")),
        ("HOME", Path::new("/home/op")),
    ]));
    assert_eq!(xdg, Some(PathBuf::from("/cfg/gyrocal/station.toml")));
    let home = Station::default_path_from(env_of(&[
        ("XDG_CONFIG_HOME", Path::new("relative")),
        ("HOME", Path::new("/home/op")),
    ]));
    assert_eq!(
        home,
        Some(PathBuf::from("/home/op/.config/gyrocal/station.toml"))
    );
    assert_eq!(Station::default_path_from(env_of(&[])), None);
}

#[test]
fn the_simulated_bench_is_complete_and_valid() {
    let today: Date = date(2026, 5, 1);
    let s = Station::simulated(1, today);
    assert_eq!(s.lab, "gyrocal simulated bench");
    let m = s.multimeter.as_ref().unwrap();
    let t = s.table.as_ref().unwrap();
    assert_eq!(m.serial, "SIM-34401A-0001");
    assert_eq!(t.serial, "SIM-ACL-0001");
    assert_eq!(m.certificate, "SIMULATED");
    assert_eq!(m.calibrated, today);
    assert!(s.overdue(date(2035, 1, 1)).is_empty());
    assert_eq!(
        s.meter_accuracy(),
        Some(MeterAccuracySpec::Period(SpecPeriod::Year1))
    );
    assert_eq!(s.table_rate_accuracy_ppm(), Some(10.0));
    // its JSON reads back
    let back: Station = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
    assert_eq!(back, s);
    // at the end of the calendar it still works
    let late = Station::simulated(7, date(9999, 12, 31));
    assert!(late.overdue(date(9999, 12, 31)).is_empty());
}

/// `serve` names the lab's live view: kept (without a trailing slash) for `gyrocal run` to
/// print the run's page on it; anything but an http(s) address is refused naming the line
/// and the key.
#[test]
fn serve_is_the_address_of_the_live_view() {
    let s = parse("id = \"b\"\nlab = \"L\"\naddress = \"A\"\nserve = \"http://lab-view:8737/\"\n");
    assert_eq!(s.serve.as_deref(), Some("http://lab-view:8737"));
    assert_eq!(parse(GOOD).serve, None);
    let e = err("id = \"b\"\nlab = \"L\"\naddress = \"A\"\nserve = \"lab-view:8737\"\n");
    assert!(e.contains("station.toml:4") && e.contains("serve"), "{e}");
    let e = err("id = \"b\"\nlab = \"L\"\naddress = \"A\"\nserve = 8737\n");
    assert!(e.contains("serve"), "{e}");
}
