//! The whole simulated bench from one configuration: the rate table, the gyro on it and the
//! multimeter reading the gyro, over in-memory pipes.
//!
//! [`BenchConfig`] deserialises from TOML (every section and field optional):
//!
//! ```toml
//! seed = 42
//! time_scale = 1.0
//! [table]
//! rate_noise_std = 0.0005
//! [gyro]
//! k1 = 0.3612
//! k1_neg = 0.3610
//! latitude_deg = 34.3
//! [dmm]
//! line_hz = 50
//! [chamber]            # optional: a thermal chamber around the gyro
//! model = "watlow_f4"  # or "espec"
//! [chamber.thermal]
//! case_tau_s = 1200
//! ```

use gyrocal_link::{StreamTransport, memory_pair};
use serde::{Deserialize, Serialize};
use tokio::io::{AsyncRead, AsyncWrite, DuplexStream};

use crate::chamber::{ChamberHandle, ChamberSimConfig};
use crate::dmm::{DmmConfig, DmmHandle, SimDmm};
use crate::gyro::{GyroConfig, GyroSignal, GyroTruth};
use crate::table::{SimTable, TableConfig, TableHandle};

/// Configuration of the simulated bench.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BenchConfig {
    /// Seed of every random source (table readback noise, gyro noise and walk, meter noise get
    /// independent streams derived from it). Default 1.
    pub seed: u64,
    /// Sim seconds per real second for the table, the gyro and the meter (it replaces their own
    /// `time_scale`). Default 1.0.
    pub time_scale: f64,
    /// The rate table.
    pub table: TableConfig,
    /// The table's wire protocol. Default ACL.
    pub table_wire: TableWire,
    /// The gyro.
    pub gyro: GyroConfig,
    /// The multimeter.
    pub dmm: DmmConfig,
    /// How the multimeter is reached. Default its RS-232 port. A Truevolt ([`DmmModel`]) is
    /// always reached on its LAN socket, whatever this says.
    pub dmm_link: DmmLink,
    /// Which multimeter. Default the HP 34401A (`dmm` configures it); a Truevolt takes its
    /// line frequency, noise and power-off time from `dmm` and the rest from `truevolt`.
    pub dmm_model: DmmModel,
    /// The Truevolt's own settings (its model is `dmm_model`'s).
    pub truevolt: crate::truevolt::TruevoltConfig,
    /// A thermal chamber around the gyro (its controller, physics and faults). Default none:
    /// the gyro is at the room's temperature (`gyro.room_c`).
    pub chamber: Option<ChamberSimConfig>,
}

/// Which simulated multimeter the bench has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum DmmModel {
    /// The HP 34401A.
    #[default]
    #[serde(rename = "34401a")]
    Hp34401a,
    /// A Keysight Truevolt.
    #[serde(untagged)]
    Truevolt(gyrocal_truevolt::Model),
}

impl DmmModel {
    /// The Truevolt model, if the meter is one.
    pub fn truevolt(self) -> Option<gyrocal_truevolt::Model> {
        match self {
            DmmModel::Hp34401a => None,
            DmmModel::Truevolt(m) => Some(m),
        }
    }

    /// The name used by `gyrocal sim --dmm` and plans (`34401a`, `34461a`, ...).
    pub fn key(self) -> &'static str {
        match self {
            DmmModel::Hp34401a => "34401a",
            DmmModel::Truevolt(m) => m.key(),
        }
    }
}

impl std::str::FromStr for DmmModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("34401a") {
            return Ok(DmmModel::Hp34401a);
        }
        s.parse::<gyrocal_truevolt::Model>()
            .map(DmmModel::Truevolt)
            .map_err(|_| format!("{s:?} is not a meter (34401a, 34460a, 34461a, 34465a, 34470a)"))
    }
}

/// How the simulated multimeter is reached.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DmmLink {
    /// The meter's own RS-232 port.
    #[default]
    Rs232,
    /// GPIB through a simulated Prologix controller (the meter in GPIB mode behind it).
    Prologix(crate::prologix::PrologixConfig),
    /// A LAN SCPI socket (a Truevolt's only link here).
    Lan,
}

