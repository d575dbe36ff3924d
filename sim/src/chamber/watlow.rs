//! The simulated Watlow F4 as a Modbus slave, written by hand from the Modbus specification
//! (Modbus Application Protocol v1.1b3 and Modbus over Serial Line v1.02), independent of
//! the driver's `tokio-modbus`.
//!
//! Function codes: 0x03 read holding registers (1–125), 0x06 write single register, 0x10
//! write multiple registers (1–123); any other is exception 01. Exceptions: 02 for a register
//! the F4 does not map here (or a read-only one written), 03 for a bad count or value (a
//! setpoint outside the range 602/603, a value a register does not take).
//!
//! RTU (serial): a frame is the slave address, the PDU and the CRC-16/Modbus (low byte
//! first). A frame with a bad CRC or for another slave is ignored in silence, as a real slave
//! does; address 0 (broadcast) is executed for writes and never answered. Frames are
//! delimited by their length for the function codes above; a frame of another function code
//! ends at a pause ([`FRAME_GAP`]), and an incomplete frame is dropped there. TCP: the MBAP header (transaction id
//! echoed, protocol 0, length, unit id) and the PDU; a unit id other than the slave's, 0 or
//! 255 is ignored.
//!
//! Registers (16-bit signed, scaled by `decimals`):
//!
//! | register | reads | writes |
//! |---|---|---|
//! | 100 | input 1: the air (sensor noise on each read) | 02 |
//! | 101–103, 105–107 | 0 (loop powers, unused) | 02 |
//! | 104, 108 | inputs 2 and 3: the product (the gyro's case thermocouple, noise on each read) | 02 |
//! | 200 | mode: 1 static setpoint, 2 profile running | 02 |
//! | 300 | the setpoint | a new setpoint (03 outside 602..603) |
//! | 602 / 603 | input 1's range low / high | 02 |
//! | 606 / 616 / 626 | decimal places of inputs 1 / 2 / 3 | 02 |
//! | 608 | 0 (loop 1 is a temperature) | 02 |
//! | 901 | units: 1 °C (or the configured value) | 02 |
//! | 1061 / 1063 | alarms door / over-temperature: 1 latched, 0 clear | 0 resets the alarm (else 03) |
//! | 1217 | 0 | 1 terminates a running profile (else 03) |
//! | 2000 + 10·(N−1), N 1–8 | event output N: 0 or 1 | 0 or 1 (else 03); the `chamber_on_output` stops or starts control |
//!
//! The driver reads the alarms with `alarm_registers = [{ register = 1061, active = 1, name =
//! "door open" }, { register = 1063, active = 1, name = "over-temperature" }]` (its
//! `AlarmRegister`: active when `value & mask == active`, mask all bits by default).

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use super::{ChamberAlarm, ChamberHandle, SimMode, State};

/// CRC-16/Modbus (polynomial 0xA001 reflected, initial 0xFFFF), sent low byte first.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// `frame` with its CRC appended (low byte first).
pub fn with_crc(mut frame: Vec<u8>) -> Vec<u8> {
    let crc = crc16(&frame);
    frame.extend_from_slice(&crc.to_le_bytes());
    frame
}

const EX_FUNCTION: u8 = 1;
const EX_ADDRESS: u8 = 2;
const EX_VALUE: u8 = 3;
/// Server device failure: what an `exception` fault answers.
const EX_DEVICE: u8 = 4;

fn exception(function: u8, code: u8) -> Vec<u8> {
    vec![function | 0x80, code]
}

fn be16(bytes: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*bytes.get(at)?, *bytes.get(at + 1)?]))
}

fn to_register(c: f64, decimals: u8) -> u16 {
    let scaled = (c * 10f64.powi(i32::from(decimals))).round();
    (scaled.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16) as u16
}

fn from_register(w: u16, decimals: u8) -> f64 {
    f64::from(w as i16) / 10f64.powi(i32::from(decimals))
}

