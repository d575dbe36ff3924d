//! The catalog's listings (`gyrocal runs`, a gyro's history, a run's steps and instruments):
//! the `runs` table with its `results`, `checks` and `steps`. Kept apart from `db.rs` (which
//! opens, migrates and closes) so each file holds one concern; the same statements serve
//! both backends (`on_pool!`).

use sqlx::Row as _;

use super::{Catalog, Pool, RunFilter};
use crate::error::CatalogError;
use crate::record::{CheckRow, InstrumentRow, Results, RunRow, StepRow};
use crate::rows::{Calibration, RunSummary};

const RUN_COLUMNS: &str = "r.id, r.directory, r.host, r.station_id, r.plan_name, r.plan_hash, \
     r.kind, r.dut_serial, r.dut_model, r.operator, r.customer, r.status, r.reason, \
     r.started_utc, r.ended_utc, r.simulated, r.verdict, r.acceptance_rule, r.steps_total, \
     r.steps_done, r.ambient_c, r.humidity_pct, r.gyrocal_version";
const RESULT_COLUMNS: &str = "res.run_id AS res_run_id, res.scale_factor, \
     res.scale_factor_std_error, res.bias_v, res.bias_v_std_error, res.bias_dph, res.k_pos, \
     res.k_neg, res.k2, res.nonlinearity_ppm, res.asymmetry_ppm, res.asymmetry_common_k2_ppm, \
     res.repeatability_ppm, res.u_scale_factor, res.u_bias_v, res.u_bias_dph, res.u_k_pos, \
     res.u_k_neg, res.best_model, res.arw_deg_rt_h, res.u_arw_deg_rt_h, \
     res.bias_instability_dph, res.u_bias_instability_dph, res.rrw_dph_rt_h, res.u_rrw_dph_rt_h, \
     res.drift_bias_dph, res.u_drift_bias_dph, res.bias_stability_100s_dph, res.drift_duration_s";

/// Reads a `runs` row selected with [`RUN_COLUMNS`].
macro_rules! run_row {
    ($r:expr) => {
        RunRow {
            id: $r.try_get("id")?,
            directory: $r.try_get("directory")?,
            host: $r.try_get("host")?,
            station_id: $r.try_get("station_id")?,
            plan_name: $r.try_get("plan_name")?,
            plan_hash: $r.try_get("plan_hash")?,
            kind: $r.try_get("kind")?,
            dut_serial: $r.try_get("dut_serial")?,
            dut_model: $r.try_get("dut_model")?,
            operator: $r.try_get("operator")?,
            customer: $r.try_get("customer")?,
            status: $r.try_get("status")?,
            reason: $r.try_get("reason")?,
            started_utc: $r.try_get("started_utc")?,
            ended_utc: $r.try_get("ended_utc")?,
            simulated: $r.try_get("simulated")?,
            verdict: $r.try_get("verdict")?,
            acceptance_rule: $r.try_get("acceptance_rule")?,
            steps_total: $r.try_get("steps_total")?,
            steps_done: $r.try_get("steps_done")?,
            ambient_c: $r.try_get("ambient_c")?,
            humidity_pct: $r.try_get("humidity_pct")?,
            gyrocal_version: $r.try_get("gyrocal_version")?,
        }
    };
}

