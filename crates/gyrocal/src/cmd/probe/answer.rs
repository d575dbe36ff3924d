//! Who answered on a port: the probe's second look at a port whose instrument's driver
//! failed, so a swapped cable or a wrong `--dmm-port` is said as such instead of as a silent
//! instrument.
//!
//! The look is the same on every port, whichever instrument the plan expects there, and it
//! relies only on what the real devices do with a query they do not know
//! (`/work/shared/docs/hp34401a.md`, `rate-table.md`, `instruments.md`):
//!
//! - a 34401A on RS-232 answers nothing before `SYSTem:REMote` (its manual: results are
//!   unpredictable), so the look sends `SYST:REM` first on links that need it. An ACUTROL
//!   table takes `SYST:REM` as an undefined header (error -113 queued, no reply: its driver
//!   drains the queue when it connects); an Ideal Aerosmith answers `?` and its prompt;
//! - then `*IDN?`: a 34401A or a Truevolt answers `HEWLETT-PACKARD,34401A,...` (a Truevolt
//!   may pose as one, or answer as itself, `Keysight Technologies,34461A,...`); an ACUTROL
//!   answers `ACUTRONIC,ACUTROL3000,<serial>,<version>`; an Aerosmith controller knows no
//!   `*IDN?` and waits for its own line ending (CR), so it says nothing yet;
//! - if nothing answered, `STA` and a CR, the Aerosmith status query: an Aerosmith answers
//!   (a number, or `?` for the line it could not parse) and its `>` prompt. A 34401A ignores
//!   a line that has no LF yet. Nothing at all: the port is silent (off, wrong baud, wrong
//!   cable).
//!
//! Nothing here moves a table: the look only identifies.

use std::time::Duration;

use gyrocal_link::Transport;

/// How long each reply of the look may take: far more than any of these devices needs to
/// answer an identification (the 34401A: a few ms plus 40 characters at the baud rate).
pub const LOOK_TIMEOUT: Duration = Duration::from_secs(2);

/// What answered on one port.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Who {
    /// A multimeter: an HP/Agilent/Keysight 344xx identity (a 34401A, or a Truevolt).
    Meter {
        /// Its `*IDN?` reply.
        reply: String,
    },
    /// A rate table: an ACUTRONIC identity, or an Ideal Aerosmith-style `>` prompt.
    Table {
        /// What it answered (its `*IDN?`, or its reply to `STA` with the prompt).
        reply: String,
    },
    /// Something answered that is neither instrument's identity (often a wrong baud rate or
    /// framing, or another device).
    Other {
        /// What arrived.
        reply: String,
    },
    /// Nothing answered.
    Nothing,
    /// The port could not be opened.
    Unopened {
        /// Why.
        error: String,
    },
}

impl Who {
    /// The instrument in words, with what it said: "a multimeter (*IDN? "...")".
    pub fn words(&self) -> String {
        match self {
            Who::Meter { reply } => format!("a multimeter answered (*IDN? {})", quoted(reply)),
            Who::Table { reply } if reply.ends_with('>') => format!(
                "a rate table answered (an Ideal Aerosmith-style prompt: {})",
                quoted(reply)
            ),
            Who::Table { reply } => format!("a rate table answered (*IDN? {})", quoted(reply)),
            Who::Other { reply } => format!(
                "something answered that is neither a multimeter nor a rate table: {}",
                quoted(reply)
            ),
            Who::Nothing => "nothing answered".to_string(),
            Who::Unopened { .. } => "the port did not open".to_string(),
        }
    }

    /// The name used in the `--json` document: `multimeter`, `table`, `other`, `nothing`,
    /// `unopened`.
    pub fn key(&self) -> &'static str {
        match self {
            Who::Meter { .. } => "multimeter",
            Who::Table { .. } => "table",
            Who::Other { .. } => "other",
            Who::Nothing => "nothing",
            Who::Unopened { .. } => "unopened",
        }
    }

    /// What arrived, if anything did.
    pub fn reply(&self) -> Option<&str> {
        match self {
            Who::Meter { reply } | Who::Table { reply } | Who::Other { reply } => Some(reply),
            Who::Nothing | Who::Unopened { .. } => None,
        }
    }

    /// True when one of the two instruments answered (so cable and baud advice is beside the
    /// point).
    pub fn is_instrument(&self) -> bool {
        matches!(self, Who::Meter { .. } | Who::Table { .. })
    }
}

