//! The ACL table driver against a table that answers arbitrary lines: every driver call must
//! return (an error is fine), never panic. The ACL reply parsers are private, so the driver is
//! fuzzed whole, in tokio's paused clock (its waits cost nothing).
#![no_main]

use std::collections::VecDeque;
use std::sync::OnceLock;
use std::time::Duration;

use gyrocal_link::{LinkError, Transport};
use gyrocal_table::acl::{AclConfig, AclTable};
use gyrocal_table::{RateTable, SettleCriteria};
use libfuzzer_sys::fuzz_target;

/// Answers every read with the next fuzzed line; a timeout once they run out.
struct Replies {
    lines: VecDeque<String>,
}

impl Transport for Replies {
    fn describe(&self) -> &str {
        "fuzz-table"
    }
    async fn write_raw(&mut self, _bytes: &[u8]) -> Result<(), LinkError> {
        Ok(())
    }
    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        match self.lines.pop_front() {
            Some(l) => Ok(l),
            None => Err(LinkError::Timeout {
                device: "fuzz-table".into(),
                timeout: timeout.unwrap_or_default(),
                partial: Vec::new(),
            }),
        }
    }
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        Ok(0)
    }
}

fn runtime() -> &'static tokio::runtime::Runtime {
    static RT: OnceLock<tokio::runtime::Runtime> = OnceLock::new();
    RT.get_or_init(|| {
        tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .start_paused(true)
            .build()
            .expect("runtime")
    })
}

fuzz_target!(|data: &[u8]| {
    if data.len() > 4096 {
        return;
    }
    let text = String::from_utf8_lossy(data);
    let lines: VecDeque<String> = text.split('\n').map(str::to_string).collect();
    runtime().block_on(async move {
        let mut table = AclTable::new(Replies { lines }, AclConfig::default());
        let criteria = SettleCriteria {
            timeout: Duration::from_secs(5),
            ..SettleCriteria::default()
        };
        if table.connect().await.is_ok() && table.enable().await.is_ok() {
            if table.set_rate(10.0, 5.0).await.is_ok() {
                let _ = table.wait_at_rate(&criteria).await;
                let _ = table.sample().await;
            }
        }
        let _ = table.read_rate().await;
        let _ = table.read_position().await;
        let _ = table.status().await;
        let _ = table.heartbeat().await;
        let _ = table.stop().await;
        let _ = table.wait_stopped(Duration::from_secs(2)).await;
        let _ = table.emergency_stop().await;
    });
});
