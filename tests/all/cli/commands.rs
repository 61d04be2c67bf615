//! The `sodyn` binary: `info`, `random-state` + `eval` round trip (README schema), error exits
//! (1 for errors found while running, 2 for clap's usage errors), the generated `--help` and the
//! README's copy of it, and `bench --smoke`'s line format.

use nalgebra::{DMatrix, DVector};
use serde_json::Value;
use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

fn sodyn(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sodyn"))
        .args(args)
        .env("RUST_BACKTRACE", "1")
        // The help is wrapped to the terminal's width, at most 100 columns.
        .env("COLUMNS", "100")
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
    assert!(!err.contains("::"), "{what}: the message names a Rust path: {err}");
    err
}

/// Exit code 2 and clap's usage error (the message, a pointer to `--help`), no panic.
fn assert_usage_error(o: &Output, what: &str) -> String {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{what}: exit code; stderr: {err}");
    assert!(err.starts_with("error: ") && err.contains("try '--help'"), "{what}: {err}");
    assert!(!err.contains("panicked"), "{what} panicked: {err}");
    assert!(!err.contains("::"), "{what}: the message names a Rust path: {err}");
    assert!(stdout(o).is_empty(), "{what}: {}", stdout(o));
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
        assert!(out.get("errors").is_none(), "no \"errors\" when every output is defined");
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

/// A mass matrix that is singular at the state (`tests/data/massless_subtree.urdf`: a massless
/// link whose child joint moves a massless link): `eval` writes every output that does not need
/// `M⁻¹` (the same values as for a regular model: τ = M a + b, contacts' `constrained_id`,
/// the contracted `id`), leaves out the others, names each in `"errors"` with the reason, and
/// exits with status 3; also with `-o FILE`.
#[test]
fn eval_writes_partial_results_when_the_mass_matrix_is_singular() {
    let urdf = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/massless_subtree.urdf");
    for (base, nv) in [(None, 3), (Some("--floating-base"), 9)] {
        // `sodyn` with the base option of this round.
        let run = |args: &[&str]| {
            let mut a = args.to_vec();
            a.extend(base);
            sodyn(&a)
        };
        let state = tmp(&format!("massless-{nv}.json"));
        let s = state.to_str().unwrap();
        let o = run(&["random-state", "--model", urdf, "--seed", "5", "-o", s]);
        assert_ok(&o, "random-state");
        let mut st: Value =
            serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
        let a = vector(&st, "a", nv);
        st["contacts"] = serde_json::json!([{"frame": "arm", "point": [0.0, 0.0, 0.3]}]);
        st["weights"] = serde_json::json!({
            "tau": vec![1.0; nv], "qdd": vec![1.0; nv], "kkt_qdd": vec![1.0; nv],
            "impact_vplus": vec![1.0; nv]
        });
        let contacts = tmp(&format!("massless-contacts-{nv}.json"));
        std::fs::write(&contacts, st.to_string()).unwrap();
        let c = contacts.to_str().unwrap();

        let defined = [
            "model",
            "nq",
            "nv",
            "gravity",
            "joints",
            "tau",
            "M",
            "b",
            "dtau_dq",
            "dtau_dv",
            "com",
            "centroidal",
        ];
        let fd = ["qdd", "dqdd_dq", "dqdd_dv", "Minv"];
        let so = ["d2tau_dq2", "d2tau_dv2", "d2tau_dqdv", "dM_dq"];
        let fd_so = ["d2qdd_dq2", "d2qdd_dv2", "d2qdd_dqdv", "d2qdd_dtaudq"];
        let cases: [(&str, &str, Vec<&str>, Vec<&str>); 3] = [
            (s, "1", defined.to_vec(), fd.to_vec()),
            (s, "2", [&defined[..], &so].concat(), [&fd[..], &fd_so].concat()),
            (
                c,
                "1",
                [&defined[..], &["constrained_id", "contracted"]].concat(),
                [
                    &fd[..],
                    &["kkt", "impact", "contracted.fd", "contracted.kkt", "contracted.impact"],
                ]
                .concat(),
            ),
        ];
        for (file, order, present, missing) in cases {
            let what = format!("eval {file} --order {order} {base:?}");
            let o = run(&["eval", "--model", urdf, "--state", file, "--order", order]);
            assert_eq!(o.status.code(), Some(3), "{what}: exit status; stderr: {}", stderr(&o));
            let out: Value = serde_json::from_str(&stdout(&o)).expect("one JSON object");
            let obj = out.as_object().unwrap();
            let mut keys: Vec<&str> = obj.keys().map(String::as_str).collect();
            let mut expected = present.clone();
            expected.push("errors");
            keys.sort_unstable();
            expected.sort_unstable();
            assert_eq!(keys, expected, "{what}: keys");
            let errors = out["errors"].as_object().expect("errors object");
            let mut err_keys: Vec<&str> = errors.keys().map(String::as_str).collect();
            let mut missing = missing.clone();
            err_keys.sort_unstable();
            missing.sort_unstable();
            assert_eq!(err_keys, missing, "{what}: errors keys");
            for (k, reason) in errors {
                let r = reason.as_str().expect("reason is a string");
                assert!(r.contains("singular") && r.contains("\"knuckle\""), "{what}: {k}: {r}");
            }
            if file == c {
                assert_eq!(
                    out["contracted"].as_object().unwrap().keys().collect::<Vec<_>>(),
                    ["id"]
                );
            }
            // The defined outputs are those of a regular evaluation: τ = M a + b.
            let (tau, m, b) =
                (vector(&out, "tau", nv), matrix(&out, "M", nv), vector(&out, "b", nv));
            assert!((&m * &a + &b - &tau).amax() < 1e-9, "{what}: tau = M a + b");
            let err = stderr(&o);
            assert!(
                err.starts_with("sodyn: error: ") && missing.iter().all(|k| err.contains(k)),
                "{what}: {err}"
            );
            assert!(!err.contains("panicked"), "{err}");
        }
        // -o FILE: the same object in the file, the same status.
        let out_file = tmp(&format!("massless-out-{nv}.json"));
        let of = out_file.to_str().unwrap();
        let o = run(&["eval", "--model", urdf, "--state", s, "-o", of]);
        assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
        assert!(stdout(&o).is_empty());
        let out: Value =
            serde_json::from_str(&std::fs::read_to_string(&out_file).unwrap()).unwrap();
        assert!(out["errors"]["qdd"].is_string() && out.get("qdd").is_none(), "{out}");
    }
    // Other failures keep status 1 (a state of the wrong length), a regular model has no
    // "errors" (random_state_eval_round_trip reads every key).
    let short = tmp("massless-short.json");
    std::fs::write(&short, "{\"v\": [0.0]}").unwrap();
    let o = sodyn(&["eval", "--model", urdf, "--state", short.to_str().unwrap()]);
    assert_clean_failure(&o, "wrong length");
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

/// The MJCF loader's tendon warning, in the command line's terms: what the model records, not
/// the library accessor's Rust path.
#[test]
fn mjcf_tendon_warning_names_no_rust_path() {
    let xml = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mjcf/tendons.xml");
    let o = sodyn(&["info", "--model", xml]);
    assert_ok(&o, "info on tendons.xml");
    let err = stderr(&o);
    assert!(
        err.contains("sodyn: warning: ")
            && err.contains(
                "<tendon>: 3 tendons (1 fixed, 2 spatial) are recorded (in the model's tendons)"
            ),
        "{err}"
    );
    assert!(!err.contains("::"), "{err}");
}

/// The URDF loader's warnings go to standard error (`sodyn: warning: FILE:LINE: ...`), the
/// command goes on and its output on standard output is untouched; `--strict-inertia` makes the
/// inertia warning an error (exit status 1).
#[test]
fn urdf_warnings_go_to_standard_error() {
    let triangle = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/urdf/triangle.urdf");
    let o = sodyn(&["info", "--model", triangle]);
    assert_ok(&o, "info on triangle.urdf");
    let err = stderr(&o);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(&format!("sodyn: warning: {triangle}:7: link \"shin\": "))
            && err.contains("triangle inequality"),
        "{err}"
    );
    assert!(stdout(&o).starts_with("model \"triangle\": nq = 1"), "{}", stdout(&o));
    assert!(!stdout(&o).contains("warning"), "{}", stdout(&o));
    // random-state: standard output is JSON only.
    let o = sodyn(&["random-state", "--model", triangle]);
    assert_ok(&o, "random-state on triangle.urdf");
    serde_json::from_str::<Value>(&stdout(&o)).expect("JSON on standard output");
    assert!(stderr(&o).contains("sodyn: warning: "), "{}", stderr(&o));
    for cmd in ["info", "random-state"] {
        let o = sodyn(&[cmd, "--model", triangle, "--strict-inertia"]);
        let err = assert_clean_failure(&o, "--strict-inertia");
        assert!(
            err.contains("triangle.urdf:7: link \"shin\"") && !err.contains("warning"),
            "{err}"
        );
    }
    // A clean model: nothing on standard error.
    let o = sodyn(&["info", "--model", "builtin:quadruped"]);
    assert_ok(&o, "info");
    assert!(stderr(&o).is_empty(), "{}", stderr(&o));
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

    // Two-frame constraints: A:B entries, and the model's own constraints.
    let o = with(&["--contacts", "LF_FOOT:RH_FOOT,RF_FOOT", "--algos", "kkt_fo,impact_so"]);
    assert_ok(&o, "bench with a loop");
    let out = stdout(&o);
    assert!(out.contains("contacts=LF_FOOT:RH_FOOT,RF_FOOT"), "{out}");
    assert!(out.contains("algo=kkt_fo ") && out.contains("algo=impact_so "), "{out}");
    for (arg, needle) in [
        ("LF_FOOT:NOPE", "NOPE"),
        ("LF_FOOT:RH_FOOT:RF_FOOT", "two frames"),
        ("LF_FOOT:LF_FOOT", "same body"),
    ] {
        let err = assert_clean_failure(&with(&["--contacts", arg, "--algos", "kkt_fo"]), arg);
        assert!(err.contains(needle) && err.contains("--contacts"), "{arg}: {err}");
    }
    let err = assert_clean_failure(&with(&["--model-constraints"]), "no model constraints");
    assert!(err.contains("--model-constraints") && err.contains("no constraints"), "{err}");
    let delta = ["bench", "--model", "builtin:delta", "--smoke", "--model-constraints"];
    let o = sodyn(&[&delta[..], &["--algos", "kkt_fo,kkt_so,impact_fo"]].concat());
    assert_ok(&o, "bench --model-constraints");
    let out = stdout(&o);
    assert!(out.contains("contacts=model(3)"), "{out}");
    assert_eq!(out.lines().filter(|l| l.starts_with("model=")).count(), 3, "{out}");

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
    let err = assert_usage_error(&with(&["--pin-cpus", "0,0"]), "repeated CPU");
    assert!(err.contains("--pin-cpus") && err.contains("repeated"), "{err}");
    let err = assert_clean_failure(
        &with(&["--pin-cpus", "0", "--paired-threads", "2"]),
        "fewer CPUs than threads",
    );
    assert!(err.contains("1 CPUs given for 2 threads"), "{err}");
    let err = assert_usage_error(&with(&["--pin-cpus", "zero"]), "bad CPU list");
    assert!(err.contains("--pin-cpus") && err.contains("zero"), "{err}");
    let err = assert_clean_failure(&with(&["--pin-cpus", "5000"]), "CPU out of range");
    assert!(err.contains("CPU 5000"), "{err}");
    assert_usage_error(&with(&["--paired-threads", "1"]), "one paired thread");

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
    let err = assert_usage_error(&with(&["--threads", "0"]), "zero threads");
    assert!(err.contains("--threads") && err.contains("at least 1"), "{err}");
    let err = assert_usage_error(&with(&["--states", "many"]), "bad --states");
    assert!(err.contains("--states") && err.contains("many"), "{err}");
    let err = assert_usage_error(&sodyn(&["bench", "--smoke"]), "missing --model");
    assert!(err.contains("--model"), "{err}");
    let err = assert_usage_error(
        &with(&["--paired-threads", "2", "--ratio-to", "id_so"]),
        "--ratio-to with --paired-threads",
    );
    assert!(err.contains("--ratio-to") && err.contains("--paired-threads"), "{err}");
    let err = assert_usage_error(&with(&["--pool", "threads"]), "unknown pool");
    assert!(err.contains("spin") && err.contains("rayon"), "{err}");
}

#[test]
fn every_command_has_a_generated_help() {
    let commands: [(&str, &[&str]); 5] = [
        (
            "demo",
            &[
                "--model <M>",
                "--seed <S>",
                "[default: builtin:humanoid]",
                "--floating-base",
                "--armature <A>",
                "--mimic",
                "--contacts <F1,F2,...>",
                "--contact-type <3d|6d>",
                "--contact-reference",
            ],
        ),
        ("info", &["--model <M>", "--floating-base"]),
        ("random-state", &["--model <M>", "--floating-base", "--seed <S>", "-o, --output <FILE>"]),
        (
            "eval",
            &["--model <M>", "--floating-base", "--state <FILE>", "--order <1|2>", "--output"],
        ),
        (
            "bench",
            &[
                "--model <M>",
                "--floating-base",
                "--contacts",
                "--algos",
                "--states <N>",
                "--seed <S>",
                "--max-seconds <X>",
                "--iters <N>",
                "--threads <N>",
                "--paired-threads <T>",
                "--pool",
                "--spin-us <U>",
                "--pin-cpus",
                "--name <NAME>",
                "--ratio-to <R>",
                "--smoke",
                "--calls <N>",
            ],
        ),
    ];
    for (cmd, options) in commands {
        for help in [vec![cmd, "--help"], vec![cmd, "-h"], vec!["help", cmd]] {
            let o = sodyn(&help);
            assert_ok(&o, &help.join(" "));
            let out = stdout(&o);
            assert!(out.contains(&format!("Usage: sodyn {cmd} ")), "{help:?}: {out}");
            for opt in options {
                assert!(out.contains(opt), "{help:?} does not list {opt}: {out}");
            }
        }
    }
    // Without a command: the help (every command listed), exit status 0.
    for args in [&[][..], &["--help"], &["help"]] {
        let o = sodyn(args);
        assert_ok(&o, "sodyn --help");
        let out = stdout(&o);
        for (cmd, _) in commands {
            assert!(out.contains(&format!("\n  {cmd} ")), "{args:?}: {cmd} missing: {out}");
        }
    }
}

#[test]
fn unknown_options_and_commands_are_usage_errors() {
    let state = tmp("neutral.json");
    std::fs::write(&state, "{}").unwrap();
    let s = state.to_str().unwrap();
    // `info` and `eval` used to ignore options of the other commands.
    for (args, bad) in [
        (&["info", "--model", "builtin:quadruped", "--seed", "3"][..], "--seed"),
        (&["info", "--model", "builtin:quadruped", "--state", s], "--state"),
        (&["eval", "--model", "builtin:quadruped", "--state", s, "--bogus"], "--bogus"),
        (&["random-state", "--model", "builtin:quadruped", "--order", "2"], "--order"),
        (&["demo", "--state", s], "--state"),
        (&["bench", "--model", "builtin:quadruped", "--smoke", "--output", "x"], "--output"),
    ] {
        let err = assert_usage_error(&sodyn(args), &args.join(" "));
        assert!(err.contains(&format!("unexpected argument '{bad}'")), "{args:?}: {err}");
    }
    let err = assert_usage_error(&sodyn(&["evaluate"]), "unknown command");
    assert!(err.contains("'evaluate'"), "{err}");
    let err =
        assert_usage_error(&sodyn(&["eval", "--model", "builtin:quadruped"]), "missing --state");
    assert!(err.contains("--state <FILE>"), "{err}");
    let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", s, "--order", "3"]);
    let err = assert_usage_error(&o, "--order 3");
    assert!(err.contains("--order"), "{err}");
    // A valid command line still works, options in any order.
    let o = sodyn(&["eval", "--state", s, "--order", "2", "--model", "builtin:pendulum2"]);
    assert_ok(&o, "eval");
}

/// A two-link URDF (one revolute joint, nq = 1; with --floating-base nq = 8).
const TWO_LINKS: &str = r#"<robot name="two_links">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="arm"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="elbow" type="revolute">
    <parent link="base"/><child link="arm"/><origin xyz="0 0 0.5"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="10"/>
  </joint>
</robot>
"#;

#[test]
fn q_of_the_other_base_hints_at_floating_base() {
    let urdf = tmp("two_links.urdf");
    std::fs::write(&urdf, TWO_LINKS).unwrap();
    let u = urdf.to_str().unwrap();
    let fixed = tmp("two_links_fixed.json");
    std::fs::write(&fixed, r#"{"q": [0.3]}"#).unwrap();
    let floating = tmp("two_links_ff.json");
    std::fs::write(&floating, r#"{"q": [0, 0, 0, 0, 0, 0, 1, 0.3]}"#).unwrap();
    let (f, ff) = (fixed.to_str().unwrap(), floating.to_str().unwrap());
    for (state, fb) in [(f, false), (ff, true)] {
        let mut args = vec!["eval", "--model", u, "--state", state];
        if fb {
            args.push("--floating-base");
        }
        let o = sodyn(&args);
        assert_ok(&o, &args.join(" "));
        let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
        // `model` is the URDF's robot name, not the file name.
        assert_eq!(out["model"], "two_links");
    }
    let o = sodyn(&["eval", "--model", u, "--state", ff]);
    let err = assert_clean_failure(&o, "free-flyer q without --floating-base");
    assert!(
        err.contains("has length 8, expected 1") && err.contains("add --floating-base"),
        "{err}"
    );
    let o = sodyn(&["eval", "--model", u, "--floating-base", "--state", f]);
    let err = assert_clean_failure(&o, "fixed-base q with --floating-base");
    assert!(
        err.contains("has length 1, expected 8") && err.contains("leave out --floating-base"),
        "{err}"
    );
    // Any other wrong length, or a built-in model (no --floating-base), gets no hint.
    let short = tmp("two_links_short.json");
    std::fs::write(&short, r#"{"q": [0.3, 0.1]}"#).unwrap();
    let o = sodyn(&["eval", "--model", u, "--state", short.to_str().unwrap()]);
    let err = assert_clean_failure(&o, "q of length 2");
    assert!(err.contains("has length 2, expected 1") && !err.contains("floating-base"), "{err}");
    let o = sodyn(&["eval", "--model", "builtin:chain1", "--state", ff]);
    let err = assert_clean_failure(&o, "built-in model");
    assert!(err.contains("has length 8, expected 1") && !err.contains("floating-base"), "{err}");
}

#[test]
fn model_is_the_robot_name_in_every_output() {
    let urdf = tmp("file_stem_is_not_the_name.urdf");
    std::fs::write(&urdf, TWO_LINKS).unwrap();
    let u = urdf.to_str().unwrap();
    let o = sodyn(&["info", "--model", u]);
    assert_ok(&o, "info");
    assert!(stdout(&o).starts_with("model \"two_links\": nq = 1"), "{}", stdout(&o));
    let o = sodyn(&["bench", "--model", u, "--smoke", "--algos", "rnea"]);
    assert_ok(&o, "bench");
    let out = stdout(&o);
    let lines: Vec<&str> = out.lines().collect();
    assert!(lines[0].starts_with("# model=two_links source="), "{out}");
    assert_eq!(parse_bench_line(lines[1])[0].1, "two_links", "{out}");
    let o = sodyn(&["bench", "--model", "builtin:chain3", "--smoke", "--algos", "rnea"]);
    assert_ok(&o, "bench on a built-in model");
    assert!(stdout(&o).contains("\nmodel=serial_chain3 "), "{}", stdout(&o));
    // --name still overrides it.
    let o = sodyn(&["bench", "--model", u, "--smoke", "--algos", "rnea", "--name", "arm"]);
    assert_ok(&o, "bench --name");
    assert!(stdout(&o).contains("\nmodel=arm nq=1 nv=1 algo=rnea "), "{}", stdout(&o));
}

/// The ```text blocks of the README's "Command line" section that start with `$ sodyn ...` are
/// that command's output, as printed.
#[test]
fn readme_shows_the_generated_help() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let start = readme.find("\n## Command line\n").expect("a Command line section");
    let section = &readme[start + 1..];
    let section = &section[..section.find("\n## ").unwrap_or(section.len())];
    let mut checked = 0;
    for block in section.split("```text\n").skip(1) {
        let block = &block[..block.find("```").expect("closed block")];
        let Some((command, expected)) = block.split_once('\n') else { continue };
        let Some(command) = command.strip_prefix("$ sodyn") else { continue };
        let args: Vec<&str> = command.split_whitespace().collect();
        let o = sodyn(&args);
        assert_ok(&o, command);
        assert_eq!(stdout(&o), expected, "README.md's copy of `sodyn{command}` is out of date");
        checked += 1;
    }
    assert!(checked >= 2, "README.md shows `sodyn --help` and `sodyn eval --help`");
}

/// `"weights"` in the state file: `eval` writes `"contracted"` with the dense key names, each
/// the contraction of the `--order 2` tensor of that key with its weight; a weight of the wrong
/// length is an error naming it.
#[test]
fn eval_writes_contracted_second_order_for_the_weights_given() {
    let nv = 18; // builtin:quadruped
    let feet = r#"[{"frame": "LF_FOOT"}, {"frame": "RH_FOOT", "point": [0.01, 0, 0]}]"#;
    let w = |n: usize, s: f64| {
        let v: Vec<String> =
            (0..n).map(|i| format!("{}", s * (i as f64 + 1.0) / n as f64)).collect();
        format!("[{}]", v.join(", "))
    };
    let state = tmp("weights.json");
    let body = format!(
        r#"{{"v": {v}, "a": {a}, "tau": {t}, "contacts": {feet}, "restitution": 0.3,
            "weights": {{"tau": {w1}, "qdd": {w2}, "kkt_qdd": {w3}, "kkt_lambda": {w4},
                         "impact_vplus": {w5}, "impact_impulse": {w6}}}}}"#,
        v = w(nv, 0.3),
        a = w(nv, -0.2),
        t = w(nv, 0.5),
        w1 = w(nv, 1.0),
        w2 = w(nv, -1.0),
        w3 = w(nv, 0.7),
        w4 = w(6, 0.4),
        w5 = w(nv, -0.6),
        w6 = w(6, 0.9),
    );
    std::fs::write(&state, &body).unwrap();
    let st = state.to_str().unwrap();
    let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", st, "--order", "2"]);
    assert_ok(&o, "eval with weights");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let weights: Value = serde_json::from_str(&body).unwrap();
    let c = &out["contracted"];
    let check = |obj: &Value, key: &str, tensor: &Value, weight: &Value| {
        let t = tensor.as_array().unwrap();
        let w: Vec<f64> = weight.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        let got = obj[key].as_array().unwrap_or_else(|| panic!("contracted key {key}"));
        let (n2, n3) = (got.len(), got[0].as_array().unwrap().len());
        let mut err: f64 = 0.0;
        let mut scale: f64 = 1.0;
        for j in 0..n2 {
            for k in 0..n3 {
                let r: f64 = (0..t.len()).map(|i| w[i] * t[i][j][k].as_f64().unwrap()).sum();
                err = err.max((got[j][k].as_f64().unwrap() - r).abs());
                scale = scale.max(r.abs());
            }
        }
        assert!(err / scale < 1e-10, "{key}: relative error {}", err / scale);
    };
    let wt = &weights["weights"];
    for k in ["d2tau_dq2", "d2tau_dv2", "d2tau_dqdv", "dM_dq"] {
        check(&c["id"], k, &out[k], &wt["tau"]);
    }
    for k in ["d2qdd_dq2", "d2qdd_dv2", "d2qdd_dqdv", "d2qdd_dtaudq"] {
        check(&c["fd"], k, &out[k], &wt["qdd"]);
        check(&c["kkt"], k, &out["kkt"][k], &wt["kkt_qdd"]);
    }
    for k in ["d2lambda_dq2", "d2lambda_dv2", "d2lambda_dqdv", "d2lambda_dtaudq"] {
        check(&c["kkt"], k, &out["kkt"][k], &wt["kkt_lambda"]);
    }
    for k in ["d2vplus_dq2", "d2vplus_dqdvminus"] {
        check(&c["impact"], k, &out["impact"][k], &wt["impact_vplus"]);
    }
    for k in ["d2impulse_dq2", "d2impulse_dqdvminus"] {
        check(&c["impact"], k, &out["impact"][k], &wt["impact_impulse"]);
    }
    // Only the weights given; order 1 writes them too.
    std::fs::write(&state, format!(r#"{{"weights": {{"qdd": {}}}}}"#, w(nv, 1.0))).unwrap();
    let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", st]);
    assert_ok(&o, "eval with one weight");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let keys: Vec<&String> = out["contracted"].as_object().unwrap().keys().collect();
    assert_eq!(keys, ["fd"]);
    // Errors: wrong length, unknown key, contact weights without contacts.
    for (body, needle) in [
        (format!(r#"{{"weights": {{"tau": {}}}}}"#, w(3, 1.0)), "weights.tau\" has length 3"),
        (r#"{"weights": {"torque": [1]}}"#.to_string(), "unknown key \"weights.torque\""),
        (format!(r#"{{"weights": {{"kkt_qdd": {}}}}}"#, w(nv, 1.0)), "need \"contacts\""),
    ] {
        std::fs::write(&state, body).unwrap();
        let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", st]);
        let err = assert_clean_failure(&o, "bad weights");
        assert!(err.contains(needle), "{err}");
    }
}

/// `demo` on a model whose mass matrix is singular (`tests/data/massless_subtree.urdf`) stops at
/// the first algorithm that needs `M⁻¹` with the library's error (exit 1), not a panic of its
/// timing loop.
#[test]
fn demo_on_a_singular_mass_matrix_is_a_clean_error() {
    let urdf = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/massless_subtree.urdf");
    let o = sodyn(&["demo", "--model", urdf]);
    let err = assert_clean_failure(&o, "demo on a singular model");
    assert!(err.contains("mass matrix is singular") && err.contains("\"knuckle\""), "{err}");
}

#[test]
fn eval_takes_baumgarte_gains_per_contact() {
    use sodyn::algo::{Contact, Data};
    use sodyn::deriv::{ContactData, kkt_derivatives};
    let m = sodyn::model::builtin::quadruped();
    let nv = m.nv();
    let vals = |s: f64| -> Vec<f64> { (0..nv).map(|i| s * (i as f64 + 1.0) / nv as f64).collect() };
    let (v, tau) = (vals(0.4), vals(0.5));
    let run = |feet: &str, name: &str| {
        let state = tmp(name);
        let body = format!(r#"{{"v": {v:?}, "tau": {tau:?}, "contacts": {feet}}}"#);
        std::fs::write(&state, body).unwrap();
        sodyn(&["eval", "--model", "builtin:quadruped", "--state", state.to_str().unwrap()])
    };
    let o = run(r#"[{"frame": "LF_FOOT", "kp": 30, "kd": 4}, {"frame": "RH_FOOT"}]"#, "gains.json");
    assert_ok(&o, "eval with gains");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    // The library with the same contacts gives the same KKT results.
    let contacts = vec![
        Contact::new(&m, "LF_FOOT", nalgebra::Vector3::zeros())
            .unwrap()
            .with_baumgarte(30.0, 4.0)
            .unwrap(),
        Contact::new(&m, "RH_FOOT", nalgebra::Vector3::zeros()).unwrap(),
    ];
    let mut cd = ContactData::new(&m, &contacts).unwrap();
    let (q, v, tau) = (m.neutral(), DVector::from_vec(v.clone()), DVector::from_vec(tau.clone()));
    let kd = kkt_derivatives(&m, &mut Data::new(&m), &mut cd, &q, &v, &tau).unwrap();
    let qdd = vector(&out["kkt"], "qdd", nv);
    assert!((&qdd - kd.qdd()).amax() < 1e-12 * (1.0 + kd.qdd().amax()));
    let dq = matrix(&out["kkt"], "dqdd_dq", nv);
    assert!((&dq - kd.dqdd_dq()).amax() < 1e-12 * (1.0 + kd.dqdd_dq().amax()));
    // A bad gain names the contact and the key.
    let o = run(r#"[{"frame": "LF_FOOT", "kp": -1}]"#, "bad_gain.json");
    let e = assert_clean_failure(&o, "negative gain");
    assert!(e.contains("contacts[0].kp"), "{e}");
}

#[test]
fn eval_takes_6d_and_local_contacts() {
    use sodyn::algo::{Contact, ContactReference, ContactType, Data};
    use sodyn::deriv::{ContactData, impact_derivatives, kkt_derivatives};
    use sodyn::spatial::Transform;
    let m = sodyn::model::builtin::quadruped();
    let nv = m.nv();
    let vals = |s: f64| -> Vec<f64> { (0..nv).map(|i| s * (i as f64 + 1.0) / nv as f64).collect() };
    let (v, tau) = (vals(0.4), vals(0.5));
    let run = |feet: &str, extra: &str, name: &str| {
        let state = tmp(name);
        let body = format!(r#"{{"v": {v:?}, "tau": {tau:?}, "contacts": {feet}{extra}}}"#);
        std::fs::write(&state, body).unwrap();
        sodyn(&["eval", "--model", "builtin:quadruped", "--state", state.to_str().unwrap()])
    };
    let feet = r#"[{"frame": "LF_FOOT", "type": "6d", "reference": "local",
        "placement": {"xyz": [0.01, 0, -0.02], "rpy": [0.1, -0.2, 0.3]}, "kd": 2},
        {"frame": "RH_FOOT", "reference": "local", "point": [0, 0.01, 0]}]"#;
    let lambda: Vec<f64> = (0..9).map(|i| i as f64 - 4.0).collect();
    let o = run(feet, &format!(r#", "lambda": {lambda:?}, "restitution": 0.2"#), "c6d.json");
    assert_ok(&o, "eval with 6-D and local contacts");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    // The library with the same contacts gives the same results.
    let lf = Contact::new(&m, "LF_FOOT", nalgebra::Vector3::zeros())
        .unwrap()
        .with_placement(&m, &Transform::from_rpy_xyz([0.1, -0.2, 0.3], [0.01, 0.0, -0.02]))
        .unwrap()
        .with_reference(ContactReference::Local)
        .with_baumgarte(0.0, 2.0)
        .unwrap();
    let contacts = vec![
        Contact { kind: ContactType::D6, ..lf },
        Contact::new(&m, "RH_FOOT", nalgebra::Vector3::new(0.0, 0.01, 0.0))
            .unwrap()
            .with_reference(ContactReference::Local),
    ];
    let mut cd = ContactData::new(&m, &contacts).unwrap();
    let (q, v, tau) = (m.neutral(), DVector::from_vec(v.clone()), DVector::from_vec(tau.clone()));
    let mut d = Data::new(&m);
    let kd = kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
    let close = |a: &DMatrix<f64>, b: &DMatrix<f64>| (a - b).amax() < 1e-12 * (1.0 + b.amax());
    let lam = vector(&out["kkt"], "lambda", 9);
    assert!((&lam - kd.lambda()).amax() < 1e-12 * (1.0 + kd.lambda().amax()));
    let dl = DMatrix::from_fn(9, nv, |i, j| out["kkt"]["dlambda_dq"][i][j].as_f64().unwrap());
    assert!(close(&dl, kd.dlambda_dq()));
    cd.set_restitution(0.2).unwrap();
    let im = impact_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap();
    let imp = vector(&out["impact"], "impulse", 9);
    assert!((&imp - im.impulse()).amax() < 1e-12 * (1.0 + im.impulse().amax()));
    assert_eq!(out["constrained_id"]["tau"].as_array().unwrap().len(), nv);
    // Bad input names the contact, the key and the allowed values.
    for (feet, extra, needles) in [
        (r#"[{"frame": "LF_FOOT", "type": "4d"}]"#, "", vec!["contacts[0]", "\"3d\"", "\"6d\""]),
        (r#"[{"frame": "LF_FOOT", "reference": "world"}]"#, "", vec!["contacts[0]", "\"local\""]),
        (
            r#"[{"frame": "LF_FOOT", "point": [0, 0, 0], "placement": {}}]"#,
            "",
            vec!["contacts[0]", "both"],
        ),
        (
            r#"[{"frame": "LF_FOOT", "placement": {"xyz": [0, 0]}}]"#,
            "",
            vec!["contacts[0].placement.xyz"],
        ),
        (
            r#"[{"frame": "LF_FOOT", "placement": {"rot": [0, 0, 0]}}]"#,
            "",
            vec!["contacts[0].placement.rot"],
        ),
        (r#"[{"frame": "LF_FOOT", "typo": 1}]"#, "", vec!["contacts[0].typo"]),
        (
            r#"[{"frame": "LF_FOOT", "type": "6d"}]"#,
            r#", "lambda": [1, 2, 3]"#,
            vec!["lambda", "6"],
        ),
        (
            r#"[{"frame": "LF_FOOT", "type": "6d"}, {"frame": "LF_FOOT"}]"#,
            "",
            vec!["contacts[0]", "contacts[1]", "redundant"],
        ),
    ] {
        let o = run(feet, extra, "bad_c6d.json");
        let e = assert_clean_failure(&o, feet);
        assert!(needles.iter().all(|n| e.contains(n)), "{feet}: {e}");
    }
}

#[test]
fn eval_writes_frames_com_and_centroidal() {
    use sodyn::algo::{Data, ReferenceFrame, center_of_mass_motion, frame_jacobian};
    let m = sodyn::model::builtin::quadruped();
    let nv = m.nv();
    let vals = |s: f64| -> Vec<f64> { (0..nv).map(|i| s * (i as f64 + 1.0) / nv as f64).collect() };
    let (v, a) = (vals(0.4), vals(-0.3));
    let state = tmp("frames.json");
    std::fs::write(
        &state,
        format!(r#"{{"v": {v:?}, "a": {a:?}, "frames": ["LF_FOOT", "trunk"]}}"#),
    )
    .unwrap();
    let st = state.to_str().unwrap();
    let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", st, "--order", "2"]);
    assert_ok(&o, "eval with frames");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let f = &out["frames"]["LF_FOOT"];
    for key in [
        "placement",
        "jacobian",
        "velocity",
        "acceleration",
        "classical_acceleration",
        "dvelocity_dq",
        "dvelocity_dv",
        "dacceleration_dq",
        "dacceleration_dv",
        "dacceleration_da",
        "djacobian_dq",
    ] {
        assert!(!f[key].is_null(), "frames.LF_FOOT.{key} missing");
    }
    assert!(!out["frames"]["trunk"].is_null());
    // The world Jacobian is the library's.
    let mut d = Data::new(&m);
    let mut jac = nalgebra::Matrix6xX::zeros(nv);
    let fid = m.frame_id("LF_FOOT").unwrap();
    frame_jacobian(&m, &mut d, &m.neutral(), fid, ReferenceFrame::World, &mut jac).unwrap();
    let rows = f["jacobian"]["world"].as_array().unwrap();
    assert_eq!(rows.len(), 6);
    let got = DMatrix::from_fn(6, nv, |i, j| rows[i][j].as_f64().unwrap());
    assert!((got - DMatrix::from_column_slice(6, nv, jac.as_slice())).amax() < 1e-12);
    let (vv, av) = (DVector::from_vec(v.clone()), DVector::from_vec(a.clone()));
    let (c, _, ac) = center_of_mass_motion(&m, &mut d, &m.neutral(), &vv, Some(&av)).unwrap();
    let com = vector(&out["com"], "position", 3);
    assert!((com - c).amax() < 1e-12);
    assert!((vector(&out["com"], "acceleration", 3) - ac).amax() < 1e-12);
    assert_eq!(out["centroidal"]["Ag"].as_array().unwrap().len(), 6);
    // An unknown frame is an error naming it.
    std::fs::write(&state, r#"{"frames": ["no_such_link"]}"#).unwrap();
    let o = sodyn(&["eval", "--model", "builtin:quadruped", "--state", st]);
    let e = assert_clean_failure(&o, "unknown frame");
    assert!(e.contains("frames[0]") && e.contains("no_such_link"), "{e}");
}

/// `--model file.xml` loads MJCF: `info` prints MuJoCo's joints in order, the loader's warning
/// goes to standard error, `eval` runs, and MJCF errors exit cleanly naming the file and line.
#[test]
fn mjcf_models_load_by_extension() {
    let xml = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mjcf/features.xml");
    let o = sodyn(&["info", "--model", xml]);
    assert_ok(&o, "info on an MJCF file");
    let out = stdout(&o);
    assert!(
        out.starts_with(
            "model \"features\": nq = 22, nv = 20, njoints = 14 (the world joint 0 included"
        ),
        "{out}"
    );
    assert!(out.contains("root") && out.contains("free_flyer") && out.contains("neck"), "{out}");
    assert!(stderr(&o).contains("sodyn: warning:") && stderr(&o).contains("armature"));
    let s = tmp("mjcf-state.json");
    let s = s.to_str().unwrap();
    assert_ok(&sodyn(&["random-state", "--model", xml, "--seed", "2", "-o", s]), "random-state");
    let o = sodyn(&["eval", "--model", xml, "--state", s]);
    assert_ok(&o, "eval on an MJCF file");
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(vector(&v, "tau", 20).len(), 20);
    // --floating-base on the only body of radian.xml.
    let radian = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mjcf/radian.xml");
    let o = sodyn(&["info", "--model", radian, "--floating-base"]);
    assert_ok(&o, "info --floating-base on MJCF");
    assert!(stdout(&o).contains("root_joint"));
    let o = sodyn(&["info", "--model", radian, "--strict-inertia"]);
    let err = assert_clean_failure(&o, "--strict-inertia on MJCF");
    assert!(err.contains("`--strict-inertia`: applies to URDF files"), "{err}");
    let bad = tmp("bad.xml");
    std::fs::write(
        &bad,
        "<mujoco>\n<worldbody>\n<body><joint type=\"x\"/></body>\n</worldbody>\n</mujoco>",
    )
    .unwrap();
    let err = assert_clean_failure(&sodyn(&["info", "--model", bad.to_str().unwrap()]), "bad MJCF");
    assert!(err.contains("bad.xml:3") && err.contains("unknown joint type \"x\""), "{err}");
}

/// `--armature`: one value for every DoF or nv values; `info` lists it; `eval`'s M, tau and
/// qdd include it (against the library with `Model::with_armature`); bad values are clean
/// errors.
#[test]
fn armature_option() {
    let o = sodyn(&["info", "--model", "builtin:chain3", "--armature", "0.25"]);
    assert_ok(&o, "info --armature");
    assert!(stdout(&o).contains("armature (per velocity coordinate): [0.25, 0.25, 0.25]"));
    let o = sodyn(&["info", "--model", "builtin:chain3"]);
    assert!(!stdout(&o).contains("armature"), "no armature line without one");
    let st = tmp("armature-state.json");
    let st = st.to_str().unwrap();
    assert_ok(
        &sodyn(&["random-state", "--model", "builtin:chain3", "--seed", "4", "-o", st]),
        "random-state",
    );
    let o = sodyn(&["eval", "--model", "builtin:chain3", "--armature", "0.1,0,0.3", "--state", st]);
    assert_ok(&o, "eval --armature");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let state: Value = serde_json::from_str(&std::fs::read_to_string(st).unwrap()).unwrap();
    let m = sodyn::model::builtin::serial_chain(3).with_armature(&[0.1, 0.0, 0.3]).unwrap();
    let (q, v, a, tau) = (
        vector(&state, "q", 3),
        vector(&state, "v", 3),
        vector(&state, "a", 3),
        vector(&state, "tau", 3),
    );
    let mut d = sodyn::algo::Data::new(&m);
    let mm = sodyn::algo::crba(&m, &mut d, &q).unwrap().clone();
    assert!((matrix(&out, "M", 3) - mm).amax() < 1e-12);
    let t = sodyn::algo::rnea(&m, &mut d, &q, &v, &a, None).unwrap().clone();
    assert!((vector(&out, "tau", 3) - t).amax() < 1e-12);
    let qdd = sodyn::algo::aba(&m, &mut d, &q, &v, &tau, None).unwrap().clone();
    assert!((vector(&out, "qdd", 3) - qdd).amax() < 1e-12);
    let o = sodyn(&["info", "--model", "builtin:chain3", "--armature", "0.1,0.2"]);
    let e = assert_clean_failure(&o, "--armature with 2 values");
    assert!(e.contains("2 values") && e.contains("nv = 3"), "{e}");
    let o = sodyn(&["info", "--model", "builtin:chain3", "--armature", "0.1,-2,0"]);
    let e = assert_clean_failure(&o, "--armature negative");
    assert!(e.contains("joint \"joint_2\"") && e.contains("-2"), "{e}");
    let o = sodyn(&["info", "--model", "builtin:chain3", "--armature", "x"]);
    let e = assert_clean_failure(&o, "--armature not a number");
    assert!(e.contains("\"x\" is not a number"), "{e}");
}

/// `--mimic`: info, random-state and eval in the reduced coordinates, the outputs equal to the
/// library's on the reduced `Model`; unsupported inputs are clean errors.
#[test]
fn mimic_commands_use_the_reduced_coordinates() {
    use sodyn::algo::{self, Data};
    use sodyn::deriv::{self, ContactData};
    let urdf = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf");
    let u = urdf.to_str().unwrap();
    let o = sodyn(&["info", "--model", u, "--mimic", "--floating-base"]);
    assert_ok(&o, "info --mimic");
    let out = stdout(&o);
    assert!(out.contains("nq = 14, nv = 13 (reduced coordinates; full tree nq = 17, nv = 16)"));
    assert!(out.contains("q = -1 * q[\"finger_l_joint\"] + 0.01"), "{out}");
    let plain = stdout(&sodyn(&["info", "--model", u]));
    assert!(plain.contains("mimics \"finger_l_joint\" (independent without --mimic)"), "{plain}");
    let st = tmp("mimic-state.json");
    let s = st.to_str().unwrap();
    let o = sodyn(&["random-state", "--model", u, "--mimic", "--floating-base", "-o", s]);
    assert_ok(&o, "random-state --mimic");
    let o =
        sodyn(&["eval", "--model", u, "--mimic", "--floating-base", "--state", s, "--order", "2"]);
    assert_ok(&o, "eval --mimic");
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let (nq, nv) = (14, 13);
    assert_eq!((v["nq"].as_u64(), v["nv"].as_u64()), (Some(nq), Some(nv)));
    let state: Value = serde_json::from_str(&std::fs::read_to_string(&st).unwrap()).unwrap();
    let (q, vel) = (vector(&state, "q", nq as usize), vector(&state, "v", nv as usize));
    let (a, tau) = (vector(&state, "a", nv as usize), vector(&state, "tau", nv as usize));
    let opts = sodyn::model::UrdfOptions { floating_base: true, mimic: true, ..Default::default() };
    let m = sodyn::model::load_urdf_file(&urdf, &opts).unwrap();
    assert!(m.is_reduced());
    let mut d = Data::with_second_order(&m);
    let n = nv as usize;
    let t = algo::rnea(&m, &mut d, &q, &vel, &a, None).unwrap().clone();
    assert!((vector(&v, "tau", n) - t).amax() < 1e-12);
    deriv::fd_so_derivatives(&m, &mut d, &q, &vel, &tau, None).unwrap();
    assert!((vector(&v, "qdd", n) - d.qdd()).amax() < 1e-12);
    assert!((matrix(&v, "dqdd_dq", n) - d.dqdd_dq()).amax() < 1e-12);
    assert!((matrix(&v, "Minv", n) - d.minv()).amax() < 1e-12);
    for k in ["d2tau_dq2", "d2tau_dv2", "d2tau_dqdv", "dM_dq", "d2qdd_dq2", "d2qdd_dtaudq"] {
        check_tensor_shape(&v, k, n);
    }
    let joints = v["joints"].as_array().unwrap();
    let fr = joints.iter().find(|j| j["name"] == "finger_r_joint").unwrap();
    assert_eq!(fr["mimic"]["joint"], "finger_l_joint");
    assert_eq!(fr["nv"], 0);
    // Contacts: constrained ID, KKT and impact (order 2 here), as the library.
    let with_contacts = tmp("mimic-contacts.json");
    let mut st_c = state.clone();
    st_c["contacts"] = serde_json::json!([{"frame": "tool"}, {"frame": "thumb_tip", "type": "6d"}]);
    st_c["restitution"] = serde_json::json!(0.3);
    st_c["weights"] = serde_json::json!({
        "qdd": vec![0.5; 13],
        "kkt_qdd": vec![0.5; 13],
        "kkt_lambda": vec![0.25; 9],
        "impact_vplus": vec![-0.5; 13],
        "impact_impulse": vec![0.75; 9],
    });
    std::fs::write(&with_contacts, st_c.to_string()).unwrap();
    let wc = with_contacts.to_str().unwrap();
    let o =
        sodyn(&["eval", "--model", u, "--mimic", "--floating-base", "--state", wc, "--order", "2"]);
    assert_ok(&o, "eval --mimic with contacts");
    let v2: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let full = m.full_tree();
    let contacts = vec![
        sodyn::model::Contact::new(full, "tool", nalgebra::Vector3::zeros()).unwrap(),
        sodyn::model::Contact::new_6d(full, "thumb_tip", None).unwrap(),
    ];
    let mut cd = ContactData::with_second_order(&m, &contacts).unwrap();
    let kd = deriv::kkt_so_derivatives(&m, &mut d, &mut cd, &q, &vel, &tau).unwrap();
    assert!((matrix(&v2["kkt"], "dqdd_dq", n) - kd.dqdd_dq()).amax() < 1e-12);
    check_tensor_shape(&v2["kkt"], "d2qdd_dq2", n);
    let mut cd = ContactData::new(&m, &contacts).unwrap();
    cd.set_restitution(0.3).unwrap();
    let im = deriv::impact_derivatives(&m, &mut d, &mut cd, &q, &vel).unwrap();
    assert!((vector(&v2["impact"], "vplus", n) - im.vplus()).amax() < 1e-12);
    check_tensor_shape(&v2["impact"], "d2vplus_dq2", n);
    check_tensor_shape(&v2["constrained_id"], "d2tau_dq2", n);
    let cc = deriv::fd_so_contracted(&m, &mut d, &q, &vel, &tau, &DVector::from_element(n, 0.5))
        .unwrap();
    assert!((matrix(&v2["contracted"]["fd"], "d2qdd_dq2", n) - cc.c_qq()).amax() < 1e-12);
    // The contracted KKT and impact second order, one weight at a time, as the library.
    let (wn, w9) = (|x: f64| DVector::from_element(n, x), |x: f64| DVector::from_element(9, x));
    let mut cd = ContactData::with_contracted(&m, &contacts).unwrap();
    let kc =
        deriv::kkt_so_contracted(&m, &mut d, &mut cd, &q, &vel, &tau, &wn(0.0), &w9(0.25)).unwrap();
    let ck = &v2["contracted"]["kkt"];
    assert!((matrix(ck, "d2lambda_dq2", n) - kc.c_qq()).amax() < 1e-12);
    assert!((matrix(ck, "d2lambda_dtaudq", n) - kc.c_tauq()).amax() < 1e-12);
    let kc =
        deriv::kkt_so_contracted(&m, &mut d, &mut cd, &q, &vel, &tau, &wn(0.5), &w9(0.0)).unwrap();
    assert!((matrix(ck, "d2qdd_dv2", n) - kc.c_vv()).amax() < 1e-12);
    let mut cd = ContactData::with_contracted(&m, &contacts).unwrap();
    cd.set_restitution(0.3).unwrap();
    let ic =
        deriv::impact_so_contracted(&m, &mut d, &mut cd, &q, &vel, &wn(-0.5), &w9(0.0)).unwrap();
    let ci = &v2["contracted"]["impact"];
    assert!((matrix(ci, "d2vplus_dq2", n) - ic.c_qq()).amax() < 1e-12);
    let ic =
        deriv::impact_so_contracted(&m, &mut d, &mut cd, &q, &vel, &wn(0.0), &w9(0.75)).unwrap();
    assert!((matrix(ci, "d2impulse_dqdvminus", n) - ic.c_qvminus()).amax() < 1e-12);
    // Frames (of the full tree), in the reduced coordinates, as the library.
    let with_frames = tmp("mimic-frames.json");
    let mut st_f = state.clone();
    st_f["frames"] = serde_json::json!(["tool", "finger_r"]);
    std::fs::write(&with_frames, st_f.to_string()).unwrap();
    let wf = with_frames.to_str().unwrap();
    let o =
        sodyn(&["eval", "--model", u, "--mimic", "--floating-base", "--state", wf, "--order", "2"]);
    assert_ok(&o, "eval --mimic with frames");
    let v3: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let rf = sodyn::algo::ReferenceFrame::World;
    let f = m.frame_id("finger_r").unwrap();
    let (mut x, mut y, mut w) = (
        nalgebra::Matrix6xX::zeros(n),
        nalgebra::Matrix6xX::zeros(n),
        nalgebra::Matrix6xX::zeros(n),
    );
    algo::frame_acceleration_derivatives(&m, &mut d, &q, &vel, &a, f, rf, &mut x, &mut y, &mut w)
        .unwrap();
    let got = &v3["frames"]["finger_r"]["dacceleration_dq"]["world"];
    for r in 0..6 {
        for c in 0..n {
            assert!((got[r][c].as_f64().unwrap() - x[(r, c)]).abs() < 1e-12);
        }
    }
    assert_eq!(v3["frames"]["tool"]["jacobian"]["local"].as_array().unwrap().len(), 6);
    let cen = algo::centroidal_dynamics_derivatives(&m, &mut d, &q, &vel, &a).unwrap().clone();
    let got = &v3["centroidal"]["dhdot_dq"];
    for r in 0..6 {
        for c in 0..n {
            assert!((got[r][c].as_f64().unwrap() - cen.dhdot_dq()[(r, c)]).abs() < 1e-12);
        }
    }
    assert_eq!(v3["com"]["jacobian"].as_array().unwrap().len(), 3);
    let mut t = sodyn::tensor::Tensor3::zeros(6, n, n);
    algo::frame_jacobian_derivative(&m, &mut d, &q, f, rf, &mut t).unwrap();
    let got = &v3["frames"]["finger_r"]["djacobian_dq"]["world"];
    assert!((got[2][3][4].as_f64().unwrap() - t[(2, 3, 4)]).abs() < 1e-12);
    // Unsupported inputs and models.
    let with_w = tmp("mimic-kkt-weights.json");
    std::fs::write(&with_w, r#"{"weights": {"kkt_qdd": [1, 1, 1, 1, 1, 1, 1]}}"#).unwrap();
    let ww = with_w.to_str().unwrap();
    let err = assert_clean_failure(
        &sodyn(&["eval", "--model", u, "--mimic", "--state", ww]),
        "eval --mimic with contact weights",
    );
    assert!(err.contains("the weights kkt_* and impact_* need \"contacts\""), "{err}");
    let err = assert_clean_failure(
        &sodyn(&["eval", "--model", u, "--mimic", "--state", s]),
        "eval --mimic, the state of the floating base",
    );
    assert!(err.contains("key \"q\" has length 14, expected 7"), "{err}");
    let err = assert_clean_failure(
        &sodyn(&["info", "--model", "builtin:humanoid", "--mimic"]),
        "--mimic on a built-in",
    );
    assert!(err.contains("`--mimic`: applies to URDF files"), "{err}");
    let err = assert_clean_failure(
        &sodyn(&["bench", "--model", u, "--mimic", "--smoke", "--algos", "kkt_fo"]),
        "bench --mimic kkt_fo without contacts",
    );
    assert!(err.contains("\"kkt_fo\" needs contacts"), "{err}");
    let o = sodyn(&[
        "bench",
        "--model",
        u,
        "--mimic",
        "--floating-base",
        "--smoke",
        "--contacts",
        "tool,thumb_tip",
        "--algos",
        "kkt_so_c,impact_so_c",
    ]);
    assert_ok(&o, "bench --mimic with contacts");
    assert_eq!(
        stdout(&o).lines().filter(|l| l.starts_with("model=mimic_arm nq=14 nv=13")).count(),
        2
    );
    let o = sodyn(&["bench", "--model", u, "--mimic", "--smoke", "--algos", "rnea,fd_so"]);
    assert_ok(&o, "bench --mimic");
    assert_eq!(
        stdout(&o).lines().filter(|l| l.starts_with("model=mimic_arm nq=7 nv=7")).count(),
        2
    );
    let o = sodyn(&["demo", "--model", u, "--mimic"]);
    assert_ok(&o, "demo --mimic");
    // An unknown reference joint is an error with --mimic (a warning without).
    let bad = tmp("mimic-bad.urdf");
    std::fs::write(
        &bad,
        std::fs::read_to_string(&urdf).unwrap().replace("joint=\"shoulder\"", "joint=\"nope\""),
    )
    .unwrap();
    let b = bad.to_str().unwrap();
    let err = assert_clean_failure(&sodyn(&["info", "--model", b, "--mimic"]), "unknown reference");
    assert!(
        err.contains("joint \"wrist_follower_joint\"") && err.contains("\"nope\" is not a joint"),
        "{err}"
    );
    assert_ok(&sodyn(&["info", "--model", b]), "unknown reference without --mimic");
}

/// `bench --mimic` times the batched algorithms of `sodyn::batch` on the reduced model, on a
/// pool of `--threads` (the batch_* lines with threads= and per=state); the options it does
/// not support are clean errors.
#[test]
fn bench_mimic_times_the_batched_algorithms() {
    let urdf = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf");
    let u = urdf.to_str().unwrap();
    let algos = "rnea,batch_rnea,batch_aba,batch_id_fo,batch_fd_fo";
    for pool in ["spin", "rayon"] {
        let o = sodyn(&[
            "bench",
            "--model",
            u,
            "--mimic",
            "--smoke",
            "--threads",
            "2",
            "--pool",
            pool,
            "--algos",
            algos,
        ]);
        assert_ok(&o, "bench --mimic batch_*");
        let out = stdout(&o);
        let header = out.lines().next().unwrap();
        assert!(header.starts_with('#') && header.contains(" threads=2 pool="), "{header}");
        let lines: Vec<&str> = out.lines().filter(|l| l.starts_with("model=mimic_arm")).collect();
        assert_eq!(lines.len(), 5, "{out}");
        for a in ["batch_rnea", "batch_aba", "batch_id_fo", "batch_fd_fo"] {
            let l = lines.iter().find(|l| l.contains(&format!(" algo={a} "))).expect(a);
            assert!(l.contains(" batch=8 ") && l.contains(" threads=2 per=state"), "{l}");
        }
        assert!(!lines[0].contains("per=state"), "{}", lines[0]);
    }
    // Every algorithm runs on a reduced model, the batched ones on two threads too; an unknown
    // name is an error listing the catalogue.
    let o = sodyn(&[
        "bench",
        "--model",
        u,
        "--mimic",
        "--smoke",
        "--paired-threads",
        "2",
        "--algos",
        "batch_rnea,com",
    ]);
    assert_ok(&o, "bench --mimic --paired-threads");
    assert!(stdout(&o).contains("algo=com "), "{}", stdout(&o));
    let err = assert_clean_failure(
        &sodyn(&["bench", "--model", u, "--mimic", "--smoke", "--algos", "batch_kkt"]),
        "bench --mimic, unknown algorithm",
    );
    assert!(err.contains("unknown algorithm \"batch_kkt\"; known algorithms: rnea,"), "{err}");
}

/// Every unknown key of a state file, at any level, is an error naming it and the known keys
/// (a typo such as `"vel"` would otherwise evaluate at zero velocity), with and without
/// `--mimic`.
#[test]
fn unknown_state_keys_are_errors_at_every_level() {
    let state = tmp("typo.json");
    let st = state.to_str().unwrap();
    let known = "(known: q, v, a, tau, contacts, lambda, restitution, damping, weights, frames)";
    let mimic = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mimic_arm.urdf");
    for (body, needle) in [
        (r#"{"vel": [0], "tau_ext": [1]}"#, format!("unknown key \"tau_ext\" {known}")),
        (r#"{"q": [0, 0], "qd": [1, 2]}"#, format!("unknown key \"qd\" {known}")),
        (r#"{"Q": []}"#, format!("unknown key \"Q\" {known}")),
        (
            r#"{"contacts": [{"frame": "link2", "kp": 1, "gain": 2}]}"#,
            "unknown key \"contacts[0].gain\" (known: frame, type, reference, point, placement, \
             kp, kd, frame2, point2, placement2)"
                .to_string(),
        ),
        (
            r#"{"contacts": [{"frame": "link2", "placement": {"xyz": [0, 0, 0], "ypr": [0, 0, 0]}}]}"#,
            "unknown key \"contacts[0].placement.ypr\" (known: xyz, rpy)".to_string(),
        ),
        (r#"{"weights": {"qd": [1, 1]}}"#, "unknown key \"weights.qd\" (known: ".to_string()),
    ] {
        std::fs::write(&state, body).unwrap();
        let o = sodyn(&["eval", "--model", "builtin:pendulum2", "--state", st]);
        let err = assert_clean_failure(&o, body);
        assert!(err.contains(&format!("{st}: {needle}")), "{body}: {err}");
        assert!(stdout(&o).is_empty(), "{body}");
    }
    // Invalid JSON: the file, serde_json's line and column, and what it expected.
    std::fs::write(&state, "{\"q\": [0,\n  nope]}").unwrap();
    let o = sodyn(&["eval", "--model", "builtin:pendulum2", "--state", st]);
    let err = assert_clean_failure(&o, "invalid JSON");
    assert!(err.contains(&format!("{st}:2:")) && err.contains(": invalid JSON: "), "{err}");
    assert!(!err.contains(" at line "), "{err}");
    // With --mimic: the same keys; a "damping" > 0 with contacts is refused (the reduced
    // coordinates' contact solve has no regularised variant).
    std::fs::write(&state, r#"{"v": [], "vel": []}"#).unwrap();
    let o = sodyn(&["eval", "--model", mimic, "--mimic", "--state", st]);
    let err = assert_clean_failure(&o, "unknown key with --mimic");
    assert!(err.contains(&format!("{st}: unknown key \"vel\" {known}")), "{err}");
    std::fs::write(&state, r#"{"damping": 1e-6, "contacts": [{"frame": "palm"}]}"#).unwrap();
    let o = sodyn(&["eval", "--model", mimic, "--mimic", "--state", st]);
    let err = assert_clean_failure(&o, "damping with --mimic");
    assert!(err.contains("damping"), "{err}");
}

/// A redundant contact set (the same point twice): an error naming the contacts and the state
/// file's `"damping"` key, in the command line's terms (no Rust path); with `"damping" > 0`
/// the KKT and impact outputs are the regularised solve's, finite. A negative or non-numeric
/// damping is an error naming the key.
#[test]
fn redundant_contacts_and_the_damping_key() {
    let state = tmp("damping.json");
    let st = state.to_str().unwrap();
    let contacts = r#""contacts": [{"frame": "LF_FOOT"}, {"frame": "LF_FOOT"}]"#;
    let eval = |body: &str, order: &str| {
        std::fs::write(&state, body).unwrap();
        sodyn(&["eval", "--model", "builtin:quadruped", "--state", st, "--order", order])
    };
    let err = assert_clean_failure(&eval(&format!("{{{contacts}}}"), "1"), "redundant set");
    assert!(
        err.contains("LF_FOOT")
            && err.contains("rank deficient")
            && err.contains("\"damping\" key"),
        "{err}"
    );
    for order in ["1", "2"] {
        let body = format!(
            r#"{{{contacts}, "damping": 1e-6, "weights": {{"kkt_qdd": [{w}], "impact_vplus": [{w}]}}}}"#,
            w = vec!["1"; 18].join(", ")
        );
        let o = eval(&body, order);
        assert_ok(&o, "damped redundant set");
        let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
        for (obj, key) in [("kkt", "qdd"), ("kkt", "lambda"), ("impact", "vplus")] {
            let x = v[obj][key].as_array().unwrap_or_else(|| panic!("{obj}.{key}: {v}"));
            assert!(!x.is_empty() && x.iter().all(|x| x.as_f64().unwrap().is_finite()), "{x:?}");
        }
        assert!(v["contracted"]["kkt"]["d2qdd_dq2"].is_array(), "{}", v["contracted"]);
    }
    for bad in ["-1", "\"a\""] {
        let o = eval(&format!("{{{contacts}, \"damping\": {bad}}}"), "1");
        let err = assert_clean_failure(&o, bad);
        assert!(err.contains("key \"damping\" must be a non-negative number"), "{err}");
    }
}

/// Runs `sodyn args` with its standard output on a pipe, reads the first bytes and closes the
/// pipe: the command ends quietly (status 0, no panic message on standard error).
#[track_caller]
fn assert_quiet_on_closed_stdout(args: &[&str]) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_sodyn"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run the sodyn binary");
    let mut out = child.stdout.take().unwrap();
    let mut first = [0u8; 16];
    out.read_exact(&mut first).unwrap_or_else(|e| panic!("{args:?}: no output ({e})"));
    drop(out);
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
    assert_eq!(o.status.code(), Some(0), "{args:?}: status; stderr: {err}");
}

/// Every command, its output closed after its first bytes (`sodyn ... | head -c 16`). The
/// outputs that come at once are larger than a pipe's buffer (64 KiB), so that writing them
/// meets the closed pipe; `demo` and `bench` write line by line as they time.
#[test]
fn a_closed_standard_output_ends_every_command_quietly() {
    let state = tmp("pipe-state.json");
    std::fs::write(&state, "{}").unwrap();
    let st = state.to_str().unwrap();
    for args in [
        &["info", "--model", "builtin:random_tree1500"][..],
        &["random-state", "--model", "builtin:random_tree4000"],
        &["eval", "--model", "builtin:humanoid", "--state", st, "--order", "2"],
        &["demo"],
        &["demo", "--model", "builtin:quadruped", "--contacts", "LF_FOOT", "--contact-type", "6d"],
        &["bench", "--model", "builtin:humanoid", "--smoke"],
    ] {
        assert_quiet_on_closed_stdout(args);
    }
}

/// A closed standard error: warnings and error messages are dropped, the command goes on to
/// its own status (0 with warnings, 1 on an error) without a panic (status 101).
#[test]
fn a_closed_standard_error_is_ignored() {
    let urdf = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/lenient/reversed_limits.urdf");
    for (args, status) in [
        (&["info", "--model", urdf][..], 0),
        (&["info", "--model", "builtin:nonexistent"], 1),
        (&["eval", "--model", "builtin:pendulum2", "--state", "/nonexistent/state.json"], 1),
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_sodyn"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("run the sodyn binary");
        drop(child.stderr.take());
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(status), "{args:?}");
        if status == 0 {
            assert!(stdout(&o).contains("x_to_world"), "{args:?}: {}", stdout(&o));
        }
    }
    // The same warnings with standard error open: file, line, joint.
    let o = sodyn(&["info", "--model", urdf]);
    assert_ok(&o, "info on reversed limits");
    let err = stderr(&o);
    assert!(
        err.contains(&format!("sodyn: warning: {urdf}:27: joint \"x_to_world\": <limit"))
            && err.contains(&format!("{urdf}:32: joint \"shoulder\""))
            && err.contains("loaded without limits"),
        "{err}"
    );
}

/// `demo` takes the model options of `eval` and the contacts of `bench`; its error column stays
/// at round-off against the oracle. Without options it is unchanged (the humanoid, its soles).
#[test]
fn demo_takes_the_model_and_contact_options() {
    let models = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/models");
    let solo = models.join("solo12.urdf");
    let solo = solo.to_str().unwrap();
    let max_err = |o: &Output| -> f64 {
        let out = stdout(o);
        let line = out
            .lines()
            .find_map(|l| l.strip_prefix("maximum relative error against the oracle: "))
            .unwrap_or_else(|| panic!("no error line: {out}"));
        line.trim().parse().unwrap()
    };
    let runs: [(&[&str], &str); 4] = [
        (
            &["demo", "--model", solo, "--floating-base", "--contacts", "FL_FOOT,FR_FOOT,HL_FOOT"],
            "contacts (3d local_world_aligned) on FL_FOOT, FR_FOOT, HL_FOOT",
        ),
        (
            &[
                "demo",
                "--model",
                solo,
                "--floating-base",
                "--contacts",
                "FL_FOOT,HR_FOOT",
                "--contact-type",
                "6d",
                "--contact-reference",
                "local",
                "--armature",
                "0.01",
            ],
            "contacts (6d local) on FL_FOOT, HR_FOOT",
        ),
        (&["demo", "--model", "builtin:quadruped", "--armature", "0.1"], "contacts on LF_FOOT"),
        (&["demo", "--model", "builtin:pendulum3"], "nq = 3, nv = 3"),
    ];
    for (args, needle) in runs {
        let o = sodyn(args);
        assert_ok(&o, &args.join(" "));
        let out = stdout(&o);
        assert!(out.contains(needle), "{args:?}: {out}");
        assert!(max_err(&o) < 1e-8, "{args:?}: {out}");
        if args.contains(&"--floating-base") {
            assert!(out.contains("nq = 19, nv = 18"), "{out}");
        }
    }
    let (base, no_armature) = (
        sodyn(&["demo", "--model", "builtin:quadruped"]),
        sodyn(&["demo", "--model", "builtin:quadruped", "--armature", "0"]),
    );
    assert_ok(&base, "demo quadruped");
    assert_ok(&no_armature, "demo quadruped --armature 0");
    // Errors: an unknown contact frame, --contact-type without
    // --contacts, a floating base on a built-in model.
    let err = assert_clean_failure(
        &sodyn(&["demo", "--model", solo, "--contacts", "FL_FOOT,NOSE"]),
        "unknown contact frame",
    );
    assert!(err.contains("`--contacts`: unknown frame \"NOSE\""), "{err}");
    // A model in reduced coordinates takes contacts like any other.
    let mimic = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mimic_arm.urdf");
    let o = sodyn(&["demo", "--model", mimic, "--mimic", "--floating-base", "--contacts", "tool"]);
    assert_ok(&o, "demo --mimic with contacts");
    assert!(stdout(&o).contains(" on tool") && stdout(&o).contains("kkt"), "{}", stdout(&o));
    let err = assert_usage_error(&sodyn(&["demo", "--contact-type", "6d"]), "--contact-type alone");
    assert!(err.contains("--contacts"), "{err}");
    let err =
        assert_clean_failure(&sodyn(&["demo", "--floating-base"]), "--floating-base built-in");
    assert!(err.contains("`--floating-base`: applies to URDF files"), "{err}");
}

#[test]
fn eval_takes_two_frame_constraints() {
    use sodyn::algo::{Contact, Data};
    use sodyn::deriv::{
        ContactData, impact_derivatives, impact_so_derivatives, kkt_derivatives, kkt_so_derivatives,
    };
    use sodyn::spatial::Transform;
    let m = sodyn::model::builtin::quadruped();
    let nv = m.nv();
    let vals = |s: f64| -> Vec<f64> { (0..nv).map(|i| s * (i as f64 + 1.0) / nv as f64).collect() };
    let (v, tau) = (vals(0.4), vals(0.5));
    // Bent legs (at the neutral configuration they are straight: singular loops).
    let mut q = m.neutral();
    for i in 7..m.nq() {
        q[i] = 0.2 + 0.05 * i as f64;
    }
    let qv: Vec<f64> = q.iter().copied().collect();
    let run = |feet: &str, name: &str| {
        let state = tmp(name);
        let body = format!(r#"{{"q": {qv:?}, "v": {v:?}, "tau": {tau:?}, "contacts": {feet}}}"#);
        std::fs::write(&state, body).unwrap();
        sodyn(&["eval", "--model", "builtin:quadruped", "--state", state.to_str().unwrap()])
    };
    let feet = r#"[{"frame": "LF_FOOT", "frame2": "RH_FOOT", "point2": [0, 0.01, 0], "kd": 2},
        {"frame": "RF_FOOT", "type": "6d", "frame2": "LH_FOOT",
         "placement2": {"xyz": [0.01, 0, -0.02], "rpy": [0.1, -0.2, 0.3]}}]"#;
    let o = run(feet, "loops.json");
    assert_ok(&o, "eval with two-frame constraints");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let contacts = vec![
        Contact::new(&m, "LF_FOOT", nalgebra::Vector3::zeros())
            .unwrap()
            .with_baumgarte(0.0, 2.0)
            .unwrap()
            .with_frame2(
                &m,
                "RH_FOOT",
                Some(&Transform::from_translation(nalgebra::Vector3::new(0.0, 0.01, 0.0))),
            )
            .unwrap(),
        Contact {
            kind: sodyn::algo::ContactType::D6,
            ..Contact::new(&m, "RF_FOOT", nalgebra::Vector3::zeros())
                .unwrap()
                .with_frame2(
                    &m,
                    "LH_FOOT",
                    Some(&Transform::from_rpy_xyz([0.1, -0.2, 0.3], [0.01, 0.0, -0.02])),
                )
                .unwrap()
        },
    ];
    let mut cd = ContactData::new(&m, &contacts).unwrap();
    let (v, tau) = (DVector::from_vec(v.clone()), DVector::from_vec(tau.clone()));
    let mut d = Data::new(&m);
    let kd = kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
    let lam = vector(&out["kkt"], "lambda", 9);
    assert!((&lam - kd.lambda()).amax() < 1e-12 * (1.0 + kd.lambda().amax()));
    let dq = matrix(&out["kkt"], "dqdd_dq", nv);
    assert!((&dq - kd.dqdd_dq()).amax() < 1e-12 * (1.0 + kd.dqdd_dq().amax()));
    let im = impact_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap();
    let imp = vector(&out["impact"], "impulse", 9);
    assert!((&imp - im.impulse()).amax() < 1e-12 * (1.0 + im.impulse().amax()));
    assert_eq!(out["constrained_id"]["tau"].as_array().unwrap().len(), nv);
    // `--order 2`: the second-order tensors with loops, those of the library.
    let state = tmp("loops-order2.json");
    let body = format!(
        r#"{{"q": {qv:?}, "v": {:?}, "tau": {:?}, "contacts": {feet}}}"#,
        v.as_slice(),
        tau.as_slice()
    );
    std::fs::write(&state, body).unwrap();
    let o = sodyn(&[
        "eval",
        "--model",
        "builtin:quadruped",
        "--state",
        state.to_str().unwrap(),
        "--order",
        "2",
    ]);
    assert_ok(&o, "eval --order 2 with two-frame constraints");
    let out2: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(out2.get("errors").is_none(), "{}", out2["errors"]);
    let mut cd2 = ContactData::with_second_order(&m, &contacts).unwrap();
    let mut d2 = Data::with_second_order(&m);
    let close = |got: &Value, want: &sodyn::tensor::Tensor3, what: &str| {
        let t = sodyn::tensor::Tensor3::from_nested(
            &serde_json::from_value::<Vec<Vec<Vec<f64>>>>(got.clone()).unwrap(),
        )
        .unwrap_or_else(|| panic!("{what}: not a tensor"));
        assert_eq!(t.dims(), want.dims(), "{what}");
        let err = t.as_slice().iter().zip(want.as_slice()).map(|(a, b)| (a - b).abs());
        let scale = want.as_slice().iter().fold(1.0f64, |s, x| s.max(x.abs()));
        let err = err.fold(0.0f64, f64::max);
        assert!(err <= 1e-12 * scale, "{what}: {err:e} (scale {scale:e})");
    };
    let ks = kkt_so_derivatives(&m, &mut d2, &mut cd2, &q, &v, &tau).unwrap().so().unwrap().clone();
    close(&out2["kkt"]["d2qdd_dq2"], ks.d2qdd_dq2(), "kkt.d2qdd_dq2");
    close(&out2["kkt"]["d2lambda_dqdv"], ks.d2lambda_dqdv(), "kkt.d2lambda_dqdv");
    let is = impact_so_derivatives(&m, &mut d2, &mut cd2, &q, &v).unwrap().so().unwrap().clone();
    close(&out2["impact"]["d2vplus_dq2"], is.d2vplus_dq2(), "impact.d2vplus_dq2");
    close(
        &out2["impact"]["d2impulse_dqdvminus"],
        is.d2impulse_dqdvminus(),
        "impact.d2impulse_dqdvminus",
    );
    let d2tau = &out2["constrained_id"]["d2tau_dq2"];
    assert_eq!(d2tau.as_array().map(Vec::len), Some(nv), "constrained_id.d2tau_dq2");
    // Bad input names the contact and the key.
    for (feet, needle) in [
        (r#"[{"frame": "LF_FOOT", "point2": [0, 0, 0]}]"#, "contacts[0].point2 needs a \"frame2\""),
        (r#"[{"frame": "LF_FOOT", "frame2": "NOPE"}]"#, "NOPE"),
        (r#"[{"frame": "LF_FOOT", "frame2": "LF_FOOT"}]"#, "same body"),
        (r#"[{"frame": "LF_FOOT", "frame2": "RH_FOOT", "point2": [0, 0]}]"#, "contacts[0].point2"),
    ] {
        let o = run(feet, "bad_loop.json");
        let e = assert_clean_failure(&o, feet);
        assert!(e.contains(needle), "{feet}: {e}");
    }
}

/// A state file without `"contacts"` takes the model's own constraints (builtin:delta's three
/// loops: the KKT outputs match the library's with `Model::constraints`); `"contacts": []` means
/// none; a reduced MJCF model with loops reports the refusal in `errors`.
#[test]
fn eval_defaults_to_the_model_constraints() {
    use sodyn::algo::Data;
    use sodyn::deriv::{ContactData, kkt_derivatives};
    let m = sodyn::model::builtin::delta();
    let nv = m.nv();
    let tau: Vec<f64> = (0..nv).map(|i| 0.1 * i as f64 - 0.5).collect();
    let run = |extra: &str, model: &str, name: &str| {
        let state = tmp(name);
        std::fs::write(&state, format!(r#"{{"tau": {tau:?}{extra}}}"#)).unwrap();
        sodyn(&["eval", "--model", model, "--state", state.to_str().unwrap()])
    };
    let o = run("", "builtin:delta", "delta-own.json");
    assert_ok(&o, "eval with the model's constraints");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let kkt = &out["kkt"];
    let (q, v) = (m.neutral(), DVector::zeros(nv));
    let mut cd = ContactData::new(&m, m.constraints()).unwrap();
    let kd =
        kkt_derivatives(&m, &mut Data::new(&m), &mut cd, &q, &v, &DVector::from_vec(tau.clone()))
            .unwrap();
    assert!((vector(kkt, "lambda", 9) - kd.lambda()).amax() <= 1e-12 * kd.lambda().amax());
    assert!((vector(kkt, "qdd", nv) - kd.qdd()).amax() <= 1e-12 * kd.qdd().amax().max(1.0));
    let o = run(r#", "contacts": []"#, "builtin:delta", "delta-none.json");
    assert_ok(&o, "eval without contacts");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(out.get("kkt").is_none());
    // equality.xml: a joint coupling (reduced coordinates) and loops.
    let xml = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mjcf/equality.xml");
    let state = tmp("equality-own.json");
    std::fs::write(&state, "{}").unwrap();
    let o = sodyn(&["eval", "--model", xml, "--state", state.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let why = out["errors"]["contacts"].as_str().unwrap();
    assert!(why.contains("model's constraints") && why.contains("reduced coordinates"), "{why}");
}

/// An MJCF model whose `<equality><tendon>` couples several joints: `info` prints each
/// eliminated joint's rule, `eval` gives it a `"coupling"` object and writes the reduced
/// outputs (those of the library), and `--armature` keeps every coupling.
#[test]
fn cli_on_tendon_couplings() {
    let xml = tmp("tendon_coupled.xml");
    std::fs::write(&xml, crate::util::mimic::TENDON_MJCF).unwrap();
    let xml = xml.to_str().unwrap();
    let m = crate::util::mimic::tendon_model();
    let (nv, nq) = (m.nv(), m.nq());
    assert!(m.linear_couplings().iter().any(|c| c.terms.len() > 1));
    let o = sodyn(&["info", "--model", xml]);
    assert_ok(&o, "info on a tendon-coupled model");
    let out = stdout(&o);
    assert!(out.contains(&format!("nq = {nq}, nv = {nv}")), "{out}");
    // j3 is eliminated by the coupling of t1 (j1, j2, j3) to t2 (j2, s1).
    let j3 = out.lines().find(|l| l.contains("j3")).expect("a line for j3");
    assert!(j3.contains("q = ") && j3.contains("q[\"j1\"]") && j3.contains("q[\"s1\"]"), "{j3}");
    let state = tmp("tendon_state.json");
    let q: Vec<f64> = m.neutral().iter().copied().collect();
    let tau: Vec<f64> = (0..nv).map(|i| 0.1 * i as f64 - 0.3).collect();
    std::fs::write(&state, format!(r#"{{"q": {q:?}, "tau": {tau:?}}}"#)).unwrap();
    let eval = |extra: &[&str]| {
        let base = ["eval", "--model", xml, "--state", state.to_str().unwrap()];
        sodyn(&[&base[..], extra].concat())
    };
    let o = eval(&[]);
    assert_ok(&o, "eval on a tendon-coupled model");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let joints = out["joints"].as_array().unwrap();
    let j3 = joints.iter().find(|j| j["name"] == "j3").unwrap();
    assert_eq!(j3["nv"], 0, "{j3}");
    let terms = j3["coupling"]["terms"].as_array().expect("a coupling object");
    assert!(terms.len() > 1, "{j3}");
    let mut d = sodyn::algo::Data::new(&m);
    let v = DVector::zeros(nv);
    let qdd = sodyn::algo::aba(&m, &mut d, &m.neutral(), &v, &DVector::from_vec(tau), None)
        .unwrap()
        .clone();
    assert!((vector(&out, "qdd", nv) - &qdd).amax() <= 1e-12 * qdd.amax().max(1.0));
    // --armature (one value per DoF of the full tree) keeps every coupling: nv unchanged.
    let o = eval(&["--armature", "0.01"]);
    assert_ok(&o, "eval --armature on a tendon-coupled model");
    let out: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(out["nv"], nv, "{}", out["nv"]);
}
