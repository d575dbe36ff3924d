//! The temperature series' page: a series analysed from synthetic sweeps (a gyro whose K
//! falls 60 ppm/°C and whose bias rises with temperature, 25 → −20 → 60 → 25 °C with a
//! hysteresis step after the cold point), rendered on the certificate layout: the table of
//! temperatures, the sensitivities with U, the verdict, the four plots as valid SVG, the
//! chamber in the instruments, everything from a file escaped.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;

use gyrocal_analysis::series::{
    BiasRecord, Options, PointInput, SeriesInput, TempcoLimits, analyse_input,
};
use gyrocal_files::{Plan, RunDir, RunMeta};
use gyrocal_report::series_page::{ChamberLine, render_series};

struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

const RATES: [f64; 9] = [-100.0, -50.0, -20.0, -5.0, 0.0, 5.0, 20.0, 50.0, 100.0];

fn series() -> SeriesInput {
    let mut noise = Noise(0x9E37_79B9_7F4A_7C15);
    let setpoints = [25.0, -20.0, 60.0, 25.0];
    let points = setpoints
        .iter()
        .enumerate()
        .map(|(i, &sp)| {
            let t = sp + 0.3 * noise.gauss();
            let hyst = if i == 3 { 150e-6 } else { 0.0 };
            let k = 0.0125 * (1.0 - 60e-6 * (t - 25.0) + hyst);
            let k0 = 0.004 + 2e-6 * (t - 25.0);
            PointInput {
                series_point: i,
                setpoint_c: sp,
                temp_min_c: t - 0.15,
                temp_mean_c: t,
                temp_max_c: t + 0.12,
                sweep: Some(gyrocal_fit::Dataset {
                    source: None,
                    points: RATES
                        .iter()
                        .map(|&w| gyrocal_fit::Point {
                            rate_dps: w,
                            volts: k0 + k * w + 2e-5 * noise.gauss(),
                            volts_std: Some(2e-4),
                            n: Some(100),
                            line: None,
                        })
                        .collect(),
                }),
                bias: Some(BiasRecord {
                    mean_v: k0 + 2e-5 * noise.gauss(),
                    std_v: 2e-4,
                    n: 100,
                }),
            }
        })
        .collect();
    SeriesInput {
        points,
        uncertainty: Default::default(),
        limits: TempcoLimits {
            k_tempco_ppm_per_c_max: Some(100.0),
            bias_tempco_dph_per_c_max: Some(0.2),
        },
    }
}

fn page(dir: &Path) -> String {
    let toml = common::plans::sweep("series <page> test", &[-20.0, -5.0, 0.0, 5.0, 20.0], 100);
    let plan = Plan::from_toml_str(&toml, Path::new("test.toml")).unwrap();
    let meta = RunMeta {
        gyrocal_version: "0.1.0-test".into(),
        simulated: true,
        ..RunMeta::default()
    };
    let rd = RunDir::create(dir, &plan, meta).unwrap();
    let m = rd.manifest().clone();
    let opts = Options {
        fit: gyrocal_fit::Options {
            methods: vec![gyrocal_fit::Method::LeastSquares],
            ..Default::default()
        },
        reference_c: None,
    };
    let doc = analyse_input(&series(), &opts, "test").unwrap();
    // a history: ramps and soaks, the product lagging the air
    let mut history = Vec::new();
    let (mut air, mut product) = (25.0_f64, 25.0_f64);
    for (i, sp) in [25.0, -20.0, 60.0, 25.0].iter().enumerate() {
        for j in 0..300 {
            let t = (i * 300 + j) as f64 * 60.0;
            air += (sp - air) * 0.05;
            product += (air - product) * 0.02;
            history.push((t, Some(*sp), Some(air), Some(product)));
        }
    }
    let chamber = ChamberLine {
        model: "watlow_f4".into(),
        port: "/dev/ttyUSB2 <&>".into(),
        record: None,
    };
    render_series(&doc, &m, dir, &history, Some(&chamber)).unwrap()
}

#[test]
fn the_series_page_shows_every_temperature_the_sensitivities_and_the_verdict() {
    let tmp = tempfile::tempdir().unwrap();
    let html = page(&tmp.path().join("run"));
    if let Ok(out) = std::env::var("GYROCAL_SHOT_HTML") {
        std::fs::write(out, &html).unwrap();
    }
    // four rows of temperatures, each with its setpoint
    let table = html
        .split("id=\"series-table\"")
        .nth(1)
        .and_then(|t| t.split("</table>").next())
        .unwrap();
    assert_eq!(
        table.matches("<tr><td class=\"num\">").count(),
        4,
        "{table}"
    );
    for sp in ["25.0", "-20.0", "60.0"] {
        assert!(table.contains(&format!(">{sp}</td>")), "{sp}: {table}");
    }
    assert!(table.contains("V/(°/s)") && table.contains("°/h"));
    // the sensitivities with U and k
    let sens = html.split("id=\"sensitivity-table\"").nth(1).unwrap();
    assert!(sens.contains("ppm/°C") && sens.contains("°/h/°C") && sens.contains("±"));
    assert!(sens.contains("k = 4.30"), "Student's t for 2 dof");
    // K: −60 ppm/°C within 100 passes or is indeterminate; the bias's ≈0.6 °/h/°C fails 0.2
    assert!(html.contains("verdict-fail"), "the bias limit is exceeded");
    assert!(html.contains("<strong>FAIL</strong>"));
    // the plots: K(T), bias(T), residuals, the history, each valid SVG
    for id in ["plot-k", "plot-bias", "plot-residuals", "plot-history"] {
        let fig = html
            .split(&format!("<figure id=\"{id}\">"))
            .nth(1)
            .and_then(|f| f.split("<figcaption>").next())
            .unwrap_or_else(|| panic!("no {id}"));
        roxmltree::Document::parse(fig).unwrap_or_else(|e| panic!("{id}: {e}"));
    }
    // hysteresis: the 150 ppm step after the cold point
    assert!(html.contains("id=\"hysteresis-table\""));
    // the chamber, escaped; the plan's name escaped
    assert!(html.contains("/dev/ttyUSB2 &lt;&amp;&gt;"));
    assert!(html.contains("series &lt;page&gt; test"));
    assert!(html.contains("id=\"end-of-report\""));
    assert!(html.contains("SIMULATED"));
}
