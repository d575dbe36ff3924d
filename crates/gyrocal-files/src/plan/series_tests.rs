//! Tests of the temperature series' plan: its keys' errors, its limits, its schedule and its
//! compile to steps.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests: a panic is a failed test

use std::path::Path;
use std::time::Duration;

use super::super::{ChamberModel, Plan, PlanKind, SafeStateChoice};
use super::*;
use crate::steps::{ChamberAction, Record};

const HEAD: &str = "[plan]\nkind = \"temperature_series\"\nname = \"s\"\nrates_dps = [0, 5, -5]\n\
    samples_per_rate = 20\nsettle_s = 3\nrepeat = 1\n\
    [table]\ndialect = \"acl\"\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n\
    [dmm]\nport = \"/dev/ttyUSB0\"\nrange_v = 10\nnplc = 1\nautozero = false\nline_hz = 50\n";

const SERIES: &str = "[series]\ntemperatures_c = [25, -20, 60, 25]\nmeasure = \"sweep\"\n\
    band_c = 0.5\nstability_c_per_min = 0.05\nsoak_min = 30\nmax_wait_min = 240\npoll_s = 10\n\
    bias_readings = 500\n";

const CHAMBER: &str = "[chamber]\nmodel = \"watlow_f4\"\nport = \"/dev/ttyUSB2\"\nbaud = 9600\n\
    slave = 1\nramp_c_per_min = 1.0\nmin_c = -40\nmax_c = 85\nsafe_state = \"ambient\"\n\
    ambient_c = 23\nproduct_input = 2\n\
    alarm_registers = [ { register = 1061, name = \"door open\" }, { register = 1063, name = \"over-temperature\" } ]\n\
    chamber_on_output = 1\n";

fn text() -> String {
    format!("{HEAD}{SERIES}{CHAMBER}")
}

fn parse(src: &str) -> Result<Plan, crate::plan::PlanError> {
    Plan::from_toml_str(src, Path::new("series.toml"))
}

/// The 1-based line of the first line of `src` that starts with `prefix`.
fn line_of(src: &str, prefix: &str) -> usize {
    src.lines().position(|l| l.starts_with(prefix)).unwrap() + 1
}

#[test]
fn the_shipped_config_parses_and_is_a_series_of_four_temperatures() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/series.toml");
    let plan = Plan::from_file(&path).unwrap();
    assert_eq!(plan.kind(), PlanKind::Series);
    let s = plan.series().unwrap();
    assert_eq!(s.temperatures_c, [25.0, -20.0, 60.0, 25.0]);
    assert!(s.revisits(3) && !s.revisits(1));
    let c = plan.chamber().unwrap();
    assert_eq!(c.model, ChamberModel::WatlowF4);
    assert_eq!(c.alarm_registers.len(), 2);
    assert_eq!(c.alarm_registers[0].name, "door open");
    assert_eq!(c.alarm_registers[0].active, 1);
    assert_eq!(c.alarm_registers[0].mask, 0xFFFF);
    // 5 rates at each of 4 temperatures
    assert_eq!(plan.step_count(), 20);
    assert_eq!(plan.schedule().len(), 20);
}

#[test]
fn every_default_is_filled_in_and_the_document_round_trips() {
    let src = format!(
        "{HEAD}[series]\ntemperatures_c = [25, -20]\n[chamber]\nmodel = \"espec\"\nport = \"/dev/ttyUSB2\"\n"
    );
    let plan = parse(&src).unwrap();
    let s = plan.series().unwrap();
    assert_eq!(s.measure, Measure::Sweep);
    assert_eq!(
        (s.band_c, s.stability_c_per_min, s.soak_min, s.max_wait_min, s.poll_s),
        (0.5, 0.05, 30.0, 240.0, 10.0)
    );
    assert_eq!(s.bias_readings, 500);
    let c = plan.chamber().unwrap();
    assert_eq!(c.model, ChamberModel::Espec);
    assert_eq!((c.baud, c.slave, c.product_input), (9600, 1, 2));
    assert_eq!(c.safe_state, SafeStateChoice::Ambient);
    assert_eq!((c.min_c, c.max_c, c.ambient_c, c.ramp_c_per_min), (-40.0, 85.0, 23.0, 1.0));
    // the manifest's form reads back to the same plan
    let back = Plan::from_doc(plan.to_doc(), Path::new("manifest")).unwrap();
    assert_eq!(back, plan);
    assert_eq!(back.hash(), plan.hash());
}

#[test]
fn the_chambers_port_is_not_part_of_the_hash_but_a_temperature_is() {
    let a = parse(&text()).unwrap();
    let b = parse(&text().replace("/dev/ttyUSB2", "tcp://10.0.0.5:502")).unwrap();
    assert_eq!(a.hash(), b.hash());
    let c = parse(&text().replace("[25, -20, 60, 25]", "[25, -25, 60, 25]")).unwrap();
    assert_ne!(a.hash(), c.hash());
}

