//! The Watlow F4 over Modbus RTU (serial) and Modbus TCP.
//!
//! Registers (holding registers, 16-bit **signed**, scaled by the input's decimal places; from
//! Espec North America's open `watlowf4.py`, see `docs/chamber.md`):
//!
//! | register | use here |
//! |---|---|
//! | 100 / 104 / 108 | input 1 (air) / input 2 / input 3 process value |
//! | 200 | mode: 0/1 static setpoint, 2 profile running, 3 profile paused |
//! | 300 | loop 1 static setpoint (written, then read back) |
//! | 602 / 603 | input 1 range low / high (narrow the setpoint limits) |
//! | 606 / 616 / 626 | decimal places of inputs 1 / 2 / 3 (0–3) |
//! | 901 | temperature unit: 1 = °C (anything else is refused) |
//! | 1217 | write 1: terminate a running profile |
//! | 2000 + 10·(N−1) | digital event output N (optional "chamber on", unconfirmed) |
//!
//! Transactions: [`Chamber::connect`] 4 reads (901, 602..=603, 606, and 616 or 626 when a
//! product input is configured); [`Chamber::read`] 3 reads (100..=108 in one block, or 100
//! alone without a product input; 200; 300) plus one per alarm register configured;
//! [`Chamber::set_setpoint`] 3 or 4 (read 200, write 1217 if a profile runs, write 300, read
//! 300 back; 300 is written again after a garbled or lost echo, 1217 never: see
//! [`ModbusLink::write_level`]). If the controller refuses the block 100..=108 (exception 2, illegal data
//! address: some firmware may not map the registers between), the driver reads 100 and the
//! product's register one at a time from then on.

mod config;

pub use config::{AlarmRegister, ProductInput, WATLOW_BAUDS, WatlowConfig};

use std::time::Duration;

use tokio_serial::{DataBits, FlowControl, Parity, SerialStream, StopBits};

use crate::modbus::{Framing, ModbusLink, ModbusStream, read_frame_sizes, transaction_time};
use crate::{
    Chamber, ChamberError, ChamberIdentity, ChamberMode, ChamberReading, ChamberTiming, SafeReport,
    SafeState,
};

/// Input 1's process value (the air).
pub const REG_INPUT1: u16 = 100;
/// Input 2's process value.
pub const REG_INPUT2: u16 = 104;
/// Input 3's process value.
pub const REG_INPUT3: u16 = 108;
/// The controller's mode.
pub const REG_MODE: u16 = 200;
/// Loop 1's static setpoint.
pub const REG_SETPOINT: u16 = 300;
/// Input 1's range low (high is the next register).
pub const REG_RANGE_LOW: u16 = 602;
/// Decimal places of input 1 (input 2: 616, input 3: 626).
pub const REG_DECIMALS1: u16 = 606;
/// The temperature unit: 1 = °C.
pub const REG_UNITS: u16 = 901;
/// Write 1 to terminate a running profile.
pub const REG_TERMINATE_PROFILE: u16 = 1217;
/// Digital event output 1 (output N is 2000 + 10·(N−1)).
pub const REG_EVENT_OUTPUT1: u16 = 2000;

/// How long a Modbus TCP connection may take to establish.
pub const TCP_CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// A 16-bit register as the F4 means it: signed, scaled by `decimals`.
pub fn from_register(word: u16, decimals: u8) -> f64 {
    f64::from(word as i16) / 10f64.powi(i32::from(decimals))
}

/// °C to a register value with `decimals` places; `None` if it does not fit 16 bits signed.
pub fn to_register(celsius: f64, decimals: u8) -> Option<u16> {
    let scaled = (celsius * 10f64.powi(i32::from(decimals))).round();
    if !scaled.is_finite() || scaled < f64::from(i16::MIN) || scaled > f64::from(i16::MAX) {
        return None;
    }
    // In range by the check above.
    Some((scaled as i16) as u16)
}

/// What connect learned from the controller.
#[derive(Debug, Clone, Copy)]
struct Setup {
    decimals1: u8,
    decimals_product: u8,
    min_c: f64,
    max_c: f64,
}

