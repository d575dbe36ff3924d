//! The series tables (`series_results`, `series_points`, schema version 3): written with a
//! run's other rows in [`super::Catalog::upsert`]'s transaction, read for a gyro's history.
//! Kept apart from `db.rs` so each file holds one concern; the same statements serve both
//! backends (`on_pool!`).

use std::collections::HashMap;

use sqlx::Row as _;

use super::{Catalog, Pool};
use crate::error::CatalogError;
use crate::series::{SeriesPointRecord, SeriesRecord};

pub(super) const INSERT_SERIES: &str = "INSERT INTO series_results (run_id, \
     k_tempco_ppm_per_c, u_k_tempco_ppm_per_c, bias_tempco_dph_per_c, u_bias_tempco_dph_per_c, \
     k_model_order, bias_model_order, hysteresis_k_ppm, hysteresis_bias_dph, t_min_c, t_max_c) \
     VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)";
pub(super) const INSERT_SERIES_POINT: &str = "INSERT INTO series_points (run_id, series_point, \
     setpoint_c, temp_min_c, temp_mean_c, temp_max_c, k, u_k, bias_dph, u_bias_dph, \
     nonlinearity_ppm) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)";

/// Writes `$series` of run `$id` in the transaction `$tx` (inside `on_pool!`, so one text
/// serves both backends' transaction types).
macro_rules! insert_series {
    ($tx:expr, $id:expr, $series:expr) => {{
        let s: &crate::series::SeriesRecord = $series;
        sqlx::query(crate::db::series::INSERT_SERIES)
            .bind($id)
            .bind(s.k_tempco_ppm_per_c)
            .bind(s.u_k_tempco_ppm_per_c)
            .bind(s.bias_tempco_dph_per_c)
            .bind(s.u_bias_tempco_dph_per_c)
            .bind(s.k_model_order)
            .bind(s.bias_model_order)
            .bind(s.hysteresis_k_ppm)
            .bind(s.hysteresis_bias_dph)
            .bind(s.t_min_c)
            .bind(s.t_max_c)
            .execute(&mut *$tx)
            .await?;
        for p in &s.points {
            sqlx::query(crate::db::series::INSERT_SERIES_POINT)
                .bind($id)
                .bind(p.series_point)
                .bind(p.setpoint_c)
                .bind(p.temp_min_c)
                .bind(p.temp_mean_c)
                .bind(p.temp_max_c)
                .bind(p.k)
                .bind(p.u_k)
                .bind(p.bias_dph)
                .bind(p.u_bias_dph)
                .bind(p.nonlinearity_ppm)
                .execute(&mut *$tx)
                .await?;
        }
    }};
}
pub(super) use insert_series;

impl Catalog {
    /// The series of every run of the gyro `serial`, by run id (runs without a series are
    /// absent), points in the plan's order.
    pub(super) async fn series_of_serial(
        &self,
        serial: &str,
    ) -> Result<HashMap<String, SeriesRecord>, CatalogError> {
        let results_sql = "SELECT s.run_id, s.k_tempco_ppm_per_c, s.u_k_tempco_ppm_per_c, \
             s.bias_tempco_dph_per_c, s.u_bias_tempco_dph_per_c, s.k_model_order, \
             s.bias_model_order, s.hysteresis_k_ppm, s.hysteresis_bias_dph, s.t_min_c, s.t_max_c \
             FROM series_results s JOIN runs r ON r.id = s.run_id WHERE r.dut_serial = $1";
        let points_sql = "SELECT p.run_id, p.series_point, p.setpoint_c, p.temp_min_c, \
             p.temp_mean_c, p.temp_max_c, p.k, p.u_k, p.bias_dph, p.u_bias_dph, \
             p.nonlinearity_ppm FROM series_points p JOIN runs r ON r.id = p.run_id \
             WHERE r.dut_serial = $1 ORDER BY p.run_id, p.series_point";
        let result: Result<HashMap<String, SeriesRecord>, sqlx::Error> = on_pool!(self, |p| {
            async {
                let mut out = HashMap::new();
                for row in &sqlx::query(results_sql).bind(serial).fetch_all(p).await? {
                    let id: String = row.try_get("run_id")?;
                    out.insert(
                        id,
                        SeriesRecord {
                            points: Vec::new(),
                            k_tempco_ppm_per_c: row.try_get("k_tempco_ppm_per_c")?,
                            u_k_tempco_ppm_per_c: row.try_get("u_k_tempco_ppm_per_c")?,
                            bias_tempco_dph_per_c: row.try_get("bias_tempco_dph_per_c")?,
                            u_bias_tempco_dph_per_c: row.try_get("u_bias_tempco_dph_per_c")?,
                            k_model_order: row.try_get("k_model_order")?,
                            bias_model_order: row.try_get("bias_model_order")?,
                            hysteresis_k_ppm: row.try_get("hysteresis_k_ppm")?,
                            hysteresis_bias_dph: row.try_get("hysteresis_bias_dph")?,
                            t_min_c: row.try_get("t_min_c")?,
                            t_max_c: row.try_get("t_max_c")?,
                        },
                    );
                }
                for row in &sqlx::query(points_sql).bind(serial).fetch_all(p).await? {
                    let id: String = row.try_get("run_id")?;
                    let point = SeriesPointRecord {
                        series_point: row.try_get("series_point")?,
                        setpoint_c: row.try_get("setpoint_c")?,
                        temp_min_c: row.try_get("temp_min_c")?,
                        temp_mean_c: row.try_get("temp_mean_c")?,
                        temp_max_c: row.try_get("temp_max_c")?,
                        k: row.try_get("k")?,
                        u_k: row.try_get("u_k")?,
                        bias_dph: row.try_get("bias_dph")?,
                        u_bias_dph: row.try_get("u_bias_dph")?,
                        nonlinearity_ppm: row.try_get("nonlinearity_ppm")?,
                    };
                    // a point without its run's series row is an orphan no writer leaves
                    match out.get_mut(&id) {
                        Some(s) => s.points.push(point),
                        None => {
                            return Err(sqlx::Error::Decode(
                                format!(
                                    "series_points holds point {} of run {id}, which has no \
                                     series_results row",
                                    point.series_point
                                )
                                .into(),
                            ));
                        }
                    }
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
}
