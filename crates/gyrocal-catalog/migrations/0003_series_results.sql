-- gyrocal catalog, schema version 3: a temperature series (the `catalog` member of the run's
-- series.json): one row per run with the temperature sensitivities and their expanded
-- uncertainties (k = 2), the models' orders, the hysteresis and the range, and one row per
-- temperature. The same statements for SQLite and PostgreSQL. Documented in SCHEMA.md.
CREATE TABLE IF NOT EXISTS series_results (
    run_id TEXT PRIMARY KEY REFERENCES runs (id) ON DELETE CASCADE,
    k_tempco_ppm_per_c DOUBLE PRECISION,
    u_k_tempco_ppm_per_c DOUBLE PRECISION,
    bias_tempco_dph_per_c DOUBLE PRECISION,
    u_bias_tempco_dph_per_c DOUBLE PRECISION,
    k_model_order BIGINT,
    bias_model_order BIGINT,
    hysteresis_k_ppm DOUBLE PRECISION,
    hysteresis_bias_dph DOUBLE PRECISION,
    t_min_c DOUBLE PRECISION,
    t_max_c DOUBLE PRECISION
);

CREATE TABLE IF NOT EXISTS series_points (
    run_id TEXT NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
    series_point BIGINT NOT NULL,
    setpoint_c DOUBLE PRECISION NOT NULL,
    temp_min_c DOUBLE PRECISION,
    temp_mean_c DOUBLE PRECISION,
    temp_max_c DOUBLE PRECISION,
    k DOUBLE PRECISION,
    u_k DOUBLE PRECISION,
    bias_dph DOUBLE PRECISION,
    u_bias_dph DOUBLE PRECISION,
    nonlinearity_ppm DOUBLE PRECISION,
    PRIMARY KEY (run_id, series_point)
);