/// A Watlow F4 chamber controller.
#[derive(Debug)]
pub struct WatlowF4 {
    link: ModbusLink,
    description: String,
    config: WatlowConfig,
    framing: Framing,
    baud: u32,
    setup: Option<Setup>,
    block_read: bool,
}

impl WatlowF4 {
    fn new(
        stream: Box<dyn ModbusStream>,
        framing: Framing,
        baud: u32,
        description: String,
        config: WatlowConfig,
    ) -> Result<Self, ChamberError> {
        config.validate(&description)?;
        let link = ModbusLink::new(
            stream,
            framing,
            config.slave,
            description.clone(),
            config.reply_timeout,
            config.retries,
        );
        Ok(WatlowF4 {
            link,
            description,
            config,
            framing,
            baud,
            setup: None,
            block_read: true,
        })
    }

    /// Opens a serial port (or a pseudo-terminal) for Modbus RTU at `baud`, 8N1, no flow
    /// control. Baud rates: [`WATLOW_BAUDS`]. Must be called within a tokio runtime.
    pub fn open_rtu(path: &str, baud: u32, config: WatlowConfig) -> Result<Self, ChamberError> {
        let description = rtu_description(path, baud, config.slave);
        if !WATLOW_BAUDS.contains(&baud) {
            return Err(ChamberError::Setup {
                device: description,
                what: format!("baud {baud} is not one the Watlow F4 offers ({WATLOW_BAUDS:?})"),
            });
        }
        config.validate(&description)?;
        let builder = tokio_serial::new(path, baud)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None);
        let port = SerialStream::open(&builder).map_err(|e| ChamberError::Link {
            device: description.clone(),
            request: "opening the serial port".into(),
            detail: e.to_string(),
        })?;
        Self::new(Box::new(port), Framing::Rtu, baud, description, config)
    }

    /// Modbus RTU over any byte stream (an in-memory pipe, a pseudo-terminal's master side
    /// already open): `description` names it in messages; `baud` is for the timing model only.
    pub fn over_stream(
        stream: impl ModbusStream,
        description: &str,
        baud: u32,
        config: WatlowConfig,
    ) -> Result<Self, ChamberError> {
        let description = rtu_description(description, baud, config.slave);
        Self::new(Box::new(stream), Framing::Rtu, baud, description, config)
    }

    /// Modbus TCP over any byte stream (tests, a tunnel).
    pub fn over_tcp_stream(
        stream: impl ModbusStream,
        description: &str,
        config: WatlowConfig,
    ) -> Result<Self, ChamberError> {
        let description = tcp_description(description, config.slave);
        Self::new(Box::new(stream), Framing::Tcp, 0, description, config)
    }

    /// Connects to a Modbus TCP server (`host:port`, a gateway or the controller), within
    /// [`TCP_CONNECT_TIMEOUT`].
    pub async fn connect_tcp(addr: &str, config: WatlowConfig) -> Result<Self, ChamberError> {
        let addr = addr.strip_prefix("tcp://").unwrap_or(addr);
        let description = tcp_description(addr, config.slave);
        config.validate(&description)?;
        let stream =
            match tokio::time::timeout(TCP_CONNECT_TIMEOUT, tokio::net::TcpStream::connect(addr))
                .await
            {
                Ok(Ok(s)) => s,
                Ok(Err(e)) => {
                    return Err(ChamberError::Link {
                        device: description,
                        request: "connecting".into(),
                        detail: e.to_string(),
                    });
                }
                Err(_) => {
                    return Err(ChamberError::Timeout {
                        device: description,
                        request: "connecting".into(),
                        timeout_ms: u64::try_from(TCP_CONNECT_TIMEOUT.as_millis())
                            .unwrap_or(u64::MAX),
                    });
                }
            };
        if let Err(e) = stream.set_nodelay(true) {
            tracing::debug!(error = %e, "cannot set TCP_NODELAY; continuing");
        }
        Self::new(Box::new(stream), Framing::Tcp, 0, description, config)
    }

    /// The setpoint limits in force: the configuration's, narrowed by the controller's input 1
    /// range once connected.
    pub fn limits(&self) -> (f64, f64) {
        match self.setup {
            Some(s) => (s.min_c, s.max_c),
            None => (self.config.min_c, self.config.max_c),
        }
    }

    fn setup(&self, what: &str) -> Result<Setup, ChamberError> {
        self.setup.ok_or_else(|| ChamberError::State {
            device: self.description.clone(),
            what: format!("{what}: not connected yet (connect reads the units and decimals first)"),
        })
    }

    fn setup_error(&self, what: String) -> ChamberError {
        ChamberError::Setup {
            device: self.description.clone(),
            what,
        }
    }

    async fn read_one(&mut self, reg: u16) -> Result<u16, ChamberError> {
        let words = self.link.read(reg, 1).await?;
        // read() returns exactly the count asked for.
        Ok(words.first().copied().unwrap_or_default())
    }

    async fn read_decimals(&mut self, reg: u16, input: u8) -> Result<u8, ChamberError> {
        let raw = self.read_one(reg).await?;
        match u8::try_from(raw) {
            Ok(d) if d <= 3 => Ok(d),
            _ => Err(self.setup_error(format!(
                "register {reg} (input {input}'s decimal places) holds {raw}, not 0–3: the \
                 driver will not guess the scaling"
            ))),
        }
    }

    async fn read_mode(&mut self) -> Result<ChamberMode, ChamberError> {
        let raw = self.read_one(REG_MODE).await?;
        match raw {
            0 | 1 => Ok(ChamberMode::Constant),
            2 => Ok(ChamberMode::Profile),
            3 => Ok(ChamberMode::Paused),
            other => Err(ChamberError::Garbled {
                device: self.description.clone(),
                request: format!("read register {REG_MODE}"),
                detail: format!("mode {other} is not 0–3"),
            }),
        }
    }

    /// Air and product, in as few transactions as the controller allows.
    async fn read_temperatures(
        &mut self,
        setup: Setup,
    ) -> Result<(f64, Option<f64>), ChamberError> {
        let product_reg = match self.config.product_input {
            ProductInput::None => None,
            ProductInput::Input2 => Some(REG_INPUT2),
            ProductInput::Input3 => Some(REG_INPUT3),
        };
        let Some(product_reg) = product_reg else {
            let air = self.read_one(REG_INPUT1).await?;
            return Ok((from_register(air, setup.decimals1), None));
        };
        if self.block_read {
            let count = REG_INPUT3 - REG_INPUT1 + 1;
            match self.link.read(REG_INPUT1, count).await {
                Ok(words) => {
                    let at = |reg: u16| words.get(usize::from(reg - REG_INPUT1)).copied();
                    if let (Some(air), Some(product)) = (at(REG_INPUT1), at(product_reg)) {
                        return Ok((
                            from_register(air, setup.decimals1),
                            Some(from_register(product, setup.decimals_product)),
                        ));
                    }
                }
                Err(_) if self.link.last_exception() == Some(2) => {
                    tracing::info!(device = %self.description, "the controller refuses the block 100..=108; reading the inputs one at a time");
                    self.block_read = false;
                }
                Err(e) => return Err(e),
            }
        }
        let air = self.read_one(REG_INPUT1).await?;
        let product = self.read_one(product_reg).await?;
        Ok((
            from_register(air, setup.decimals1),
            Some(from_register(product, setup.decimals_product)),
        ))
    }

    async fn read_alarms(&mut self) -> Result<Vec<String>, ChamberError> {
        let mut active = Vec::new();
        for alarm in self.config.alarms.clone() {
            let value = self.read_one(alarm.register).await?;
            if value & alarm.mask == alarm.active {
                active.push(alarm.name);
            }
        }
        Ok(active)
    }

    /// Writes the setpoint and reads it back (the limits already checked).
    async fn write_setpoint(&mut self, setup: Setup, setpoint_c: f64) -> Result<f64, ChamberError> {
        let word = to_register(setpoint_c, setup.decimals1).ok_or_else(|| ChamberError::Limit {
            device: self.description.clone(),
            what: format!("setpoint {setpoint_c} °C does not fit the controller's register"),
        })?;
        if matches!(
            self.read_mode().await?,
            ChamberMode::Profile | ChamberMode::Paused
        ) {
            tracing::info!(device = %self.description, "terminating the controller's own profile");
            self.link.write(REG_TERMINATE_PROFILE, 1).await?;
        }
        // a level: written again after a garbled or lost echo (see ModbusLink::write_level)
        self.link.write_level(REG_SETPOINT, word).await?;
        let back = self.read_one(REG_SETPOINT).await?;
        if back != word {
            return Err(ChamberError::Instrument {
                device: self.description.clone(),
                request: format!("write register {REG_SETPOINT} = {setpoint_c} °C"),
                reason: format!(
                    "read back {} °C instead",
                    from_register(back, setup.decimals1)
                ),
            });
        }
        Ok(from_register(back, setup.decimals1))
    }

    fn check_limits(&self, setpoint_c: f64) -> Result<(), ChamberError> {
        let (lo, hi) = self.limits();
        if !setpoint_c.is_finite() || setpoint_c < lo || setpoint_c > hi {
            return Err(ChamberError::Limit {
                device: self.description.clone(),
                what: format!("setpoint {setpoint_c} °C is outside the limits {lo} .. {hi} °C"),
            });
        }
        Ok(())
    }

    async fn safe_ambient(&mut self, setpoint_c: f64) -> Result<String, String> {
        if self.setup.is_none() {
            self.connect().await.map_err(|e| e.to_string())?;
        }
        self.set_setpoint(setpoint_c)
            .await
            .map_err(|e| e.to_string())?;
        let mode = self.read_mode().await.map_err(|e| e.to_string())?;
        if mode != ChamberMode::Constant {
            return Err(format!(
                "setpoint {setpoint_c} °C written and read back, but the mode reads {mode}"
            ));
        }
        Ok(format!(
            "setpoint {setpoint_c} °C read back from register {REG_SETPOINT}, mode constant"
        ))
    }

    async fn safe_output_off(&mut self, state: SafeState) -> Result<String, String> {
        let Some(n) = self.config.chamber_on_output else {
            return Err(format!(
                "the Watlow F4 has no {state} register, and no `chamber_on_output` (the event \
                 output wired to switch the chamber on) is configured: the chamber was left as \
                 it was; switch it to {state} at its panel"
            ));
        };
        let reg = REG_EVENT_OUTPUT1 + 10 * (u16::from(n) - 1);
        self.link.write(reg, 0).await.map_err(|e| e.to_string())?;
        let back = self.read_one(reg).await.map_err(|e| e.to_string())?;
        if back != 0 {
            return Err(format!(
                "event output {n} (register {reg}) written off but reads {back}"
            ));
        }
        Ok(format!(
            "event output {n} (register {reg}, configured as \"chamber on\") read back off"
        ))
    }
}