impl Default for BenchConfig {
    fn default() -> Self {
        BenchConfig {
            seed: 1,
            time_scale: 1.0,
            table: TableConfig::default(),
            table_wire: TableWire::default(),
            gyro: GyroConfig::default(),
            // a simulated bench says it is one, in its meters' serial fields as the table's
            // (SIM0001): a run against it is recorded as simulated. (The meters' own
            // defaults keep what a real unit answers: the 34401A's serial field is 0.)
            dmm: DmmConfig {
                identity: SIMULATED_34401A_IDENTITY.into(),
                ..DmmConfig::default()
            },
            dmm_link: DmmLink::default(),
            dmm_model: DmmModel::default(),
            truevolt: crate::truevolt::TruevoltConfig {
                serial: "SIM0001".into(),
                ..crate::truevolt::TruevoltConfig::default()
            },
            chamber: None,
        }
    }
}

/// The simulated bench's 34401A identity: a real unit's, with `SIM0001` in the serial field
/// (a real one answers 0 there).
pub const SIMULATED_34401A_IDENTITY: &str = "HEWLETT-PACKARD,34401A,SIM0001,11-5-2";

/// The wire protocol the simulated table speaks (the motion, limits and faults are the same).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TableWire {
    /// gyrocal's serial ACL dialect (ACUTROL).
    #[default]
    Acl,
    /// The experimental Ideal Aerosmith ASCII dialect, with its wire options.
    Aerosmith(crate::table::aerosmith::AerosmithWire),
}

impl TableHandle {
    /// Serves `wire` on one more link (a client reconnecting, a TCP connection).
    pub fn serve_wire<S>(&self, stream: S, wire: TableWire) -> tokio::task::JoinHandle<()>
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        match wire {
            TableWire::Acl => self.serve_link(stream),
            TableWire::Aerosmith(w) => self.serve_aerosmith(stream, w),
        }
    }
}

/// The simulators' side of a running bench: truth, fault injection, shutdown.
pub struct BenchHandle {
    /// The table.
    pub table: TableHandle,
    /// The multimeter.
    pub dmm: DmmHandle,
    /// The gyro's true coefficients.
    pub truth: GyroTruth,
    /// A Truevolt's LAN port (more connections, reconnects); `None` for a 34401A.
    pub lan: Option<crate::truevolt::LanPort>,
    /// The chamber (its truth, faults, and more links: [`ChamberHandle::serve`],
    /// [`ChamberHandle::serve_tcp`]); `None` without one.
    pub chamber: Option<ChamberHandle>,
}

/// A running bench: the drivers' transports and the simulators' handle.
pub struct Bench {
    /// The multimeter's link (give it to the 34401A driver).
    pub dmm: StreamTransport<DuplexStream>,
    /// The table's link (give it to the table driver).
    pub table: StreamTransport<DuplexStream>,
    /// The chamber's link, until [`Bench::chamber_link`] takes it.
    chamber: Option<DuplexStream>,
    /// Truth and control of the simulators.
    pub handle: BenchHandle,
}