fn output_index(register: u16) -> Option<usize> {
    let off = register.checked_sub(2000)?;
    (off % 10 == 0 && off / 10 < 8).then_some(usize::from(off / 10))
}

/// One register's value, or the exception code.
fn read_register(s: &mut State, register: u16) -> Result<u16, u8> {
    let d = s.config.decimals;
    Ok(match register {
        100 => to_register(s.sensed_air(), d),
        101..=103 | 105..=107 => 0,
        104 | 108 => to_register(s.sensed_product(), d),
        200 => match s.mode {
            SimMode::Profile => 2,
            _ => 1,
        },
        300 => to_register(s.setpoint_c, d),
        602 => to_register(s.config.range_c.0, d),
        603 => to_register(s.config.range_c.1, d),
        606 | 616 | 626 => u16::from(d),
        608 => 0,
        901 => s.config.units,
        super::REG_ALARM_DOOR => u16::from(s.alarm(ChamberAlarm::Door)),
        super::REG_ALARM_OVERTEMP => u16::from(s.alarm(ChamberAlarm::OverTemperature)),
        1217 => 0,
        r => match output_index(r) {
            Some(i) => s.outputs[i],
            None => return Err(EX_ADDRESS),
        },
    })
}

/// Writes one register, or the exception code.
fn write_register(s: &mut State, register: u16, value: u16) -> Result<(), u8> {
    match register {
        300 => {
            let c = from_register(value, s.config.decimals);
            let (lo, hi) = s.config.range_c;
            if !(lo..=hi).contains(&c) {
                return Err(EX_VALUE);
            }
            s.setpoint_c = c;
        }
        super::REG_ALARM_DOOR | super::REG_ALARM_OVERTEMP => {
            if value != 0 {
                return Err(EX_VALUE);
            }
            let a = if register == super::REG_ALARM_DOOR {
                ChamberAlarm::Door
            } else {
                ChamberAlarm::OverTemperature
            };
            s.set_alarm(a, false);
        }
        1217 => {
            if value != 1 {
                return Err(EX_VALUE);
            }
            if s.mode == SimMode::Profile {
                s.mode = SimMode::Constant;
            }
        }
        r => match output_index(r) {
            Some(i) if value <= 1 => s.outputs[i] = value,
            Some(_) => return Err(EX_VALUE),
            None => return Err(EX_ADDRESS),
        },
    }
    s.retarget();
    Ok(())
}

/// The `n` registers from `first` (the caller has checked they end at or below 0xFFFF; any
/// beyond are left out rather than wrapped).
fn registers(first: u16, n: u16) -> impl Iterator<Item = u16> {
    (u32::from(first)..u32::from(first) + u32::from(n)).filter_map(|r| u16::try_from(r).ok())
}

/// Executes one request PDU; the reply PDU (an exception's included).
fn execute(s: &mut State, pdu: &[u8]) -> Vec<u8> {
    let Some(&function) = pdu.first() else {
        return exception(0, EX_FUNCTION);
    };
    if !matches!(function, 0x03 | 0x06 | 0x10) {
        return exception(function, EX_FUNCTION);
    }
    let (Some(first), Some(n)) = (be16(pdu, 1), be16(pdu, 3)) else {
        return exception(function, EX_VALUE);
    };
    let count = if function == 0x06 { 1 } else { n };
    if let Some(code) = s.wire.register_exception(first, count) {
        return exception(function, code);
    }
    match function {
        0x03 => {
            if !(1..=125).contains(&n) {
                return exception(function, EX_VALUE);
            }
            if u32::from(first) + u32::from(n) > 0x1_0000 {
                return exception(function, EX_ADDRESS);
            }
            let mut reply = vec![0x03, (n * 2) as u8];
            for r in registers(first, n) {
                match read_register(s, r) {
                    Ok(v) => reply.extend_from_slice(&v.to_be_bytes()),
                    Err(code) => return exception(function, code),
                }
            }
            reply
        }
        0x06 => match write_register(s, first, n) {
            Ok(()) => pdu[..5].to_vec(),
            Err(code) => exception(function, code),
        },
        _ => {
            // 0x10: address, count, byte count, values
            let bytes = pdu.get(5).copied().map(usize::from);
            if !(1..=123).contains(&n) || bytes != Some(usize::from(n) * 2) {
                return exception(function, EX_VALUE);
            }
            if u32::from(first) + u32::from(n) > 0x1_0000 {
                return exception(function, EX_ADDRESS);
            }
            for (i, r) in registers(first, n).enumerate() {
                let Some(v) = be16(pdu, 6 + 2 * i) else {
                    return exception(function, EX_VALUE);
                };
                if let Err(code) = write_register(s, r, v) {
                    return exception(function, code);
                }
            }
            pdu[..5].to_vec()
        }
    }
}