/// Every key of [series] and [chamber] with a bad value is refused naming the file, the
/// line of the value, the section and the key.
#[test]
fn every_new_keys_error_names_file_line_section_and_key() {
    let cases: &[(&str, &str, &str, &str)] = &[
        // (line prefix to replace, replacement, "[section] key" expected, words expected)
        ("temperatures_c", "temperatures_c = []", "[series] temperatures_c", "is empty"),
        ("measure", "measure = \"all\"", "[series] measure", "\"sweep\""),
        ("band_c", "band_c = 0", "[series] band_c", "must be > 0"),
        ("stability_c_per_min", "stability_c_per_min = -1", "[series] stability_c_per_min", "must be > 0"),
        ("soak_min", "soak_min = -5", "[series] soak_min", "from 0"),
        ("max_wait_min", "max_wait_min = 20", "[series] max_wait_min", "longer than soak_min"),
        ("poll_s", "poll_s = 0", "[series] poll_s", "must be > 0"),
        ("bias_readings", "bias_readings = 0", "[series] bias_readings", "from 1 to 1000000"),
        ("model", "model = \"thermotron\"", "[chamber] model", "watlow_f4"),
        ("port", "port = \"prologix:/dev/ttyUSB7?addr=3\"", "[chamber] port", "GPIB"),
        ("baud", "baud = 1234", "[chamber] baud", "1234"),
        ("slave", "slave = 0", "[chamber] slave", "from 1 to 247"),
        ("ramp_c_per_min", "ramp_c_per_min = 0", "[chamber] ramp_c_per_min", "> 0"),
        ("min_c", "min_c = 90", "[chamber] max_c", "above min_c"),
        ("max_c", "max_c = 500", "[chamber] max_c", "from -100 to 250"),
        ("safe_state", "safe_state = \"cold\"", "[chamber] safe_state", "\"standby\""),
        ("ambient_c", "ambient_c = 100", "[chamber] ambient_c", "outside the chamber's limits"),
        ("product_input", "product_input = 4", "[chamber] product_input", "2 or 3"),
        ("chamber_on_output", "chamber_on_output = 9", "[chamber] chamber_on_output", "from 1 to 8"),
        (
            "alarm_registers",
            "alarm_registers = [ { register = 70000, name = \"door open\" } ]",
            "[chamber.alarm_registers[0]] register",
            "0 to 65535",
        ),
        (
            "alarm_registers",
            "alarm_registers = [ { register = 1061, name = \" \" } ]",
            "[chamber.alarm_registers[0]] name",
            "is empty",
        ),
        ("alarm_registers", "alarm_registers = 5", "[chamber] alarm_registers", "list of tables"),
    ];
    for &(prefix, replacement, key, words) in cases {
        let src = text();
        // the new sections' lines only ([table] and [dmm] have a `port` too)
        let first = line_of(&src, "[series]");
        let line_in = |prefix: &str| {
            src.lines()
                .enumerate()
                .position(|(i, l)| i + 1 > first && l.starts_with(prefix))
                .unwrap()
                + 1
        };
        let line = line_in(prefix);
        let bad: String = src
            .lines()
            .enumerate()
            .map(|(i, l)| if i + 1 == line { replacement } else { l })
            .collect::<Vec<_>>()
            .join("\n");
        let e = parse(&bad).expect_err(replacement).to_string();
        // min_c = 90 is reported at max_c's line (the pair is wrong where max_c stands)
        let line = if prefix == "min_c" { line_in("max_c") } else { line };
        assert!(
            e.starts_with(&format!("series.toml:{line}:")),
            "{replacement}: line {line}: {e}"
        );
        assert!(e.contains(key), "{replacement}: {key}: {e}");
        assert!(e.contains(words), "{replacement}: {words}: {e}");
    }
}

