//! steps.csv's temperature series columns: written, read back, checked against the schedule,
//! and absent from older files that still read.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests: a panic is a failed test

use super::*;

const PLAN: &str = "[plan]\nkind = \"temperature_series\"\nname = \"s\"\nrates_dps = [0, 5]\n\
    samples_per_rate = 3\nsettle_s = 0\n\
    [table]\ndialect = \"acl\"\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n\
    [dmm]\nport = \"/dev/ttyUSB0\"\nrange_v = 10\nnplc = 1\nautozero = false\nline_hz = 50\n\
    [series]\ntemperatures_c = [25, -20]\nmeasure = \"both\"\nbias_readings = 4\n\
    [chamber]\nmodel = \"watlow_f4\"\nport = \"/dev/ttyUSB2\"\n";

fn plan() -> Plan {
    Plan::from_toml_str(PLAN, Path::new("series.toml")).unwrap()
}

/// Writes `step`'s readings and its row, with the gyro's temperatures `temps`.
fn record(rd: &mut RunDir, step: usize, temps: Option<(f64, f64, f64)>) -> Result<(), RunError> {
    let s = rd.schedule()[step];
    let n = s.sample_count(std::time::Duration::from_millis(40));
    let samples: Vec<Sample> = (0..n)
        .map(|i| Sample {
            index: i,
            t_s: step as f64 * 10.0 + i as f64 * 0.04,
            volts: Some(0.01 + 0.36 * s.rate_dps),
        })
        .collect();
    rd.append_samples(step, &samples).unwrap();
    let at = s.series.unwrap();
    rd.append_step(StepRecord {
        step,
        pass: s.pass,
        rate_dps: s.rate_dps,
        rate_meas_dps: None,
        rate_meas_std_dps: None,
        rate_meas_min_dps: None,
        rate_meas_max_dps: None,
        rate_samples: None,
        volts: 0.01 + 0.36 * s.rate_dps,
        volts_std: None,
        n,
        overloads: 0,
        retries: 0,
        t_start_s: step as f64 * 10.0,
        t_end_s: step as f64 * 10.0 + 1.0,
        series: Some(SeriesCells {
            series_point: at.point,
            setpoint_c: at.setpoint_c,
            temp_min_c: temps.map(|t| t.0),
            temp_mean_c: temps.map(|t| t.1),
            temp_max_c: temps.map(|t| t.2),
            bias_record: at.bias_record,
        }),
    })
}

#[test]
fn a_series_rows_temperature_cells_are_written_and_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let mut rd = RunDir::create(&run, &plan(), RunMeta::default()).unwrap();
    record(&mut rd, 0, Some((24.9, 25.0, 25.1))).unwrap();
    record(&mut rd, 2, Some((24.95, 25.02, 25.08))).unwrap();
    record(&mut rd, 3, None).unwrap();
    drop(rd);
    let text = fs::read_to_string(run.join(STEPS_CSV)).unwrap();
    let mut lines = text.lines();
    assert!(lines.next().unwrap().ends_with(
        ",t_end_utc,series_point,setpoint_c,temp_min_c,temp_mean_c,temp_max_c,bias_record"
    ));
    assert!(
        lines.next().unwrap().ends_with(",0,25.0,24.9,25.0,25.1,0"),
        "{text}"
    );
    // the bias record at 25 °C is marked; point 1 is -20 °C
    assert!(
        lines
            .next()
            .unwrap()
            .ends_with(",0,25.0,24.95,25.02,25.08,1"),
        "{text}"
    );
    assert!(lines.next().unwrap().ends_with(",1,-20.0,,,,0"), "{text}");
    let data = load(&run).unwrap();
    let cells: Vec<SeriesCells> = data.steps.iter().map(|s| s.series.unwrap()).collect();
    assert_eq!(cells[0].temp_min_c, Some(24.9));
    assert_eq!(cells[1].temp_mean_c, Some(25.02));
    assert!(cells[1].bias_record && !cells[0].bias_record);
    assert_eq!((cells[2].series_point, cells[2].setpoint_c), (1, -20.0));
    assert_eq!(cells[2].temp_max_c, None);
}

#[test]
fn a_row_at_the_wrong_temperature_or_with_disordered_temperatures_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let mut rd = RunDir::create(&run, &plan(), RunMeta::default()).unwrap();
    let e = record(&mut rd, 0, Some((25.2, 25.0, 25.1)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("must be ordered"), "{e}");
    rd.restart_step(0).unwrap();
    let s = rd.schedule()[0];
    let samples = [Sample {
        index: 0,
        t_s: 0.0,
        volts: Some(0.1),
    }];
    rd.append_samples(0, &samples).unwrap();
    let e = rd
        .append_step(StepRecord {
            step: 0,
            pass: 0,
            rate_dps: s.rate_dps,
            rate_meas_dps: None,
            rate_meas_std_dps: None,
            rate_meas_min_dps: None,
            rate_meas_max_dps: None,
            rate_samples: None,
            volts: 0.1,
            volts_std: None,
            n: 1,
            overloads: 0,
            retries: 0,
            t_start_s: 0.0,
            t_end_s: 0.1,
            series: None,
        })
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no series cells") && e.contains("series_point 0"),
        "{e}"
    );
}

#[test]
fn a_steps_file_from_before_the_series_columns_still_reads() {
    let sweep = PLAN
        .split("[series]")
        .next()
        .unwrap()
        .replace("kind = \"temperature_series\"\n", "");
    let plan = Plan::from_toml_str(&sweep, Path::new("sweep.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let mut rd = RunDir::create(&run, &plan, RunMeta::default()).unwrap();
    rd.append_samples(
        0,
        &[Sample {
            index: 0,
            t_s: 0.0,
            volts: Some(0.01),
        }],
    )
    .unwrap();
    drop(rd);
    // steps.csv as the previous format wrote it
    let header = STEPS_HEADER_V4.join(",");
    fs::write(
        run.join(STEPS_CSV),
        format!("{header}\n1,1,0,,,,,,0.01,,1,0,0,0,0.04,,\n"),
    )
    .unwrap();
    let data = load(&run).unwrap();
    assert_eq!(data.steps.len(), 1);
    assert_eq!(data.steps[0].series, None);
    // a sweep's resume keeps it as it is: only a series run has the series' columns
    let rd = RunDir::open_for_resume(&run, &plan).unwrap();
    drop(rd);
    let text = fs::read_to_string(run.join(STEPS_CSV)).unwrap();
    assert_eq!(text, format!("{header}\n1,1,0,,,,,,0.01,,1,0,0,0,0.04,,\n"));
}

#[test]
fn only_a_series_run_writes_the_series_columns() {
    let sweep = PLAN
        .split("[series]")
        .next()
        .unwrap()
        .replace("kind = \"temperature_series\"\n", "");
    let dir = tempfile::tempdir().unwrap();
    for (name, text, header) in [
        ("sweep", sweep.as_str(), STEPS_HEADER_V4.join(",")),
        ("series", PLAN, STEPS_HEADER.join(",")),
    ] {
        let plan = Plan::from_toml_str(text, Path::new("plan.toml")).unwrap();
        let run = dir.path().join(name);
        drop(RunDir::create(&run, &plan, RunMeta::default()).unwrap());
        let written = fs::read_to_string(run.join(STEPS_CSV)).unwrap();
        assert_eq!(written.lines().next(), Some(header.as_str()), "{name}");
    }
}
