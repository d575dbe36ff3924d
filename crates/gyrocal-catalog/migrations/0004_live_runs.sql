-- gyrocal catalog, schema version 4: the live state of the runs going on (the message bus of
-- `gyrocal serve`): one row per run and host, replaced at each update of the run's live
-- state and announced with NOTIFY gyrocal_live on PostgreSQL. Not a result: the run directory
-- and the `runs` table stay the truth. The same statements for SQLite and PostgreSQL (an
-- SQLite catalog has the table but gyrocal publishes nothing to it). Documented in SCHEMA.md.
CREATE TABLE IF NOT EXISTS live_runs (
    run_id TEXT NOT NULL,
    host TEXT NOT NULL,
    station_id TEXT,
    dut_serial TEXT,
    plan_name TEXT NOT NULL,
    kind TEXT NOT NULL,
    phase TEXT NOT NULL,
    step BIGINT NOT NULL,
    steps BIGINT NOT NULL,
    steps_done BIGINT NOT NULL,
    eta_s DOUBLE PRECISION,
    last_reading_v DOUBLE PRECISION,
    running_mean_v DOUBLE PRECISION,
    table_state TEXT,
    status TEXT NOT NULL,
    verdict TEXT,
    updated_utc TEXT NOT NULL,
    state_json TEXT NOT NULL,
    PRIMARY KEY (run_id, host)
);
CREATE INDEX IF NOT EXISTS live_runs_updated ON live_runs (updated_utc);