/// Reads the `results` columns selected with [`RESULT_COLUMNS`] (`None` when the LEFT JOIN
/// found none).
macro_rules! results_row {
    ($r:expr) => {{
        let present: Option<String> = $r.try_get("res_run_id")?;
        match present {
            None => None,
            Some(_) => Some(Results {
                scale_factor: $r.try_get("scale_factor")?,
                scale_factor_std_error: $r.try_get("scale_factor_std_error")?,
                bias_v: $r.try_get("bias_v")?,
                bias_v_std_error: $r.try_get("bias_v_std_error")?,
                bias_dph: $r.try_get("bias_dph")?,
                k_pos: $r.try_get("k_pos")?,
                k_neg: $r.try_get("k_neg")?,
                k2: $r.try_get("k2")?,
                nonlinearity_ppm: $r.try_get("nonlinearity_ppm")?,
                asymmetry_ppm: $r.try_get("asymmetry_ppm")?,
                asymmetry_common_k2_ppm: $r.try_get("asymmetry_common_k2_ppm")?,
                repeatability_ppm: $r.try_get("repeatability_ppm")?,
                u_scale_factor: $r.try_get("u_scale_factor")?,
                u_bias_v: $r.try_get("u_bias_v")?,
                u_bias_dph: $r.try_get("u_bias_dph")?,
                u_k_pos: $r.try_get("u_k_pos")?,
                u_k_neg: $r.try_get("u_k_neg")?,
                best_model: $r.try_get("best_model")?,
                arw_deg_rt_h: $r.try_get("arw_deg_rt_h")?,
                u_arw_deg_rt_h: $r.try_get("u_arw_deg_rt_h")?,
                bias_instability_dph: $r.try_get("bias_instability_dph")?,
                u_bias_instability_dph: $r.try_get("u_bias_instability_dph")?,
                rrw_dph_rt_h: $r.try_get("rrw_dph_rt_h")?,
                u_rrw_dph_rt_h: $r.try_get("u_rrw_dph_rt_h")?,
                drift_bias_dph: $r.try_get("drift_bias_dph")?,
                u_drift_bias_dph: $r.try_get("u_drift_bias_dph")?,
                bias_stability_100s_dph: $r.try_get("bias_stability_100s_dph")?,
                drift_duration_s: $r.try_get("drift_duration_s")?,
            }),
        }
    }};
}
impl Catalog {
    /// The runs matching `filter`, newest first, with their results.
    pub async fn runs(&self, filter: &RunFilter) -> Result<Vec<RunSummary>, CatalogError> {
        let mut sql = format!(
            "SELECT {RUN_COLUMNS}, {RESULT_COLUMNS} FROM runs r \
             LEFT JOIN results res ON res.run_id = r.id WHERE 1 = 1"
        );
        let mut binds: Vec<String> = Vec::new();
        for (column, op, value) in [
            ("r.dut_serial", "=", &filter.serial),
            ("r.status", "=", &filter.status),
            ("r.started_utc", ">=", &filter.since),
            ("r.station_id", "=", &filter.station),
        ] {
            if let Some(v) = value {
                binds.push(v.clone());
                sql.push_str(&format!(" AND {column} {op} ${}", binds.len()));
            }
        }
        sql.push_str(" ORDER BY r.started_utc DESC, r.id DESC");
        if let Some(limit) = filter.limit {
            sql.push_str(&format!(" LIMIT {}", limit.max(0)));
        }
        self.check_listed_tables().await?;
        let result: Result<Vec<RunSummary>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut q = sqlx::query(&sql);
                for b in &binds {
                    q = q.bind(b);
                }
                let rows = q.fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(RunSummary {
                        run: run_row!(row),
                        results: results_row!(row),
                    });
                }
                Ok(out)
            }
            .await
        });
        match result {
            Ok(out) => Ok(out),
            Err(e) => Err(self.read_error(&e).await),
        }
    }

    /// The complete calibrations of the gyro `serial`, oldest first, with results and
    /// acceptance checks; simulated runs only when `include_simulated`.
    pub async fn calibrations(
        &self,
        serial: &str,
        include_simulated: bool,
    ) -> Result<Vec<Calibration>, CatalogError> {
        // Every run of the serial is read and decoded, and the status and simulated filters
        // applied here rather than in SQL: a row garbled on disk then fails to decode (or
        // shows a status gyrocal never writes) instead of silently failing a WHERE clause
        // and leaving the history one calibration short.
        let sql = format!(
            "SELECT {RUN_COLUMNS}, {RESULT_COLUMNS} FROM runs r \
             LEFT JOIN results res ON res.run_id = r.id \
             WHERE r.dut_serial = $1 \
             ORDER BY r.started_utc, r.id"
        );
        let checks_sql = "SELECT c.run_id, c.quantity, c.value, c.unit, \
             c.expanded_uncertainty, c.min, c.max, c.marginal_min, c.marginal_max, c.verdict \
             FROM checks c JOIN runs r ON r.id = c.run_id WHERE r.dut_serial = $1";
        let rates_sql = "SELECT DISTINCT s.run_id, s.rate_dps FROM steps s \
             JOIN runs r ON r.id = s.run_id WHERE r.dut_serial = $1";
        self.check_listed_tables().await?;
        let result: Result<Vec<Calibration>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let rows = sqlx::query(&sql).bind(serial).fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    let run: RunRow = run_row!(row);
                    let results = results_row!(row);
                    if !is_status_word(&run.status) {
                        return Err(sqlx::Error::Decode(
                            format!(
                                "run {} has the status {:?}, which gyrocal never writes",
                                run.id, run.status
                            )
                            .into(),
                        ));
                    }
                    if run.status != "complete" || (run.simulated && !include_simulated) {
                        continue;
                    }
                    out.push(Calibration {
                        run,
                        results,
                        checks: Vec::new(),
                        rates_dps: Vec::new(),
                        series: None,
                    });
                }
                let rows = sqlx::query(checks_sql).bind(serial).fetch_all(p).await?;
                let mut index = std::collections::HashMap::new();
                for (i, c) in out.iter().enumerate() {
                    index.insert(c.run.id.clone(), i);
                }
                for row in &rows {
                    let id: String = row.try_get("run_id")?;
                    let check = CheckRow {
                        quantity: row.try_get("quantity")?,
                        value: row.try_get("value")?,
                        unit: row.try_get("unit")?,
                        expanded_uncertainty: row.try_get("expanded_uncertainty")?,
                        min: row.try_get("min")?,
                        max: row.try_get("max")?,
                        marginal_min: row.try_get("marginal_min")?,
                        marginal_max: row.try_get("marginal_max")?,
                        verdict: row.try_get("verdict")?,
                    };
                    if let Some(&i) = index.get(&id) {
                        out[i].checks.push(check);
                    }
                }
                // the rates each run demanded: the history tells plans apart by them (a
                // different simulation seed is the same plan, a different rate list is not)
                let rows = sqlx::query(rates_sql).bind(serial).fetch_all(p).await?;
                for row in &rows {
                    let id: String = row.try_get("run_id")?;
                    let rate: f64 = row.try_get("rate_dps")?;
                    if let Some(&i) = index.get(&id) {
                        out[i].rates_dps.push(rate);
                    }
                }
                for c in &mut out {
                    c.rates_dps.sort_by(f64::total_cmp);
                    c.rates_dps.dedup();
                }
                Ok(out)
            }
            .await
        });
        let mut out = match result {
            Ok(out) => out,
            Err(e) => return Err(self.read_error(&e).await),
        };
        // a temperature series' sensitivities and points (schema version 3)
        let mut series = self.series_of_serial(serial).await?;
        for c in &mut out {
            c.series = series.remove(&c.run.id);
        }
        Ok(out)
    }

    /// The finished steps of a run, in order.
    pub async fn steps(&self, run_id: &str) -> Result<Vec<StepRow>, CatalogError> {
        let sql = "SELECT step, pass, rate_dps, rate_meas_dps, volts, volts_std, n, overloads \
                   FROM steps WHERE run_id = $1 ORDER BY step";
        let result: Result<Vec<StepRow>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let rows = sqlx::query(sql).bind(run_id).fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(StepRow {
                        step: row.try_get("step")?,
                        pass: row.try_get("pass")?,
                        rate_dps: row.try_get("rate_dps")?,
                        rate_meas_dps: row.try_get("rate_meas_dps")?,
                        volts: row.try_get("volts")?,
                        volts_std: row.try_get("volts_std")?,
                        n: row.try_get("n")?,
                        overloads: row.try_get("overloads")?,
                    });
                }
                Ok(out)
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// The instruments of a run.
    pub async fn instruments(&self, run_id: &str) -> Result<Vec<InstrumentRow>, CatalogError> {
        let sql = "SELECT role, identity, model, asset_id, serial, certificate, calibrated, due \
                   FROM instruments WHERE run_id = $1 ORDER BY role";
        let result: Result<Vec<InstrumentRow>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let rows = sqlx::query(sql).bind(run_id).fetch_all(p).await?;
                let mut out = Vec::with_capacity(rows.len());
                for row in &rows {
                    out.push(InstrumentRow {
                        role: row.try_get("role")?,
                        identity: row.try_get("identity")?,
                        model: row.try_get("model")?,
                        asset_id: row.try_get("asset_id")?,
                        serial: row.try_get("serial")?,
                        certificate: row.try_get("certificate")?,
                        calibrated: row.try_get("calibrated")?,
                        due: row.try_get("due")?,
                    });
                }
                Ok(out)
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }
}

/// A run status as gyrocal writes it (`complete`, `failed`, ...): lower-case ASCII words.
fn is_status_word(status: &str) -> bool {
    !status.is_empty() && status.bytes().all(|b| b.is_ascii_lowercase() || b == b'_')
}