/// A reply shown in a message: quoted, control characters escaped, at most 80 characters.
pub fn quoted(reply: &str) -> String {
    let mut s: String = reply.chars().take(80).collect();
    if reply.chars().count() > 80 {
        s.push('…');
    }
    format!("{s:?}")
}

/// Classifies what a port answered to `*IDN?` (or, for an Aerosmith, to `STA` with its
/// prompt). An empty reply is [`Who::Nothing`].
pub fn classify(reply: &str) -> Who {
    let r = reply.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    if r.is_empty() {
        return Who::Nothing;
    }
    // an Ideal Aerosmith-style controller ends every reply with its prompt
    if r.ends_with('>') && r.len() <= 24 {
        return Who::Table {
            reply: r.to_string(),
        };
    }
    let fields: Vec<&str> = r.split(',').map(str::trim).collect();
    if fields.len() >= 2 {
        let maker = fields[0].to_ascii_uppercase();
        let model = fields[1].to_ascii_uppercase();
        let meter_maker = ["HEWLETT", "AGILENT", "KEYSIGHT"]
            .iter()
            .any(|m| maker.contains(m))
            || maker == "HP";
        if meter_maker && model.starts_with("344") {
            return Who::Meter {
                reply: r.to_string(),
            };
        }
        if maker.contains("ACUTRONIC")
            || model.starts_with("ACUTROL")
            || maker.contains("AEROSMITH")
        {
            return Who::Table {
                reply: r.to_string(),
            };
        }
    }
    Who::Other {
        reply: r.to_string(),
    }
}

