CREATE TABLE IF NOT EXISTS runs (
    id TEXT PRIMARY KEY,
    directory TEXT NOT NULL,
    host TEXT,
    station_id TEXT,
    plan_name TEXT NOT NULL,
    plan_hash TEXT NOT NULL,
    kind TEXT NOT NULL,
    dut_serial TEXT,
    dut_model TEXT,
    operator TEXT,
    customer TEXT,
    status TEXT NOT NULL,
    reason TEXT,
    started_utc TEXT NOT NULL,
    ended_utc TEXT,
    simulated BOOLEAN NOT NULL,
    verdict TEXT,
    acceptance_rule TEXT,
    steps_total BIGINT NOT NULL,
    steps_done BIGINT NOT NULL,
    ambient_c DOUBLE PRECISION,
    humidity_pct DOUBLE PRECISION,
    gyrocal_version TEXT,
    imported_utc TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS runs_serial_started ON runs (dut_serial, started_utc);
CREATE INDEX IF NOT EXISTS runs_started ON runs (started_utc);

CREATE TABLE IF NOT EXISTS results (
    run_id TEXT PRIMARY KEY REFERENCES runs (id) ON DELETE CASCADE,
    scale_factor DOUBLE PRECISION,
    scale_factor_std_error DOUBLE PRECISION,
    bias_v DOUBLE PRECISION,
    bias_v_std_error DOUBLE PRECISION,
    bias_dph DOUBLE PRECISION,
    k_pos DOUBLE PRECISION,
    k_neg DOUBLE PRECISION,
    k2 DOUBLE PRECISION,
    nonlinearity_ppm DOUBLE PRECISION,
    asymmetry_ppm DOUBLE PRECISION,
    asymmetry_common_k2_ppm DOUBLE PRECISION,
    repeatability_ppm DOUBLE PRECISION,
    u_scale_factor DOUBLE PRECISION,
    u_bias_v DOUBLE PRECISION,
    u_bias_dph DOUBLE PRECISION,
    u_k_pos DOUBLE PRECISION,
    u_k_neg DOUBLE PRECISION,
    best_model TEXT
);

CREATE TABLE IF NOT EXISTS steps (
    run_id TEXT NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
    step BIGINT NOT NULL,
    pass BIGINT NOT NULL,
    rate_dps DOUBLE PRECISION NOT NULL,
    rate_meas_dps DOUBLE PRECISION,
    volts DOUBLE PRECISION NOT NULL,
    volts_std DOUBLE PRECISION,
    n BIGINT NOT NULL,
    overloads BIGINT NOT NULL,
    PRIMARY KEY (run_id, step)
);

CREATE TABLE IF NOT EXISTS instruments (
    run_id TEXT NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
    role TEXT NOT NULL,
    identity TEXT,
    model TEXT,
    asset_id TEXT,
    serial TEXT,
    certificate TEXT,
    calibrated TEXT,
    due TEXT,
    PRIMARY KEY (run_id, role)
);

CREATE TABLE IF NOT EXISTS checks (
    run_id TEXT NOT NULL REFERENCES runs (id) ON DELETE CASCADE,
    quantity TEXT NOT NULL,
    value DOUBLE PRECISION,
    unit TEXT,
    expanded_uncertainty DOUBLE PRECISION,
    min DOUBLE PRECISION,
    max DOUBLE PRECISION,
    marginal_min DOUBLE PRECISION,
    marginal_max DOUBLE PRECISION,
    verdict TEXT,
    PRIMARY KEY (run_id, quantity)
);
