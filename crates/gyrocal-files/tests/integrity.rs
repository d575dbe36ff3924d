//! The run directory's record of its files, checked: `verify`, `check_files`, the result
//! files written through the run directory, and whose fault an error is.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{meta, plan, run_step};

use std::fs;
use std::path::Path;

use gyrocal_files::rundir::{FileState, STEPS_CSV, WriteResult as _, check_files, verify};
use gyrocal_files::{RunDir, RunError, RunErrorKind, RunResults, Status};

fn complete_run(dir: &Path) -> RunDir {
    let mut rd = RunDir::create(dir, &plan(), meta()).unwrap();
    for step in 0..5 {
        run_step(&mut rd, step, true);
    }
    rd.finish(Status::Complete, None, 50.0).unwrap();
    rd
}

#[test]
fn an_emptied_steps_csv_of_a_run_that_is_not_complete_is_found() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    {
        let mut rd = RunDir::create(&dir, &plan(), meta()).unwrap();
        for step in 0..3 {
            run_step(&mut rd, step, true);
        }
        rd.finish(Status::Failed, Some("meter gone".into()), 30.0)
            .unwrap();
    }
    assert!(check_files(&dir, &[STEPS_CSV]).unwrap().is_empty());
    let steps = dir.join(STEPS_CSV);
    let header = fs::read_to_string(&steps)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    fs::write(&steps, format!("{header}\n")).unwrap();
    let d = check_files(&dir, &[STEPS_CSV]).unwrap();
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(
        d[0].text
            .contains("lacks 3 of the 3 steps manifest.json records as done (plan steps 1, 2, 3)"),
        "{}",
        d[0].text
    );
    // and verify says the run cannot be verified (it has no checksums yet)
    let v = verify(&dir).unwrap();
    assert!(!v.ok());
    assert!(
        v.problems[0].contains("not complete (status failed)"),
        "{:?}",
        v.problems
    );
}

#[test]
fn results_are_written_through_the_run_directory_and_verified() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    {
        let mut rd = complete_run(&dir);
        rd.write_result("allan.json", b"{}\n").unwrap();
        // not the data, the record or the fit
        for name in ["steps.csv", "manifest.json", "fit.json", ".x", "a/b"] {
            let e = rd.write_result(name, b"x").unwrap_err();
            assert_eq!(e.kind(), RunErrorKind::Internal, "{name}: {e}");
        }
    }
    assert!(!dir.join(".lock").exists());
    let v = verify(&dir).unwrap();
    assert!(v.ok(), "{v:?}");
    assert!(v.checks.iter().any(|c| c.file == "allan.json" && c.ok()));
    // a later writer, on the finished run: takes the lock, records, lets go
    {
        let mut r = RunResults::open(&dir).unwrap();
        // while it holds the lock nobody else writes the run
        assert!(matches!(
            RunResults::open(&dir),
            Err(RunError::Locked { .. })
        ));
        r.write_result("allan.html", b"<html></html>").unwrap();
        assert!(r.manifest().checksums.contains_key("allan.html"));
    }
    assert!(!dir.join(".lock").exists());
    assert!(verify(&dir).unwrap().ok());
    // an edited result fails
    fs::write(dir.join("allan.html"), "<html>edited</html>").unwrap();
    let v = verify(&dir).unwrap();
    let c = v.checks.iter().find(|c| c.file == "allan.html").unwrap();
    assert!(matches!(c.state, FileState::Changed { .. }), "{c:?}");
    assert!(!v.ok());
    // a result file nobody recorded fails too
    fs::write(dir.join("allan.html"), "<html></html>").unwrap();
    let mut m: serde_json::Value =
        serde_json::from_slice(&fs::read(dir.join("manifest.json")).unwrap()).unwrap();
    m["checksums"].as_object_mut().unwrap().remove("allan.json");
    fs::write(dir.join("manifest.json"), serde_json::to_vec(&m).unwrap()).unwrap();
    let v = verify(&dir).unwrap();
    let c = v.checks.iter().find(|c| c.file == "allan.json").unwrap();
    assert_eq!(c.state, FileState::NotRecorded);
    assert!(
        c.describe().contains("allan.json NOT RECORDED"),
        "{}",
        c.describe()
    );
}

#[test]
fn a_full_disk_is_the_environment_and_a_wrong_path_the_input() {
    let io = |raw: i32| RunError::Io {
        path: "/x/manifest.json".into(),
        action: "write",
        source: std::io::Error::from_raw_os_error(raw),
    };
    // ENOSPC, EDQUOT, EIO, EFBIG: the system failed
    for raw in [28, 122, 5, 27] {
        assert_eq!(io(raw).kind(), RunErrorKind::Environment, "errno {raw}");
    }
    // ENOENT, EACCES, EROFS, ENOTDIR: the path given is wrong
    for raw in [2, 13, 30, 20] {
        assert_eq!(io(raw).kind(), RunErrorKind::Input, "errno {raw}");
    }
    let tmp = tempfile::tempdir().unwrap();
    let e = verify(tmp.path()).unwrap_err();
    assert_eq!(e.kind(), RunErrorKind::Input);
}