/// What to send for one request, and after how long (sim s); `None`: nothing.
fn respond(chamber: &ChamberHandle, pdu: &[u8]) -> Option<(Vec<u8>, bool, f64)> {
    let mut s = chamber.lock();
    let fate = s.begin_request();
    if fate.silent {
        return None;
    }
    let function = pdu.first().copied().unwrap_or(0);
    let reply = if fate.refused {
        exception(function, EX_DEVICE)
    } else {
        execute(&mut s, pdu)
    };
    Some((reply, fate.corrupt, fate.delay_s))
}

/// The length of the RTU request at the start of `buf` when its function code fixes it
/// (`Some(None)`: not yet known, more bytes needed; `None`: the code does not fix it).
fn rtu_length(buf: &[u8]) -> Option<Option<usize>> {
    match buf.get(1) {
        None => Some(None),
        Some(0x03 | 0x06) => Some(Some(8)),
        Some(0x10) => Some(buf.get(6).map(|&n| 9 + usize::from(n))),
        Some(_) => None,
    }
}

/// How long a pause ends a frame: a frame of a function code whose length is unknown ends
/// there, and an incomplete one is thrown away. Longer than RTU's 3.5 characters (3.6 ms at
/// 9600 baud) on purpose: a pseudo-terminal on a busy machine may deliver a frame in pieces
/// milliseconds apart, and a driver waits far longer than this for its reply anyway.
pub const FRAME_GAP: std::time::Duration = std::time::Duration::from_millis(50);

/// Answers one RTU frame (or stays silent); `false` when the stream is gone.
async fn answer_rtu<S>(chamber: &ChamberHandle, stream: &mut S, frame: &[u8]) -> bool
where
    S: AsyncWrite + Unpin,
{
    let Some((body, crc)) = frame.split_at_checked(frame.len().saturating_sub(2)) else {
        return true;
    };
    if frame.len() < 4 || crc16(body).to_le_bytes() != crc {
        // a corrupted frame: silence, as a real slave
        return true;
    }
    let slave = chamber.lock().config.slave;
    let address = body[0];
    if address != slave && address != 0 {
        return true;
    }
    let Some((pdu, corrupt, delay)) = respond(chamber, &body[1..]) else {
        return true;
    };
    if address == 0 {
        // a broadcast is executed, never answered
        return true;
    }
    let mut reply = vec![slave];
    reply.extend_from_slice(&pdu);
    let mut reply = with_crc(reply);
    if corrupt && let Some(last) = reply.last_mut() {
        *last = !*last;
    }
    tokio::time::sleep(chamber.real(delay)).await;
    stream.write_all(&reply).await.is_ok() && stream.flush().await.is_ok()
}

