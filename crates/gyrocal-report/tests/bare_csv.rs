//! A bare steps CSV is read in one pass of gyrocal's chunked reader: the points and the
//! optional measured-rate columns line up row by row, whatever the file's line ends, byte-order
//! mark, comments and empty rows; an informative cell that is not a number is left out, a bad
//! required cell names its line.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use gyrocal_report::load_input;

#[test]
fn the_measured_rates_line_up_with_the_points() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("steps.csv");
    let rows = [
        "\u{feff}# a bench's export",
        "rate_dps,volts,volts_std,rate_meas_dps,rate_meas_std_dps",
        "-10,-3.6032,1e-4,-10.0004,2e-4",
        ",,,,",
        "-5,-1.7972,1e-4,x,2e-4",
        "# mid",
        "0,0.0088,1e-4,0.0001,",
        "5,1.8148,1e-4,5.0003,1e-4",
        "10,3.6208,1e-4,\"10.0002\",inf",
    ];
    std::fs::write(&path, rows.join("\r\n")).unwrap();
    let input = load_input(&path).unwrap();
    assert_eq!(input.data.points.len(), 5);
    let lines: Vec<_> = input.data.points.iter().map(|p| p.line).collect();
    assert_eq!(lines, [Some(3), Some(5), Some(7), Some(8), Some(9)]);
    let meas: Vec<_> = input
        .steps
        .iter()
        .map(|s| (s.rate_dps, s.rate_meas_dps, s.rate_meas_std_dps))
        .collect();
    assert_eq!(
        meas,
        [
            (-10.0, Some(-10.0004), Some(2e-4)),
            (-5.0, None, Some(2e-4)),
            (0.0, Some(0.0001), None),
            (5.0, Some(5.0003), Some(1e-4)),
            (10.0, Some(10.0002), None),
        ]
    );
}

#[test]
fn without_a_measured_rate_column_no_step_has_one() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("steps.csv");
    // a standard deviation alone is not shown: it goes with a measured rate
    std::fs::write(
        &path,
        "rate_dps,volts,rate_meas_std_dps\n-1,-0.35,1e-4\n0,0.0088,1e-4\n1,0.37,1e-4\n2,0.73,1e-4\n",
    )
    .unwrap();
    let input = load_input(&path).unwrap();
    assert_eq!(input.steps.len(), 4);
    assert!(
        input
            .steps
            .iter()
            .all(|s| s.rate_meas_dps.is_none() && s.rate_meas_std_dps.is_none())
    );
    std::fs::write(&path, "rate_dps,volts\n-1,-0.35\n0,0.0088\n1,x\n").unwrap();
    let e = load_input(&path).unwrap_err();
    assert!(
        e.to_string().contains(&format!(
            "{}: line 4: column `volts`: not a number: `x`",
            path.display()
        )),
        "{e}"
    );
}
