//! The `sodyn` binary: `info`, `random-state` + `eval` round trip (README schema), error exits,
//! and `bench --smoke`'s line format.

use nalgebra::{DMatrix, DVector};
use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Output};

fn sodyn(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sodyn"))
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("run the sodyn binary")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh path in the test scratch directory.
fn tmp(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cli-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{}-{name}", std::process::id()))
}

fn assert_ok(o: &Output, what: &str) {
    assert!(o.status.success(), "{what} failed: {}\n{}", stderr(o), stdout(o));
}

/// Exit code 1, a `sodyn: error:` message, no panic or backtrace.
fn assert_clean_failure(o: &Output, what: &str) -> String {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{what}: exit code; stderr: {err}");
    assert!(err.contains("error"), "{what}: {err}");
    assert!(!err.contains("panicked"), "{what} panicked: {err}");
    assert!(!err.contains("backtrace"), "{what} printed a backtrace: {err}");
    err
}

fn vector(v: &Value, key: &str, n: usize) -> DVector<f64> {
    let a = v[key].as_array().unwrap_or_else(|| panic!("key {key} is not a list"));
    assert_eq!(a.len(), n, "length of {key}");
    DVector::from_iterator(n, a.iter().map(|x| x.as_f64().expect("number")))
}

fn matrix(v: &Value, key: &str, n: usize) -> DMatrix<f64> {
    let rows = v[key].as_array().unwrap_or_else(|| panic!("key {key} is not a list"));
    assert_eq!(rows.len(), n, "rows of {key}");
    let mut m = DMatrix::zeros(n, n);
    for (i, r) in rows.iter().enumerate() {
        let r = r.as_array().unwrap_or_else(|| panic!("{key}[{i}] is not a list"));
        assert_eq!(r.len(), n, "columns of {key}[{i}]");
        for (j, x) in r.iter().enumerate() {
            m[(i, j)] = x.as_f64().expect("number");
        }
    }
    m
}

fn check_tensor_shape(v: &Value, key: &str, n: usize) {
    let t = v[key].as_array().unwrap_or_else(|| panic!("key {key} missing"));
    assert_eq!(t.len(), n, "{key} dim 0");
    for (i, m) in t.iter().enumerate() {
        let m = m.as_array().unwrap();
        assert_eq!(m.len(), n, "{key}[{i}] dim 1");
        for r in m {
            let r = r.as_array().unwrap();
            assert_eq!(r.len(), n, "{key}[{i}][..] dim 2");
            assert!(r.iter().all(|x| x.as_f64().is_some_and(f64::is_finite)), "{key} finite");
        }
    }
}

#[test]
fn info_on_builtin_model() {
    let o = sodyn(&["info", "--model", "builtin:quadruped"]);
    assert_ok(&o, "info");
    let out = stdout(&o);
    assert!(out.contains("nq = 19, nv = 18"), "{out}");
    assert!(out.contains("root_joint") && out.contains("free_flyer"), "{out}");
}

#[test]
fn random_state_eval_round_trip() {
    let state = tmp("state.json");
    let s = state.to_str().unwrap();
    let o = sodyn(&["random-state", "--model", "builtin:quadruped", "--seed", "3", "--output", s]);
    assert_ok(&o, "random-state");
    let st: Value = serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
    let (nq, nv) = (19, 18);
    let q = vector(&st, "q", nq);
    let (v, a, tau_in) = (vector(&st, "v", nv), vector(&st, "a", nv), vector(&st, "tau", nv));
    assert!((q.rows(3, 4).norm() - 1.0).abs() < 1e-12, "unit quaternion");
    assert!(v.iter().chain(a.iter()).all(|x| x.abs() <= 1.0));

    for order in ["1", "2"] {
        let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", s, "--order", order]);
        assert_ok(&o, "eval");
        let out: Value = serde_json::from_str(&stdout(&o)).expect("eval prints one JSON object");
        assert_eq!(out["model"], "quadruped");
        assert_eq!(out["nq"], nq);
        assert_eq!(out["nv"], nv);
        let g = vector(&out, "gravity", 6);
        assert_eq!(g.as_slice(), &[0.0, 0.0, 0.0, 0.0, 0.0, -9.81]);
        let joints = out["joints"].as_array().expect("joints");
        assert_eq!(joints.len(), 13);
        for key in ["name", "type", "parent", "idx_q", "nq", "idx_v", "nv"] {
            assert!(joints[0].get(key).is_some(), "joints[0].{key}");
        }
        let tau = vector(&out, "tau", nv);
        let b = vector(&out, "b", nv);
        let qdd = vector(&out, "qdd", nv);
        let m = matrix(&out, "M", nv);
        for key in ["dtau_dq", "dtau_dv", "dqdd_dq", "dqdd_dv"] {
            matrix(&out, key, nv);
        }
        let minv = matrix(&out, "Minv", nv);
        // Consistency: τ = M a + b, M q̈ + b = τ_in, M M⁻¹ = I.
        assert!((&m * &a + &b - &tau).amax() < 1e-9, "tau = M a + b");
        assert!((&m * &qdd + &b - &tau_in).amax() < 1e-9, "M qdd + b = tau");
        assert!((&m * &minv - DMatrix::identity(nv, nv)).amax() < 1e-9, "M Minv = I");
        let tensors = [
            "d2tau_dq2",
            "d2tau_dv2",
            "d2tau_dqdv",
            "dM_dq",
            "d2qdd_dq2",
            "d2qdd_dv2",
            "d2qdd_dqdv",
            "d2qdd_dtaudq",
        ];
        for key in tensors {
            if order == "2" {
                check_tensor_shape(&out, key, nv);
            } else {
                assert!(out.get(key).is_none(), "{key} only with --order 2");
            }
        }
    }
}

#[test]
fn wrong_length_state_key_is_an_error() {
    let state = tmp("short-v.json");
    std::fs::write(&state, r#"{"v": [0.1, 0.2, 0.3]}"#).unwrap();
    let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", state.to_str().unwrap()]);
    let err = assert_clean_failure(&o, "short v");
    assert!(err.contains("\"v\""), "names the key: {err}");
    assert!(err.contains("expected 18"), "names the expected length: {err}");
}

#[test]
fn unknown_model_is_an_error() {
    let o = sodyn(&["info", "--model", "builtin:no_such_robot"]);
    let err = assert_clean_failure(&o, "unknown built-in");
    assert!(err.contains("no_such_robot"), "{err}");
    let o = sodyn(&["info", "--model", "/nonexistent/robot.urdf"]);
    let err = assert_clean_failure(&o, "missing URDF");
    assert!(err.contains("robot.urdf"), "{err}");
}

#[test]
fn malformed_urdf_is_a_clean_error() {
    let path = tmp("broken_robot.urdf");
    std::fs::write(&path, "<robot name=\"r\">\n  <link name=\"a\">\n    <inertial>\n</robot>\n")
        .unwrap();
    for cmd in ["info", "random-state"] {
        let o = sodyn(&[cmd, "--model", path.to_str().unwrap()]);
        let err = assert_clean_failure(&o, "malformed URDF");
        assert!(err.contains("broken_robot.urdf"), "names the file: {err}");
    }
    let o = sodyn(&["bench", "--smoke", "--model", path.to_str().unwrap()]);
    let err = assert_clean_failure(&o, "bench on a malformed URDF");
    assert!(err.contains("broken_robot.urdf"), "names the file: {err}");
}

/// Parses `key=value` fields of a bench line, checking the fixed leading fields.
fn parse_bench_line(line: &str) -> Vec<(String, String)> {
    let fields: Vec<(String, String)> = line
        .split_whitespace()
        .map(|f| {
            let (k, v) = f.split_once('=').unwrap_or_else(|| panic!("field {f} in {line}"));
            (k.to_string(), v.to_string())
        })
        .collect();
    let keys: Vec<&str> = fields.iter().take(9).map(|(k, _)| k.as_str()).collect();
    assert_eq!(
        keys,
        ["model", "nq", "nv", "algo", "median_us", "p10_us", "p90_us", "batch", "samples"],
        "{line}"
    );
    for (k, v) in &fields[4..7] {
        let x: f64 = v.parse().unwrap_or_else(|_| panic!("{k}={v} in {line}"));
        assert!(x.is_finite() && x > 0.0, "{k}={v} in {line}");
    }
    for (k, v) in &fields[7..9] {
        let n: usize = v.parse().unwrap_or_else(|_| panic!("{k}={v} in {line}"));
        assert!(n >= 1, "{line}");
    }
    fields
}

#[test]
fn bench_smoke_prints_the_line_format() {
    let o = sodyn(&["bench", "--model", "builtin:quadruped", "--smoke", "--name", "quad"]);
    assert_ok(&o, "bench --smoke");
    let out = stdout(&o);
    let mut algos = vec![];
    for line in out.lines().filter(|l| !l.starts_with('#')) {
        let f = parse_bench_line(line);
        assert_eq!(f[0].1, "quad");
        assert_eq!(f[1].1, "19");
        assert_eq!(f[2].1, "18");
        algos.push(f[3].1.clone());
    }
    for a in ["rnea", "crba", "aba", "id_fo", "fd_fo", "id_so", "fd_so", "batch_id_fo"] {
        assert!(algos.iter().any(|x| x == a), "algo {a} missing from:\n{out}");
    }
}

#[test]
fn bench_options_are_validated() {
    let base = ["bench", "--model", "builtin:quadruped", "--smoke"];
    let with = |extra: &[&str]| sodyn(&[&base[..], extra].concat());

    let err = assert_clean_failure(&with(&["--algos", "rnea,warp_drive"]), "unknown algo");
    assert!(err.contains("warp_drive") && err.contains("id_so") && err.contains("fd_fo"), "{err}");

    let err = assert_clean_failure(&with(&["--algos", "kkt_fo"]), "contact algo without contacts");
    assert!(err.contains("kkt_fo") && err.contains("--contacts"), "{err}");

    let err = assert_clean_failure(&with(&["--contacts", "LF_FOOT,NO_SUCH_FOOT"]), "bad frame");
    assert!(err.contains("NO_SUCH_FOOT"), "{err}");

    // Valid contact frames are accepted (and recorded in the header line).
    let o = with(&["--contacts", "LF_FOOT,RF_FOOT,LH_FOOT,RH_FOOT", "--algos", "rnea,batch_id_fo"]);
    assert_ok(&o, "bench with contacts");
    let out = stdout(&o);
    assert!(out.contains("contacts=LF_FOOT,RF_FOOT,LH_FOOT,RH_FOOT"), "{out}");
    assert_eq!(out.lines().filter(|l| l.starts_with("model=")).count(), 2, "{out}");

    // The contact algorithms run with contacts.
    let o = with(&[
        "--contacts",
        "LF_FOOT,RF_FOOT,LH_FOOT,RH_FOOT",
        "--algos",
        "kkt_fo,kkt_so,impact_fo,impact_so",
    ]);
    assert_ok(&o, "bench contact algorithms");
    let out = stdout(&o);
    for a in ["kkt_fo", "kkt_so", "impact_fo", "impact_so"] {
        assert!(out.contains(&format!("algo={a} ")), "{a} missing:\n{out}");
    }

    // --paired-threads: two lines per batched algorithm (1 and T threads, the second with the
    // paired speed-up), one for the others.
    let o = with(&["--paired-threads", "2", "--algos", "rnea,batch_rnea"]);
    assert_ok(&o, "bench --paired-threads");
    let out = stdout(&o);
    assert!(out.contains("threads=1,2(paired)"), "{out}");
    let batch: Vec<&str> = out.lines().filter(|l| l.contains("algo=batch_rnea ")).collect();
    assert_eq!(batch.len(), 2, "{out}");
    assert!(batch[0].contains(" threads=1 ") && !batch[0].contains("speedup="), "{out}");
    assert!(batch[1].contains(" threads=2 ") && batch[1].contains(" speedup="), "{out}");
    assert_eq!(out.lines().filter(|l| l.contains("algo=rnea ")).count(), 1, "{out}");
    // Timed (not --smoke): the paired blocks and their speed-ups are measured and printed.
    // Timed (short) runs on 16 states.
    let timed = |extra: &[&str]| {
        let base =
            ["bench", "--model", "builtin:quadruped", "--states", "16", "--max-seconds", "0.01"];
        sodyn(&[&base[..], extra].concat())
    };
    let o = timed(&["--paired-threads", "2", "--algos", "batch_rnea"]);
    assert_ok(&o, "timed bench --paired-threads");
    let out = stdout(&o);
    let line = out.lines().find(|l| l.contains(" threads=2 ")).expect("2-thread line");
    let field = |k: &str| -> f64 {
        let v = line.split_whitespace().find_map(|w| w.strip_prefix(k)).expect(k);
        v.parse().unwrap_or_else(|_| panic!("{k}{v} in {line}"))
    };
    for k in ["speedup=", "speedup_first="] {
        let x = field(k);
        assert!(x.is_finite() && x > 0.0, "{k}{x} in {line}");
    }
    let block = field("block=");
    assert!((1.0..=16.0).contains(&block), "{line}");
    let err = assert_clean_failure(&with(&["--pin-cpus", "0,0"]), "repeated CPU");
    assert!(err.contains("--pin-cpus") && err.contains("repeated"), "{err}");
    let err = assert_clean_failure(
        &with(&["--pin-cpus", "0", "--paired-threads", "2"]),
        "fewer CPUs than threads",
    );
    assert!(err.contains("1 CPUs given for 2 threads"), "{err}");
    let err = assert_clean_failure(&with(&["--pin-cpus", "zero"]), "bad CPU list");
    assert!(err.contains("--pin-cpus") && err.contains("zero"), "{err}");
    let err = assert_clean_failure(&with(&["--pin-cpus", "5000"]), "CPU out of range");
    assert!(err.contains("CPU 5000"), "{err}");
    assert_clean_failure(&with(&["--paired-threads", "1"]), "one paired thread");

    // --ratio-to: each algorithm timed against a reference in alternating blocks, with the
    // median per-pair ratio and the reference's own times on the algorithm's line.
    let o = timed(&["--algos", "rnea,fd_so", "--ratio-to", "id_so"]);
    assert_ok(&o, "timed bench --ratio-to");
    let out = stdout(&o);
    let lines: Vec<&str> = out.lines().filter(|l| l.starts_with("model=")).collect();
    assert_eq!(lines.len(), 2, "{out}");
    for line in &lines {
        let f = parse_bench_line(line);
        let get = |k: &str| -> f64 {
            let (_, v) =
                f.iter().find(|(key, _)| key == k).unwrap_or_else(|| panic!("{k}: {line}"));
            v.parse().unwrap_or_else(|_| panic!("{k}={v} in {line}"))
        };
        assert!(line.contains(" ratio_to=id_so "), "{line}");
        for k in ["ratio", "ref_median_us", "ref_p10_us", "ref_p90_us"] {
            assert!(get(k).is_finite() && get(k) > 0.0, "{k} in {line}");
        }
        assert!(get("ratio_pairs") >= 10.0, "{line}");
        // The ratio is the median of per-pair ratios, so it lies within the spread of the two
        // sides' times.
        let (lo, hi) = (get("p10_us") / get("ref_p90_us"), get("p90_us") / get("ref_p10_us"));
        assert!(lo * 0.5 <= get("ratio") && get("ratio") <= hi * 2.0, "{line}");
    }
    assert!(lines[0].contains("algo=rnea ") && lines[1].contains("algo=fd_so "), "{out}");
    let err = assert_clean_failure(&with(&["--ratio-to", "warp"]), "unknown reference");
    assert!(err.contains("--ratio-to") && err.contains("warp"), "{err}");
    let err = assert_clean_failure(
        &with(&["--algos", "batch_rnea", "--ratio-to", "rnea"]),
        "batched algorithm against a reference",
    );
    assert!(err.contains("batch_rnea"), "{err}");
    let err = assert_clean_failure(
        &with(&["--algos", "id_so", "--ratio-to", "id_so"]),
        "reference against itself",
    );
    assert!(err.contains("id_so"), "{err}");
    let err =
        assert_clean_failure(&with(&["--algos", "rnea", "--ratio-to", "kkt_fo"]), "no contacts");
    assert!(err.contains("kkt_fo") && err.contains("--contacts"), "{err}");
    assert_clean_failure(&with(&["--threads", "0"]), "zero threads");
    assert_clean_failure(&with(&["--states", "many"]), "bad --states");
    assert_clean_failure(&sodyn(&["bench", "--smoke"]), "missing --model");
}