/// Serves Modbus RTU on `stream` until it closes.
pub async fn serve_rtu<S>(chamber: ChamberHandle, mut stream: S)
where
    S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
{
    let mut buf: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 512];
    loop {
        if let Some(Some(len)) = rtu_length(&buf)
            && buf.len() >= len
        {
            let frame: Vec<u8> = buf.drain(..len).collect();
            if !answer_rtu(&chamber, &mut stream, &frame).await {
                return;
            }
            continue;
        }
        let read = if buf.is_empty() {
            Ok(stream.read(&mut chunk).await)
        } else {
            tokio::time::timeout(FRAME_GAP, stream.read(&mut chunk)).await
        };
        match read {
            Err(_) => {
                // a pause: a frame of unknown length ends here; an incomplete one is dropped
                let frame = std::mem::take(&mut buf);
                if rtu_length(&frame).is_none() && !answer_rtu(&chamber, &mut stream, &frame).await
                {
                    return;
                }
            }
            Ok(Ok(0) | Err(_)) => return,
            Ok(Ok(n)) => buf.extend_from_slice(&chunk[..n]),
        }
    }
}

/// Serves Modbus TCP on `stream` until it closes.
pub async fn serve_tcp<S>(chamber: ChamberHandle, mut stream: S)
where
    S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
{
    loop {
        let mut header = [0u8; 7];
        if stream.read_exact(&mut header).await.is_err() {
            return;
        }
        let length = usize::from(u16::from_be_bytes([header[4], header[5]]));
        if !(2..=254).contains(&length) || header[2..4] != [0, 0] {
            // not Modbus: a real server drops the connection
            return;
        }
        let mut pdu = vec![0u8; length - 1];
        if stream.read_exact(&mut pdu).await.is_err() {
            return;
        }
        let unit = header[6];
        let slave = chamber.lock().config.slave;
        if unit != slave && unit != 0 && unit != 255 {
            continue;
        }
        let Some((reply_pdu, corrupt, delay)) = respond(&chamber, &pdu) else {
            continue;
        };
        let len = u16::try_from(reply_pdu.len() + 1).unwrap_or(u16::MAX);
        let mut reply = vec![header[0], header[1], 0, u8::from(corrupt)];
        reply.extend_from_slice(&len.to_be_bytes());
        reply.push(unit);
        reply.extend_from_slice(&reply_pdu);
        tokio::time::sleep(chamber.real(delay)).await;
        if stream.write_all(&reply).await.is_err() || stream.flush().await.is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chamber::ChamberSimConfig;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    /// Any PDU a master (or line noise with a valid CRC) may send gets a reply or an
    /// exception, never a panic: the last register, counts at and past the limits, short
    /// PDUs, random bytes.
    #[tokio::test(start_paused = true)]
    async fn hostile_pdus_never_panic() {
        let h = ChamberHandle::new(ChamberSimConfig::default(), 1.0, 1);
        let mut s = h.lock();
        assert_eq!(
            execute(&mut s, &[0x03, 0xFF, 0xFF, 0x00, 0x01]),
            [0x83, 0x02]
        );
        assert_eq!(
            execute(&mut s, &[0x03, 0xFF, 0xFF, 0x00, 0x02]),
            [0x83, 0x02]
        );
        assert_eq!(
            execute(&mut s, &[0x03, 0x00, 0x64, 0x00, 0x00]),
            [0x83, 0x03]
        );
        assert_eq!(
            execute(&mut s, &[0x03, 0x00, 0x64, 0x00, 0x7E]),
            [0x83, 0x03]
        );
        assert_eq!(execute(&mut s, &[0x06, 0x01]), [0x86, 0x03]);
        assert_eq!(execute(&mut s, &[]), [0x80, 0x01]);
        assert_eq!(
            execute(&mut s, &[0x10, 0xFF, 0xFF, 0x00, 0x01, 0x02, 0x00]),
            [0x90, 0x03]
        );
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..20_000 {
            let len = rng.random_range(0..12);
            let mut pdu: Vec<u8> = (0..len).map(|_| rng.random()).collect();
            if let Some(f) = pdu.first_mut() {
                *f = [0x03, 0x06, 0x10, 0x04][usize::from(*f % 4)];
            }
            let reply = execute(&mut s, &pdu);
            assert!(!reply.is_empty());
        }
    }
}
