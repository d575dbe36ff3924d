//! Writing a run's rows (an import, the run hook) and clearing the catalog (a rebuild): one
//! transaction per run, its child rows replaced as a whole. Kept apart from `db.rs`; the same
//! statements serve both backends (`on_pool!`).

use super::{Catalog, Pool, now_utc, series};
use crate::error::CatalogError;
use crate::record::RunRecord;

const UPSERT_RUN: &str = "INSERT INTO runs (id, directory, host, station_id, plan_name, \
     plan_hash, kind, dut_serial, dut_model, operator, customer, status, reason, started_utc, \
     ended_utc, simulated, verdict, acceptance_rule, steps_total, steps_done, ambient_c, \
     humidity_pct, gyrocal_version, imported_utc) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, \
     $10, $11, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, $22, $23, $24) \
     ON CONFLICT (id) DO UPDATE SET directory = excluded.directory, host = excluded.host, \
     station_id = excluded.station_id, plan_name = excluded.plan_name, \
     plan_hash = excluded.plan_hash, kind = excluded.kind, dut_serial = excluded.dut_serial, \
     dut_model = excluded.dut_model, operator = excluded.operator, \
     customer = excluded.customer, status = excluded.status, reason = excluded.reason, \
     started_utc = excluded.started_utc, ended_utc = excluded.ended_utc, \
     simulated = excluded.simulated, verdict = excluded.verdict, \
     acceptance_rule = excluded.acceptance_rule, steps_total = excluded.steps_total, \
     steps_done = excluded.steps_done, ambient_c = excluded.ambient_c, \
     humidity_pct = excluded.humidity_pct, gyrocal_version = excluded.gyrocal_version, \
     imported_utc = excluded.imported_utc";
const INSERT_RESULTS: &str = "INSERT INTO results (run_id, scale_factor, \
     scale_factor_std_error, bias_v, bias_v_std_error, bias_dph, k_pos, k_neg, k2, \
     nonlinearity_ppm, asymmetry_ppm, asymmetry_common_k2_ppm, repeatability_ppm, \
     u_scale_factor, u_bias_v, u_bias_dph, u_k_pos, u_k_neg, best_model, arw_deg_rt_h, \
     u_arw_deg_rt_h, bias_instability_dph, u_bias_instability_dph, rrw_dph_rt_h, u_rrw_dph_rt_h, \
     drift_bias_dph, u_drift_bias_dph, bias_stability_100s_dph, drift_duration_s) VALUES ($1, \
     $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17, $18, $19, $20, $21, \
     $22, $23, $24, $25, $26, $27, $28, $29)";
const INSERT_STEP: &str = "INSERT INTO steps (run_id, step, pass, rate_dps, rate_meas_dps, \
     volts, volts_std, n, overloads) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)";
const INSERT_INSTRUMENT: &str = "INSERT INTO instruments (run_id, role, identity, model, \
     asset_id, serial, certificate, calibrated, due) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)";
const INSERT_CHECK: &str = "INSERT INTO checks (run_id, quantity, value, unit, \
     expanded_uncertainty, min, max, marginal_min, marginal_max, verdict) VALUES ($1, $2, $3, \
     $4, $5, $6, $7, $8, $9, $10)";
/// The child tables, deleted before a run's rows are written again.
const CHILD_TABLES: [&str; 6] = [
    "results",
    "steps",
    "instruments",
    "checks",
    "series_results",
    "series_points",
];

