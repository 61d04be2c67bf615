//! The `sodyn` command-line tool: `info`, `random-state`, `eval`, `demo`, `bench`.

mod bench;
mod eval;

use crate::error::{Error, Result};
use crate::model::Model;
use nalgebra::DVector;
use serde_json::{Value, json};
use std::path::Path;

pub use eval::{State, eval_json, load_state, state_json};

const USAGE: &str = "\
sodyn: rigid-body dynamics and its exact first- and second-order derivatives

USAGE:
  sodyn demo [--model M] [--seed S]
  sodyn info --model M [--floating-base]
  sodyn random-state --model M [--floating-base] [--seed S] [--output FILE]
  sodyn eval --model M [--floating-base] --state FILE [--order 1|2] [--output FILE]
  sodyn bench --model M [--floating-base] [--contacts F1,F2] [--algos a,b] [--states N]
              [--seed S] [--max-seconds X] [--iters N] [--threads N] [--name NAME] [--smoke]

M is a URDF path or builtin:NAME (builtin:humanoid, builtin:quadruped, builtin:chain7,
builtin:pendulum2, builtin:random_tree20, builtin:random_tree20_ff, ...).
--floating-base adds a free-flyer root joint in front of a URDF's root link.
See README.md for the JSON schemas.";

/// Parsed command-line options shared by the subcommands.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// `--model`.
    pub model: Option<String>,
    /// `--floating-base`.
    pub floating_base: bool,
    /// `--seed`.
    pub seed: u64,
    /// `--state`.
    pub state: Option<String>,
    /// `--output`.
    pub output: Option<String>,
    /// `--order` (1 or 2).
    pub order: u32,
}

fn parse_options(args: &[String]) -> Result<Options> {
    let mut o = Options { order: 1, ..Options::default() };
    let mut i = 0;
    let value = |i: usize, name: &str| -> Result<String> {
        args.get(i + 1).cloned().ok_or_else(|| Error::Io(format!("option {name} needs a value")))
    };
    while i < args.len() {
        match args[i].as_str() {
            "--model" => {
                o.model = Some(value(i, "--model")?);
                i += 1;
            }
            "--floating-base" => o.floating_base = true,
            "--seed" => {
                let s = value(i, "--seed")?;
                o.seed = s.parse().map_err(|_| {
                    Error::Io(format!("--seed: \"{s}\" is not a non-negative integer"))
                })?;
                i += 1;
            }
            "--state" => {
                o.state = Some(value(i, "--state")?);
                i += 1;
            }
            "--order" => {
                let s = value(i, "--order")?;
                o.order = match s.as_str() {
                    "1" => 1,
                    "2" => 2,
                    _ => return Err(Error::Io(format!("--order: \"{s}\" must be 1 or 2"))),
                };
                i += 1;
            }
            "--output" | "-o" => {
                o.output = Some(value(i, "--output")?);
                i += 1;
            }
            other => return Err(Error::Io(format!("unknown option \"{other}\"\n\n{USAGE}"))),
        }
        i += 1;
    }
    Ok(o)
}

/// Loads a model from `builtin:NAME` or a URDF path.
pub fn load_model(spec: &str, floating_base: bool) -> Result<Model> {
    if let Some(name) = spec.strip_prefix("builtin:") {
        if floating_base {
            return Err(Error::Io(format!(
                "--floating-base applies to URDF files; built-in model \"{name}\" defines its own base"
            )));
        }
        crate::model::builtin::by_name(name)
            .ok_or_else(|| Error::Unknown { kind: "built-in model".into(), name: name.into() })
    } else {
        let opts = crate::model::urdf::UrdfOptions { floating_base };
        crate::model::urdf::load_urdf_file(Path::new(spec), &opts)
    }
}

fn need_model(o: &Options) -> Result<Model> {
    let spec =
        o.model.as_deref().ok_or_else(|| Error::Io(format!("--model is required\n\n{USAGE}")))?;
    load_model(spec, o.floating_base)
}

fn write_output(o: &Options, v: &Value) -> Result<()> {
    let text = serde_json::to_string(v).map_err(|e| Error::Io(e.to_string()))?;
    match &o.output {
        Some(path) => {
            std::fs::write(path, text + "\n").map_err(|e| Error::Io(format!("{path}: {e}")))
        }
        None => {
            println!("{text}");
            Ok(())
        }
    }
}

/// The joint table of a model as printed by `sodyn info`.
pub fn joint_table(model: &Model) -> String {
    let mut s = format!(
        "model \"{}\": nq = {}, nv = {}, {} joints, {} frames\n",
        model.name,
        model.nq,
        model.nv,
        model.njoints() - 1,
        model.frames.len()
    );
    s += &format!(
        "{:>4}  {:<32} {:<11} {:<28} {:>5} {:>3} {:>5} {:>3}  {:>9}  mimic\n",
        "id", "name", "type", "parent", "idx_q", "nq", "idx_v", "nv", "mass"
    );
    for i in 1..model.njoints() {
        let p = model.parents[i];
        s += &format!(
            "{:>4}  {:<32} {:<11} {:<28} {:>5} {:>3} {:>5} {:>3}  {:>9.4}  {}\n",
            i,
            model.names[i],
            model.joints[i].name(),
            model.names[p],
            model.idx_q[i],
            model.nqs[i],
            model.idx_v[i],
            model.nvs[i],
            model.inertias[i].mass,
            model.mimic[i]
                .as_ref()
                .map(|m| format!("mimics \"{m}\" (loaded independent)"))
                .unwrap_or_default()
        );
    }
    s
}

/// Runs the CLI with `args` (without the program name). Returns the process exit code.
pub fn run(args: &[String]) -> i32 {
    match run_inner(args) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("sodyn: error: {e}");
            1
        }
    }
}

fn run_inner(args: &[String]) -> Result<()> {
    let Some(cmd) = args.first() else {
        println!("{USAGE}");
        return Ok(());
    };
    if cmd == "bench" {
        // `bench` has options of its own.
        return bench::run(&args[1..]);
    }
    let o = parse_options(&args[1..])?;
    match cmd.as_str() {
        "info" => {
            let m = need_model(&o)?;
            print!("{}", joint_table(&m));
            Ok(())
        }
        "random-state" => {
            let m = need_model(&o)?;
            let mut rng = crate::rng::Rng::new(o.seed);
            let st = State::random(&m, &mut rng);
            write_output(&o, &state_json(&st))
        }
        "eval" => {
            let m = need_model(&o)?;
            let path = o.state.as_deref().ok_or_else(|| Error::Io("--state is required".into()))?;
            let text =
                std::fs::read_to_string(path).map_err(|e| Error::Io(format!("{path}: {e}")))?;
            let st = load_state(&m, &text, path)?;
            let out = eval_json(&m, &st, o.order)?;
            write_output(&o, &out)
        }
        "demo" => crate::demo::run_demo(o.model.as_deref().unwrap_or("builtin:humanoid"), o.seed),
        "help" | "--help" | "-h" => {
            println!("{USAGE}");
            Ok(())
        }
        other => Err(Error::Io(format!("unknown command \"{other}\"\n\n{USAGE}"))),
    }
}

/// A JSON array of a vector.
pub fn vec_json(x: &DVector<f64>) -> Value {
    json!(x.as_slice())
}