fn rtu_description(path: &str, baud: u32, slave: u8) -> String {
    format!("{path} (Watlow F4, Modbus RTU {baud} 8N1, slave {slave})")
}

fn tcp_description(addr: &str, slave: u8) -> String {
    format!("{addr} (Watlow F4, Modbus TCP, unit {slave})")
}

impl Chamber for WatlowF4 {
    fn describe(&self) -> &str {
        &self.description
    }

    async fn connect(&mut self) -> Result<ChamberIdentity, ChamberError> {
        let units = self.read_one(REG_UNITS).await?;
        if units != 1 {
            let shown = if units == 0 {
                "°F".to_string()
            } else {
                format!("unit {units}")
            };
            return Err(self.setup_error(format!(
                "the controller is set to {shown} (register {REG_UNITS}); set it to °C at the \
                 controller (System menu, °C/°F) before a run: the driver will not convert"
            )));
        }
        let decimals1 = self.read_decimals(REG_DECIMALS1, 1).await?;
        let range = self.link.read(REG_RANGE_LOW, 2).await?;
        let (lo_raw, hi_raw) = match range.as_slice() {
            [lo, hi] => (*lo, *hi),
            _ => (0, 0),
        };
        let (range_lo, range_hi) = (
            from_register(lo_raw, decimals1),
            from_register(hi_raw, decimals1),
        );
        let decimals_product = match self.config.product_input {
            ProductInput::None => decimals1,
            ProductInput::Input2 => self.read_decimals(616, 2).await?,
            ProductInput::Input3 => self.read_decimals(626, 3).await?,
        };
        let min_c = self.config.min_c.max(range_lo);
        let max_c = self.config.max_c.min(range_hi);
        if min_c >= max_c {
            return Err(self.setup_error(format!(
                "no setpoint is allowed: the limits {} .. {} °C and the controller's input 1 \
                 range {range_lo} .. {range_hi} °C do not overlap",
                self.config.min_c, self.config.max_c
            )));
        }
        self.setup = Some(Setup {
            decimals1,
            decimals_product,
            min_c,
            max_c,
        });
        let product = match self.config.product_input {
            ProductInput::None => "no product input".to_string(),
            p => format!(
                "product on input {} ({decimals_product} decimals)",
                p.number()
            ),
        };
        Ok(ChamberIdentity {
            model: "Watlow F4".into(),
            detail: format!(
                "°C; input 1 (air) {decimals1} decimals, range {range_lo} .. {range_hi} °C; \
                 {product}; setpoint limits {min_c} .. {max_c} °C"
            ),
        })
    }