impl Catalog {
    /// Writes a run's rows, replacing what the catalog held for its id, in one transaction:
    /// importing the same run twice (or from two processes at once) leaves one copy.
    pub async fn upsert(&self, rec: &RunRecord) -> Result<(), CatalogError> {
        let imported = now_utc();
        let result: Result<(), sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut tx = p.begin().await?;
                let r = &rec.run;
                sqlx::query(UPSERT_RUN)
                    .bind(&r.id)
                    .bind(&r.directory)
                    .bind(&r.host)
                    .bind(&r.station_id)
                    .bind(&r.plan_name)
                    .bind(&r.plan_hash)
                    .bind(&r.kind)
                    .bind(&r.dut_serial)
                    .bind(&r.dut_model)
                    .bind(&r.operator)
                    .bind(&r.customer)
                    .bind(&r.status)
                    .bind(&r.reason)
                    .bind(&r.started_utc)
                    .bind(&r.ended_utc)
                    .bind(r.simulated)
                    .bind(&r.verdict)
                    .bind(&r.acceptance_rule)
                    .bind(r.steps_total)
                    .bind(r.steps_done)
                    .bind(r.ambient_c)
                    .bind(r.humidity_pct)
                    .bind(&r.gyrocal_version)
                    .bind(&imported)
                    .execute(&mut *tx)
                    .await?;
                for table in CHILD_TABLES {
                    sqlx::query(&format!("DELETE FROM {table} WHERE run_id = $1"))
                        .bind(&r.id)
                        .execute(&mut *tx)
                        .await?;
                }
                if let Some(x) = &rec.results {
                    sqlx::query(INSERT_RESULTS)
                        .bind(&r.id)
                        .bind(x.scale_factor)
                        .bind(x.scale_factor_std_error)
                        .bind(x.bias_v)
                        .bind(x.bias_v_std_error)
                        .bind(x.bias_dph)
                        .bind(x.k_pos)
                        .bind(x.k_neg)
                        .bind(x.k2)
                        .bind(x.nonlinearity_ppm)
                        .bind(x.asymmetry_ppm)
                        .bind(x.asymmetry_common_k2_ppm)
                        .bind(x.repeatability_ppm)
                        .bind(x.u_scale_factor)
                        .bind(x.u_bias_v)
                        .bind(x.u_bias_dph)
                        .bind(x.u_k_pos)
                        .bind(x.u_k_neg)
                        .bind(&x.best_model)
                        .bind(x.arw_deg_rt_h)
                        .bind(x.u_arw_deg_rt_h)
                        .bind(x.bias_instability_dph)
                        .bind(x.u_bias_instability_dph)
                        .bind(x.rrw_dph_rt_h)
                        .bind(x.u_rrw_dph_rt_h)
                        .bind(x.drift_bias_dph)
                        .bind(x.u_drift_bias_dph)
                        .bind(x.bias_stability_100s_dph)
                        .bind(x.drift_duration_s)
                        .execute(&mut *tx)
                        .await?;
                }
                for s in &rec.steps {
                    sqlx::query(INSERT_STEP)
                        .bind(&r.id)
                        .bind(s.step)
                        .bind(s.pass)
                        .bind(s.rate_dps)
                        .bind(s.rate_meas_dps)
                        .bind(s.volts)
                        .bind(s.volts_std)
                        .bind(s.n)
                        .bind(s.overloads)
                        .execute(&mut *tx)
                        .await?;
                }
                for i in &rec.instruments {
                    sqlx::query(INSERT_INSTRUMENT)
                        .bind(&r.id)
                        .bind(&i.role)
                        .bind(&i.identity)
                        .bind(&i.model)
                        .bind(&i.asset_id)
                        .bind(&i.serial)
                        .bind(&i.certificate)
                        .bind(&i.calibrated)
                        .bind(&i.due)
                        .execute(&mut *tx)
                        .await?;
                }
                if let Some(x) = &rec.series {
                    series::insert_series!(tx, &r.id, x);
                }
                for c in &rec.checks {
                    sqlx::query(INSERT_CHECK)
                        .bind(&r.id)
                        .bind(&c.quantity)
                        .bind(c.value)
                        .bind(&c.unit)
                        .bind(c.expanded_uncertainty)
                        .bind(c.min)
                        .bind(c.max)
                        .bind(c.marginal_min)
                        .bind(c.marginal_max)
                        .bind(&c.verdict)
                        .execute(&mut *tx)
                        .await?;
                }
                tx.commit().await
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }

    /// Deletes every row (for `gyrocal catalog rebuild`), in one transaction.
    pub async fn clear(&self) -> Result<(), CatalogError> {
        let result: Result<(), sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut tx = p.begin().await?;
                for table in CHILD_TABLES.iter().chain(["runs"].iter()) {
                    sqlx::query(&format!("DELETE FROM {table}"))
                        .execute(&mut *tx)
                        .await?;
                }
                tx.commit().await
            }
            .await
        });
        result.map_err(|e| self.err(&e))
    }
}