/// Looks at who answers on `link` (see the module documentation for the exchange and why).
/// Errors of the link (a write that fails, a disconnect) count as silence: the look is
/// advice, never a failure of its own.
pub async fn look<T: Transport>(link: &mut T) -> Who {
    let _ = link.device_clear().await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let _ = link.discard_input().await;
    if link.needs_remote_command() {
        let _ = link.send_line("SYST:REM").await;
        // an Aerosmith on a CR LF wire answers the line at once: keep its answer out of the
        // identification (a 34401A, an ACUTROL: nothing)
        tokio::time::sleep(Duration::from_millis(100)).await;
        let _ = link.discard_input().await;
    }
    if link.send_line("*IDN?").await.is_ok() {
        match link.read_line(Some(LOOK_TIMEOUT)).await {
            Ok(reply) => {
                let who = classify(&reply);
                if who != Who::Nothing {
                    return who;
                }
            }
            Err(gyrocal_link::LinkError::Timeout { partial, .. }) if !partial.is_empty() => {
                // a reply without a line ending: an Aerosmith's prompt, or noise
                return classify(&String::from_utf8_lossy(&partial));
            }
            Err(_) => {}
        }
    }
    let _ = link.discard_input().await;
    if link.write_raw(b"STA\r").await.is_err() {
        return Who::Nothing;
    }
    match link.read_until(b'>', Some(LOOK_TIMEOUT)).await {
        Ok(before) => Who::Table {
            reply: format!("{}>", before.trim()),
        },
        Err(gyrocal_link::LinkError::Timeout { partial, .. }) if !partial.is_empty() => {
            classify(&String::from_utf8_lossy(&partial))
        }
        Err(_) => Who::Nothing,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meters_by_their_identity() {
        for idn in [
            "HEWLETT-PACKARD,34401A,0,11-5-2",
            "HEWLETT-PACKARD,34401A,0,7-5-2",
            "Keysight Technologies,34461A,MY53012345,A.02.14-02.40-02.14-00.49-01-01",
            "Agilent Technologies,34410A,MY47000001,2.35-2.35-0.09-46-09",
            "HEWLETT-PACKARD,34401A,SIM0001,11-5-2\r",
        ] {
            assert!(matches!(classify(idn), Who::Meter { .. }), "{idn}");
        }
    }

    #[test]
    fn tables_by_their_identity_or_prompt() {
        for reply in [
            "ACUTRONIC,ACUTROL3000,SIM0001,1.0",
            "Acutronic,ACUTROL3000,1120-0031,4.2",
            "?\r>",
            "5>",
        ] {
            assert!(matches!(classify(reply), Who::Table { .. }), "{reply:?}");
        }
    }

    #[test]
    fn anything_else_is_other_or_nothing() {
        assert_eq!(classify(""), Who::Nothing);
        assert_eq!(classify(" \r\n"), Who::Nothing);
        assert!(matches!(
            classify("\u{fffd}\u{fffd}x\u{fffd}"),
            Who::Other { .. }
        ));
        assert!(matches!(
            classify("FLUKE,8846A,1234,1.0"),
            Who::Other { .. }
        ));
        // a 34401A's number is not an identity
        assert!(matches!(classify("+1.00010310E+01"), Who::Other { .. }));
    }

    #[test]
    fn words_name_the_instrument_and_quote_its_reply() {
        let w = classify("ACUTRONIC,ACUTROL3000,SIM0001,1.0").words();
        assert_eq!(
            w,
            "a rate table answered (*IDN? \"ACUTRONIC,ACUTROL3000,SIM0001,1.0\")"
        );
        assert!(Who::Nothing.words().contains("nothing"));
    }

    /// What a 34401A on RS-232 does (answers `*IDN?` only after `SYST:REM`).
    #[tokio::test]
    async fn look_finds_a_34401a() {
        let mut link = gyrocal_link::ScriptedTransport::new("meter")
            .expect_raw(&[gyrocal_link::DEVICE_CLEAR])
            .expect_line("SYST:REM")
            .query("*IDN?", "HEWLETT-PACKARD,34401A,0,11-5-2");
        let who = look(&mut link).await;
        link.done();
        assert!(matches!(who, Who::Meter { .. }), "{who:?}");
    }

    /// What an ACUTROL does: `SYST:REM` unknown (queued error, no reply), `*IDN?` answered.
    #[tokio::test]
    async fn look_finds_an_acutrol() {
        let mut link = gyrocal_link::ScriptedTransport::new("table")
            .expect_raw(&[gyrocal_link::DEVICE_CLEAR])
            .expect_line("SYST:REM")
            .query("*IDN?", "ACUTRONIC,ACUTROL3000,1120-0031,4.2");
        let who = look(&mut link).await;
        link.done();
        assert_eq!(
            who,
            Who::Table {
                reply: "ACUTRONIC,ACUTROL3000,1120-0031,4.2".into()
            }
        );
    }

    /// What an Ideal Aerosmith does: no `*IDN?` (it waits for its CR); `STA` answered with
    /// its status and its prompt.
    #[tokio::test]
    async fn look_finds_an_aerosmith() {
        let mut link = gyrocal_link::ScriptedTransport::new("table")
            .expect_raw(&[gyrocal_link::DEVICE_CLEAR])
            .expect_line("SYST:REM")
            .expect_line("*IDN?")
            .silence()
            .expect_raw(b"STA\r")
            .reply("?\r")
            .reply(">");
        let who = look(&mut link).await;
        link.done();
        assert!(matches!(who, Who::Table { .. }), "{who:?}");
        assert!(who.words().contains("Aerosmith"), "{}", who.words());
    }

    /// What a silent port does: nothing to `*IDN?` nor to `STA`.
    #[tokio::test]
    async fn look_says_nothing_answered() {
        let mut link = gyrocal_link::ScriptedTransport::new("silent")
            .expect_raw(&[gyrocal_link::DEVICE_CLEAR])
            .expect_line("SYST:REM")
            .expect_line("*IDN?")
            .silence()
            .expect_raw(b"STA\r")
            .silence();
        let who = look(&mut link).await;
        link.done();
        assert_eq!(who, Who::Nothing);
    }
}