    async fn set_setpoint(&mut self, setpoint_c: f64) -> Result<(), ChamberError> {
        let setup = self.setup("set the setpoint")?;
        self.check_limits(setpoint_c)?;
        self.write_setpoint(setup, setpoint_c).await.map(|_| ())
    }

    async fn read(&mut self) -> Result<ChamberReading, ChamberError> {
        let setup = self.setup("read")?;
        let (air_c, product_c) = self.read_temperatures(setup).await?;
        let mode = self.read_mode().await?;
        let setpoint_c = from_register(self.read_one(REG_SETPOINT).await?, setup.decimals1);
        let alarms = self.read_alarms().await?;
        Ok(ChamberReading {
            air_c,
            product_c,
            setpoint_c,
            mode,
            alarms,
        })
    }

    async fn reset_alarms(&mut self) -> Result<(), ChamberError> {
        Err(ChamberError::Unsupported {
            device: self.description.clone(),
            what: "resetting alarms (no confirmed register: reset them at the chamber's panel)"
                .into(),
        })
    }

    async fn go_safe(&mut self, state: SafeState) -> SafeReport {
        let outcome = match state {
            SafeState::Ambient { setpoint_c } => self.safe_ambient(setpoint_c).await,
            SafeState::Standby | SafeState::Off => self.safe_output_off(state).await,
        };
        let (confirmed, detail) = match outcome {
            Ok(detail) => (true, detail),
            Err(detail) => (false, detail),
        };
        SafeReport {
            state,
            confirmed,
            detail,
        }
    }

