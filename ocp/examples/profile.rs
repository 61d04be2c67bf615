//! Times (or, with `--calls N`, just runs for callgrind) the phases of an FDDP solve on a
//! problem file: `{"problem": <spec JSON>, "xs": [...], "us": [...]}` and a URDF model.
//!
//! `cargo run --release -p sodyn-ocp --example profile -- MODEL.urdf PROBLEM.json [--calls N] [--fixed-base]`

use nalgebra::DVector;
use sodyn::model::{UrdfOptions, load_urdf_file};
use sodyn_ocp::{Solver, SolverKind, spec};
use std::sync::Arc;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!(
            "usage: profile MODEL.urdf PROBLEM.json [--calls N] [--phase calc_diff|solve] [--fixed-base]"
        );
        std::process::exit(2);
    }
    let floating_base = !args.iter().any(|a| a == "--fixed-base");
    let opts = UrdfOptions { floating_base, ..Default::default() };
    let model = Arc::new(load_urdf_file(std::path::Path::new(&args[1]), &opts).expect("model"));
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&args[2]).expect("file")).expect("json");
    let calls: Option<usize> =
        args.iter().position(|a| a == "--calls").map(|i| args[i + 1].parse().expect("N"));
    let phase = args
        .iter()
        .position(|a| a == "--phase")
        .map(|i| args[i + 1].clone())
        .unwrap_or_else(|| "calc_diff".into());
    let problem = spec::problem_from_json(model, &doc["problem"].to_string()).expect("problem");
    let vecs = |k: &str| -> Vec<DVector<f64>> {
        doc[k]
            .as_array()
            .expect(k)
            .iter()
            .map(|x| {
                DVector::from_vec(
                    x.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect(),
                )
            })
            .collect()
    };
    let (xs, us) = (vecs("xs"), vecs("us"));
    let mut solver = Solver::new(problem, SolverKind::Fddp);
    let n = calls.unwrap_or(50);
    let t = Instant::now();
    for _ in 0..n {
        match phase.as_str() {
            "solve" => {
                solver.solve(&xs, &us, 100, false, None).expect("solve");
            }
            _ => {
                solver.problem.calc_diff(&xs, &us).expect("calc_diff");
            }
        }
    }
    let dt = t.elapsed().as_secs_f64() / n as f64;
    if calls.is_none() {
        println!(
            "{phase}: {:.3} ms per call (T = {}, iterations of the last solve: {}, cost {:?})",
            dt * 1e3,
            solver.problem.horizon(),
            solver.iter(),
            solver.cost()
        );
    }
}