#[test]
fn an_unknown_key_of_the_new_sections_gets_a_did_you_mean() {
    let e = parse(&text().replace("band_c = 0.5", "bandc = 0.5"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("did you mean `band_c`"), "{e}");
    let e = parse(&text().replace("slave = 1", "slav = 1"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("did you mean `slave`"), "{e}");
}

#[test]
fn a_setpoint_outside_the_chambers_limits_is_refused_at_its_own_line() {
    let src = text().replace("[25, -20, 60, 25]", "[25, -20,\n  90, 25]");
    let e = parse(&src).unwrap_err().to_string();
    let line = line_of(&src, "  90");
    assert!(e.starts_with(&format!("series.toml:{line}:")), "{e}");
    assert!(
        e.contains("[series] temperatures_c[2] = 90 °C is outside the chamber's limits [-40, 85] °C"),
        "{e}"
    );
    // the limits are the plan's: narrower ones refuse -20 too
    let e = parse(&text().replace("min_c = -40", "min_c = -10"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("temperatures_c[1] = -20 °C is outside"), "{e}");
}

#[test]
fn the_sections_belong_together_and_to_a_series() {
    let e = parse(&format!("{HEAD}{SERIES}")).unwrap_err().to_string();
    assert!(e.contains("needs a [chamber] section"), "{e}");
    let e = parse(&format!("{HEAD}{CHAMBER}")).unwrap_err().to_string();
    assert!(e.contains("needs a [series] section"), "{e}");
    let sweep = text().replace("kind = \"temperature_series\"\n", "");
    let e = parse(&sweep).unwrap_err().to_string();
    assert!(e.contains("[series] belongs to a temperature series"), "{e}");
    // a series that sweeps needs a sweep's rates; one that only records the bias does not
    let one_rate = text().replace("rates_dps = [0, 5, -5]", "rates_dps = [0]");
    let e = parse(&one_rate).unwrap_err().to_string();
    assert!(e.contains("at least two distinct rates"), "{e}");
    parse(&one_rate.replace("measure = \"sweep\"", "measure = \"bias\"")).unwrap();
}

#[test]
fn the_schedule_is_the_sweep_at_each_temperature_then_its_bias_record() {
    let plan = parse(&text().replace("measure = \"sweep\"", "measure = \"both\"")).unwrap();
    let schedule = plan.schedule();
    // 3 rates + 1 bias record at each of 4 temperatures
    assert_eq!(schedule.len(), 16);
    assert_eq!(plan.step_count(), 16);
    for (i, s) in schedule.iter().enumerate() {
        assert_eq!(s.index, i);
        let at = s.series.unwrap();
        assert_eq!(at.point as usize, i / 4);
        assert_eq!(at.setpoint_c, [25.0, -20.0, 60.0, 25.0][i / 4]);
        assert_eq!(at.bias_record, i % 4 == 3);
        if at.bias_record {
            assert_eq!(s.rate_dps, 0.0);
            assert_eq!(s.acquire, Acquire::Samples(500));
        } else {
            assert_eq!(s.rate_dps, [0.0, 5.0, -5.0][i % 4]);
            assert_eq!(s.acquire, Acquire::Samples(20));
        }
    }
}

#[test]
fn each_temperature_is_soaked_before_its_steps_and_every_step_watches_the_chamber() {
    let plan = parse(&text()).unwrap();
    let schedule = plan.schedule();
    let c = crate::steps::compile(&plan, &schedule, false);
    assert!(c.uses_chamber && c.uses_table);
    assert_eq!(c.schedule_len, 12);
    assert_eq!(c.recording().copied().collect::<Vec<_>>(), schedule);
    // soak, 3 steps, soak, 3 steps, ...
    assert_eq!(c.steps.len(), 16);
    for (i, a) in c.steps.iter().enumerate() {
        let point = (i / 4) as u32;
        if i % 4 == 0 {
            assert_eq!(a.record, Record::Soak);
            let ChamberAction::Soak(s) = a.chamber else {
                panic!("{a:?}")
            };
            assert_eq!(s.point, point);
            assert_eq!(s.setpoint_c, [25.0, -20.0, 60.0, 25.0][i / 4]);
            assert_eq!(s.soak, Duration::from_secs(1800));
            assert_eq!(s.max_wait, Duration::from_secs(4 * 3600));
            assert_eq!(s.poll, Duration::from_secs(10));
            assert_eq!((s.band_c, s.ramp_c_per_min), (0.5, 1.0));
        } else {
            assert!(matches!(a.record, Record::Row(_)));
            assert!(
                matches!(a.chamber, ChamberAction::Watch(w) if w.point == point && w.band_c == 0.5),
                "{a:?}"
            );
        }
    }
}

#[test]
fn a_resumed_series_soaks_again_where_it_stopped() {
    let plan = parse(&text()).unwrap();
    let schedule = plan.schedule();
    // stopped after the first step at -20 °C (step 4 of 12 done)
    let remaining: Vec<_> = schedule[4..].to_vec();
    let c = crate::steps::compile(&plan, &remaining, false);
    let ChamberAction::Soak(first) = c.steps[0].chamber else {
        panic!("{:?}", c.steps[0])
    };
    assert_eq!((first.point, first.setpoint_c), (1, -20.0));
    // the two steps left at -20 °C, then a soak at 60 °C
    assert!(matches!(c.steps[1].record, Record::Row(s) if s.index == 4));
    assert!(matches!(c.steps[3].chamber, ChamberAction::Soak(s) if s.point == 2));
    assert_eq!(c.steps.len(), 2 + 3 + 3 + 2 + 1);
}

#[test]
fn check_says_the_series_and_how_long_its_ramps_and_soaks_take() {
    let plan = parse(&text()).unwrap();
    let k = plan.kind_summary().unwrap();
    assert_eq!(k.key, "series");
    assert!(k.line.contains("25 → -20 → 60 → 25 °C"), "{}", k.line);
    assert!(k.line.contains("hysteresis"), "{}", k.line);
    // ramps from ambient 23: 2 + 45 + 80 + 35 = 162 °C at 1 °C/min; soaks 4 × 30 min
    assert!(k.line.contains("ramps take 2.7 h"), "{}", k.line);
    assert!(k.line.contains("soaks at least 2.0 h"), "{}", k.line);
    assert_eq!(k.json["ramps_s"], 162.0 * 60.0);
    assert_eq!(k.json["revisited_points"], serde_json::json!([3]));
}