    fn timing(&self) -> ChamberTiming {
        let latency = self.config.reply_latency;
        let read = |count| {
            transaction_time(
                self.framing,
                self.baud,
                read_frame_sizes(self.framing, count),
                latency,
            )
        };
        let temperatures = match self.config.product_input {
            ProductInput::None => read(1),
            _ => read(REG_INPUT3 - REG_INPUT1 + 1),
        };
        let alarms = u32::try_from(self.config.alarms.len()).unwrap_or(u32::MAX);
        ChamberTiming {
            read: temperatures + read(1) * 2 + read(1) * alarms,
            reply_timeout: self.config.reply_timeout,
        }
    }

    fn take_retries(&mut self) -> Vec<String> {
        self.link.take_retries()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ChamberErrorKind;

    #[test]
    fn signed_scaling_both_ways() {
        assert_eq!(to_register(-20.5, 1), Some(0xFF33));
        assert_eq!(from_register(0xFF33, 1), -20.5);
        assert_eq!(to_register(25.0, 1), Some(250));
        assert_eq!(from_register(250, 0), 250.0);
        assert_eq!(from_register(0x8000, 2), -327.68);
        assert_eq!(to_register(400.0, 2), None);
        assert_eq!(to_register(f64::NAN, 1), None);
    }

    #[test]
    fn bad_settings_are_named() {
        let c = WatlowConfig {
            slave: 0,
            ..WatlowConfig::default()
        };
        let e = c.validate("x").unwrap_err();
        assert_eq!(e.kind(), ChamberErrorKind::Setup);
        assert!(e.to_string().contains("slave address 0"), "{e}");
        let c = WatlowConfig {
            chamber_on_output: Some(9),
            ..WatlowConfig::default()
        };
        assert!(
            c.validate("x")
                .unwrap_err()
                .to_string()
                .contains("chamber_on_output 9")
        );
    }
}
