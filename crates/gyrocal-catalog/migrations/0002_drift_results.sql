-- gyrocal catalog, schema version 2: the figures of a drift test (IEEE 952 noise terms from
-- the run's allan.json, five-term fit, expanded uncertainties k = 2) beside a sweep's. The
-- same statements for SQLite and PostgreSQL. Documented in SCHEMA.md.
ALTER TABLE results ADD COLUMN arw_deg_rt_h DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN u_arw_deg_rt_h DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN bias_instability_dph DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN u_bias_instability_dph DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN rrw_dph_rt_h DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN u_rrw_dph_rt_h DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN drift_bias_dph DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN u_drift_bias_dph DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN bias_stability_100s_dph DOUBLE PRECISION;
ALTER TABLE results ADD COLUMN drift_duration_s DOUBLE PRECISION;
