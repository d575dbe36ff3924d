//! Where the station file is found, and the simulated bench's station.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use jiff::civil::Date;

use super::{InstrumentRecord, STATION_ENV, SpecPeriod, Station, StationError};

impl Station {
    /// The default station file: `$XDG_CONFIG_HOME/gyrocal/station.toml` (when the variable
    /// is set to an absolute path), else `$HOME/.config/gyrocal/station.toml`; `None` without
    /// either.
    pub fn default_path() -> Option<PathBuf> {
        Station::default_path_from(|k| std::env::var_os(k))
    }

    /// [`Station::default_path`] with the environment given by `env`.
    pub fn default_path_from(env: impl Fn(&str) -> Option<OsString>) -> Option<PathBuf> {
        let dir = |k: &str| env(k).map(PathBuf::from).filter(|p| p.is_absolute());
        if let Some(config) = dir("XDG_CONFIG_HOME") {
            return Some(config.join("gyrocal").join("station.toml"));
        }
        dir("HOME").map(|home| home.join(".config").join("gyrocal").join("station.toml"))
    }

    /// The station of this run: the `--station` path when given, else the [`STATION_ENV`]
    /// variable's (when set and not empty), else the [`Station::default_path`] when that file
    /// exists. A path from the flag or the variable that does not exist is an error; no
    /// default file is `Ok(None)`.
    pub fn resolve(flag: Option<&Path>) -> Result<Option<(PathBuf, Station)>, StationError> {
        Station::resolve_with(flag, |k| std::env::var_os(k), Station::default_path())
    }

    /// [`Station::resolve`] with the environment given by `env` and the default path by
    /// `default` (tests set neither in the process).
    pub fn resolve_with(
        flag: Option<&Path>,
        env: impl Fn(&str) -> Option<OsString>,
        default: Option<PathBuf>,
    ) -> Result<Option<(PathBuf, Station)>, StationError> {
        let given = flag.map(|p| (p.to_path_buf(), "--station")).or_else(|| {
            env(STATION_ENV)
                .filter(|v| !v.is_empty())
                .map(|v| (PathBuf::from(v), STATION_ENV))
        });
        let path = match given {
            Some((path, origin)) => {
                if !path.exists() {
                    return Err(StationError::NotFound { path, origin });
                }
                path
            }
            None => match default {
                Some(path) if path.exists() => path,
                _ => return Ok(None),
            },
        };
        let station = Station::from_file(&path)?;
        Ok(Some((path, station)))
    }

    /// The simulated bench's station (`gyrocal run --simulate`, `gyrocal sim`): complete and
    /// plainly marked, serials `SIM-34401A-NNNN` and `SIM-ACL-NNNN` from `seed`, certificates
    /// `SIMULATED`, calibrated `today` and due ten years later, the 1-year meter specification
    /// and a 10 ppm table.
    pub fn simulated(seed: u64, today: Date) -> Station {
        let n = format!("{:04}", seed % 10_000);
        let due = today
            .checked_add(jiff::Span::new().years(10))
            .unwrap_or(Date::MAX);
        let record = |model: &str, tag: &str| InstrumentRecord {
            model: model.to_string(),
            asset_id: format!("SIM-{tag}-{n}"),
            serial: format!("SIM-{tag}-{n}"),
            certificate: "SIMULATED".into(),
            calibrated: today,
            due,
            accuracy: None,
            gain_pct: None,
            offset_pct: None,
            rate_accuracy_ppm: None,
        };
        Station {
            id: format!("SIM-BENCH-{n}"),
            lab: "gyrocal simulated bench".into(),
            address: "in-process simulation (no laboratory)".into(),
            ambient_c: None,
            humidity_pct: None,
            catalog: None,
            serve: None,
            multimeter: Some(InstrumentRecord {
                accuracy: Some(SpecPeriod::Year1),
                ..record("HP 34401A (simulated)", "34401A")
            }),
            table: Some(InstrumentRecord {
                rate_accuracy_ppm: Some(10.0),
                ..record("ACL rate table (simulated)", "ACL")
            }),
            chamber: None,
        }
    }

    /// [`Station::simulated`] with a simulated chamber's record beside the meter and the table
    /// (a simulated temperature series): model `CONTROLLER (simulated)`, so the check of the
    /// model against the controller's identity ([`Station::check_chamber`]) compares like a
    /// real bench's, serial and asset `SIM-CH-NNNN`, certificate `SIMULATED`.
    pub fn simulated_with_chamber(seed: u64, today: Date, controller: &str) -> Station {
        let mut s = Station::simulated(seed, today);
        if let Some(t) = s.table.clone() {
            let n = format!("{:04}", seed % 10_000);
            s.chamber = Some(InstrumentRecord {
                model: format!("{} (simulated)", controller.trim()),
                asset_id: format!("SIM-CH-{n}"),
                serial: format!("SIM-CH-{n}"),
                rate_accuracy_ppm: None,
                ..t
            });
        }
        s
    }
}