/// SplitMix64: derives independent seeds from one.
fn derive_seed(seed: u64, stream: u64) -> u64 {
    let mut z = seed.wrapping_add(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Bench {
    /// Spawns the table and the multimeter (reading the gyro on the table) as tokio tasks over
    /// in-memory pipes. Must be called inside a tokio runtime; fine in paused virtual time.
    pub fn spawn(config: BenchConfig) -> Bench {
        let (table_link, table_dev) = memory_pair("sim-table");
        let name = match config.dmm_model {
            DmmModel::Hp34401a => "sim-34401a".to_string(),
            DmmModel::Truevolt(m) => format!("sim-{}", m.key()),
        };
        let (dmm_link, dmm_dev) = memory_pair(name);
        let handle = Bench::spawn_on(config, dmm_dev, table_dev);
        let chamber = handle.chamber.as_ref().map(|c| {
            let (host, device) = tokio::io::duplex(4096);
            c.serve(device);
            host
        });
        Bench {
            dmm: dmm_link,
            table: table_link,
            handle,
            chamber,
        }
    }

    /// The in-memory byte stream of the simulated chamber's controller (taken once; `None`
    /// without a chamber or when taken already): Modbus RTU of a Watlow F4 for
    /// `gyrocal_chamber::WatlowF4::over_stream`, or the Espec's text lines (wrap it in
    /// [`Bench::chamber_transport`] for `gyrocal_chamber::Espec::over_transport`).
    pub fn chamber_link(&mut self) -> Option<DuplexStream> {
        self.chamber.take()
    }

    /// The chamber's link as a gyrocal-link line transport (for the Espec driver).
    pub fn chamber_transport(&mut self) -> Option<StreamTransport<DuplexStream>> {
        self.chamber_link()
            .map(|s| StreamTransport::new(s, "sim-chamber"))
    }

    /// Spawns the bench serving the device sides of the links it is given: `dmm` for the
    /// multimeter, `table` for the table (for example the master sides of two
    /// pseudo-terminals). More table links can be served later with
    /// [`TableHandle::serve_link`]. A chamber, when configured, is created (its clock starts
    /// with the table's) but serves no link until given one ([`ChamberHandle::serve`]). Must
    /// be called inside a tokio runtime.
    pub fn spawn_on<D, T>(config: BenchConfig, dmm: D, table: T) -> BenchHandle
    where
        D: AsyncRead + AsyncWrite + Send + Unpin + 'static,
        T: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let BenchConfig {
            seed,
            time_scale,
            table: mut table_config,
            table_wire,
            gyro,
            dmm: mut dmm_config,
            dmm_link,
            dmm_model,
            truevolt,
            chamber,
        } = config;
        let time_scale = if time_scale.is_finite() && time_scale > 0.0 {
            time_scale
        } else {
            1.0
        };
        table_config.time_scale = time_scale;
        dmm_config.time_scale = time_scale;
        let table_handle = match table_wire {
            TableWire::Acl => SimTable::spawn(table, table_config, derive_seed(seed, 1)),
            TableWire::Aerosmith(w) => {
                SimTable::spawn_aerosmith(table, table_config, w, derive_seed(seed, 1))
            }
        };
        let chamber = chamber.map(|c| ChamberHandle::new(c, time_scale, derive_seed(seed, 4)));
        let mut signal = GyroSignal::new(gyro, table_handle.clone(), derive_seed(seed, 2));
        if let Some(c) = &chamber {
            signal = signal.in_chamber(c.clone());
        }
        let truth = signal.truth();
        let mut lan = None;
        let dmm_handle = match (dmm_model, dmm_link) {
            (DmmModel::Truevolt(model), _) => {
                let config = crate::truevolt::TruevoltConfig {
                    model,
                    line_hz: dmm_config.line_hz,
                    noise_v: dmm_config.noise_v,
                    power_off_s: dmm_config.power_off_s,
                    time_scale,
                    ..truevolt
                };
                let (handle, port) = crate::truevolt::SimTruevolt::spawn(
                    config,
                    Some(Box::new(dmm)),
                    Box::new(signal),
                    derive_seed(seed, 3),
                );
                lan = Some(port);
                handle
            }
            (DmmModel::Hp34401a, DmmLink::Rs232 | DmmLink::Lan) => {
                SimDmm::spawn(dmm, dmm_config, Box::new(signal), derive_seed(seed, 3))
            }
            (DmmModel::Hp34401a, DmmLink::Prologix(ctl)) => {
                // the controller task lives as long as its host link; its handle is not needed
                let (_controller, meter) = crate::prologix::spawn_gpib_meter(
                    dmm,
                    ctl,
                    dmm_config,
                    Box::new(signal),
                    derive_seed(seed, 3),
                );
                meter
            }
        };
        BenchHandle {
            table: table_handle,
            dmm: dmm_handle,
            truth,
            lan,
            chamber,
        }
    }
}
