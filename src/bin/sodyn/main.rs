//! The `sodyn` command-line tool: `demo`, `info`, `random-state`, `eval`, `bench`.
//!
//! Everything of the command line lives in this binary, not in the library: argument parsing
//! (clap), the JSON state files and `eval` output ([`eval`]), the timings of `demo` and `bench`.
//! Exit status: 0 on success (also when standard output is closed while a command writes, e.g.
//! by `| head`: the command ends there, quietly; see [`out`]), 1 on an error found while
//! running (the message, prefixed with `sodyn: error:`, on standard error; a closed standard
//! error is ignored), 2 on a usage error reported by clap (unknown option,
//! missing or malformed value), 3 when `eval` wrote partial results (outputs undefined at the
//! state, e.g. a singular mass matrix, left out and named in the output's `"errors"` object).

// First: its macros (`outln!`, `out!`, `errln!`) are used by the modules below.
#[macro_use]
mod out;

mod bench;
mod demo;
mod eval;

use clap::{Args, CommandFactory, Parser, Subcommand};
use serde_json::Value;
use sodyn::error::{Error, Result};
use sodyn::model::{ContactReference, ContactType, MjcfOptions, Model, UrdfOptions};
use std::path::Path;
use std::process::ExitCode;

/// Shown under every command's `--help`.
const AFTER_HELP: &str = "\
M is a URDF path, an MJCF (MuJoCo XML) path ending in .xml, or builtin:NAME (humanoid,
quadruped, chain<N>, pendulum<N>, random_tree<N>[_ff][_s<SEED>]). Exit status: 0 on success
(also when standard output is closed early, e.g. by head), 1 on an error (the message on
standard error), 2 on a usage error, 3 when eval left out undefined outputs (its \"errors\"
object names them). README.md has the JSON schemas.";

/// sodyn: rigid-body dynamics and its exact first- and second-order derivatives
#[derive(Debug, Parser)]
#[command(name = "sodyn", version, after_help = AFTER_HELP, args_override_self = true)]
#[command(max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Every algorithm at a random state: timings and errors against the AD oracle
    #[command(after_help = AFTER_HELP)]
    Demo(DemoArgs),
    /// Print the joint table of a model
    #[command(after_help = AFTER_HELP)]
    Info(InfoArgs),
    /// Write a random state (q, v, a, tau) as JSON
    #[command(after_help = AFTER_HELP)]
    RandomState(RandomStateArgs),
    /// Values and derivatives at a state: a JSON state file in, one JSON object out
    #[command(after_help = AFTER_HELP)]
    Eval(EvalArgs),
    /// Time the algorithms per call, one line per algorithm
    #[command(long_about = bench::long_about(), after_help = AFTER_HELP)]
    Bench(bench::BenchArgs),
}

/// `--model` and `--floating-base`.
#[derive(Clone, Debug, Args)]
struct ModelArgs {
    /// The model: a URDF or MJCF (.xml) path, or builtin:NAME
    #[arg(long, value_name = "M")]
    model: String,
    /// Add a free-flyer root joint in front of the URDF's root link (MJCF: of the worldbody's
    /// only body)
    #[arg(long)]
    floating_base: bool,
    /// Refuse a URDF link inertia that violates the triangle inequality instead of loading it
    /// with a warning
    #[arg(long)]
    strict_inertia: bool,
    /// Armature (rotor inertia added to the mass matrix's diagonal) of the degrees of freedom:
    /// one value for every DoF, or nv comma-separated values in velocity order; replaces the
    /// model's own (zeros for URDF and built-in models, the joints' armature for MJCF)
    #[arg(long, value_name = "A", allow_hyphen_values = true)]
    armature: Option<String>,
    /// Read the URDF's <mimic> joints as constraints (q = multiplier * q_ref + offset): they
    /// have no degree of freedom, and q, v, a, tau and every output are in the reduced
    /// coordinates (--armature then gives the full tree's DoFs)
    #[arg(long)]
    mimic: bool,
}

/// Options of `sodyn demo`: those of `--model` (`ModelArgs`, with a default model) and the
/// contacts of `bench`.
#[derive(Debug, Args)]
struct DemoArgs {
    /// The model: a URDF or MJCF (.xml) path, or builtin:NAME
    #[arg(long, value_name = "M", default_value = "builtin:humanoid")]
    model: String,
    /// Add a free-flyer root joint in front of the URDF's root link (MJCF: of the worldbody's
    /// only body)
    #[arg(long)]
    floating_base: bool,
    /// Refuse a URDF link inertia that violates the triangle inequality instead of loading it
    /// with a warning
    #[arg(long)]
    strict_inertia: bool,
    /// Armature of the degrees of freedom: one value for every DoF, or nv comma-separated
    /// values in velocity order (see eval --help)
    #[arg(long, value_name = "A", allow_hyphen_values = true)]
    armature: Option<String>,
    /// Read the URDF's <mimic> joints as constraints (see info --help); the demo then has no
    /// contacts
    #[arg(long)]
    mimic: bool,
    /// Contacts at the origins of these frames (of --contact-type, in --contact-reference)
    /// instead of the default ones (the soles or feet of a model that has frames named
    /// left_sole, right_sole, LF_FOOT, RF_FOOT, LH_FOOT, RH_FOOT)
    #[arg(long, value_name = "F1,F2,...", value_parser = bench::parse_list)]
    contacts: Option<bench::List>,
    /// Type of the --contacts: 3d (points) or 6d (the whole frames)
    #[arg(long, value_name = "3d|6d", default_value = "3d", requires = "contacts",
          value_parser = |s: &str| ContactType::parse(s).map_err(|e| e.to_string()))]
    contact_type: ContactType,
    /// Axes of the --contacts' rows: local_world_aligned or local
    #[arg(long, value_name = "local_world_aligned|local", default_value = "local_world_aligned",
          requires = "contacts",
          value_parser = |s: &str| ContactReference::parse(s).map_err(|e| e.to_string()))]
    contact_reference: ContactReference,
    /// Seed of the random state
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
}

impl DemoArgs {
    /// The model options.
    fn model_args(&self) -> ModelArgs {
        ModelArgs {
            model: self.model.clone(),
            floating_base: self.floating_base,
            strict_inertia: self.strict_inertia,
            armature: self.armature.clone(),
            mimic: self.mimic,
        }
    }
}

#[derive(Debug, Args)]
struct InfoArgs {
    #[command(flatten)]
    model: ModelArgs,
}

#[derive(Debug, Args)]
struct RandomStateArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Seed of the random state
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// Write the JSON to FILE instead of standard output
    #[arg(short, long, value_name = "FILE")]
    output: Option<String>,
}

#[derive(Debug, Args)]
struct EvalArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// The state: a JSON file with q, v, a, tau (and optionally contacts, lambda, restitution,
    /// damping, weights, frames); without contacts, the model's own constraints (MJCF
    /// equality constraints, the loops of builtin:fourbar and builtin:delta)
    #[arg(long, value_name = "FILE")]
    state: String,
    /// 1: values and first-order derivatives; 2: also the second-order tensors
    #[arg(long, value_name = "1|2", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=2))]
    order: u32,
    /// Write the JSON to FILE instead of standard output
    #[arg(short, long, value_name = "FILE")]
    output: Option<String>,
}

fn main() -> ExitCode {
    // Usage errors, `--help` and `--version` exit here (status 2, 0, 0).
    let cli = Cli::parse();
    match run(cli) {
        Ok(Outcome::Done) => ExitCode::SUCCESS,
        Ok(Outcome::Partial) => ExitCode::from(PARTIAL_EXIT),
        Err(e) => {
            errln!("sodyn: error: {}", out::cli_message(&e.to_string()));
            ExitCode::from(1)
        }
    }
}

/// Exit status of `eval` when it wrote partial results.
const PARTIAL_EXIT: u8 = 3;

/// How a command that did not fail ended.
enum Outcome {
    /// Every output written.
    Done,
    /// `eval` wrote the outputs that are defined and an `"errors"` object for the others.
    Partial,
}

fn run(cli: Cli) -> Result<Outcome> {
    let Some(command) = cli.command else {
        // No command: the help, as `sodyn --help` prints it.
        out!("{}", Cli::command().render_help());
        return Ok(Outcome::Done);
    };
    match command {
        Command::Demo(o) => demo::run_demo(&o),
        Command::Info(o) => {
            let m = load_model(&o.model)?;
            out!("{}", joint_table(&m));
            Ok(())
        }
        Command::RandomState(o) => {
            let m = load_model(&o.model)?;
            let mut rng = sodyn::rng::Rng::new(o.seed);
            let st = eval::State::random(&m, &mut rng);
            write_output(o.output.as_deref(), &eval::state_json(&st))
        }
        Command::Eval(o) => return run_eval(&o),
        Command::Bench(o) => bench::run(&o),
    }
    .map(|()| Outcome::Done)
}

/// `sodyn eval`: the output object, written also when some outputs are undefined at the state
/// (then `Outcome::Partial`, and a message on standard error listing them).
fn run_eval(o: &EvalArgs) -> Result<Outcome> {
    let path = &o.state;
    let m = load_model(&o.model)?;
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io(format!("{path}: {e}")))?;
    let base = (!o.model.model.starts_with("builtin:")).then_some(o.model.floating_base);
    let st = eval::load_state(&m, &text, path, base)?;
    let out = eval::eval_json(&m, &st, o.order)?;
    write_output(o.output.as_deref(), &out)?;
    match out.get("errors").and_then(Value::as_object) {
        Some(errors) => {
            let keys: Vec<&str> = errors.keys().map(String::as_str).collect();
            errln!(
                "sodyn: error: {} undefined at this state, left out of the output (its \"errors\" \
                 object has the reasons): {}",
                if keys.len() == 1 { "an output is" } else { "outputs are" },
                keys.join(", ")
            );
            Ok(Outcome::Partial)
        }
        None => Ok(Outcome::Done),
    }
}

/// Loads a model from `builtin:NAME`, an MJCF path (`.xml`) or a URDF path; with `--mimic`, a
/// URDF's model in the reduced coordinates of its `<mimic>` joints (`--armature` then gives the
/// full tree's DoFs).
fn load_model(o: &ModelArgs) -> Result<Model> {
    if o.mimic && (o.model.starts_with("builtin:") || is_mjcf(&o.model)) {
        return Err(Error::Argument {
            name: "--mimic".into(),
            reason: format!("applies to URDF files (their <mimic> elements); {} has none", o.model),
        });
    }
    let opts = UrdfOptions {
        floating_base: o.floating_base,
        strict_inertia: o.strict_inertia,
        mimic: o.mimic,
    };
    let model = load_model_spec(&o.model, &opts)?;
    match &o.armature {
        Some(a) if model.is_reduced() => {
            with_armature_arg(model.full_tree(), a)?.with_linear_couplings(model.linear_couplings())
        }
        Some(a) => with_armature_arg(&model, a),
        None => Ok(model),
    }
}

/// The model with the armature of `--armature`: one number for every DoF, or `nv`
/// comma-separated numbers.
fn with_armature_arg(model: &Model, arg: &str) -> Result<Model> {
    let vals = arg
        .split(',')
        .map(|x| {
            x.trim().parse::<f64>().map_err(|e| Error::Argument {
                name: "--armature".into(),
                reason: format!("\"{}\" is not a number ({e})", x.trim()),
            })
        })
        .collect::<Result<Vec<f64>>>()?;
    let a = match vals.as_slice() {
        [x] => vec![*x; model.nv()],
        _ if vals.len() == model.nv() => vals,
        _ => {
            return Err(Error::Argument {
                name: "--armature".into(),
                reason: format!(
                    "{} values for a model with nv = {} (give one value, or nv values in \
                     velocity order)",
                    vals.len(),
                    model.nv()
                ),
            });
        }
    };
    model.with_armature(&a)
}

/// Loads a model from `spec` (`builtin:NAME`, a path ending in `.xml` for MJCF, otherwise a
/// URDF path) and prints the loader's warnings
/// ([`Model::warnings`]) on standard error, one `sodyn: warning: ...` line each.
fn load_model_spec(spec: &str, opts: &UrdfOptions) -> Result<Model> {
    let model = if let Some(name) = spec.strip_prefix("builtin:") {
        if opts.floating_base {
            return Err(Error::Argument {
                name: "--floating-base".into(),
                reason: format!(
                    "applies to URDF files; built-in model \"{name}\" defines its own base"
                ),
            });
        }
        sodyn::model::builtin::by_name(name)
            .ok_or_else(|| Error::Unknown { kind: "built-in model".into(), name: name.into() })?
    } else if is_mjcf(spec) {
        if opts.strict_inertia {
            return Err(Error::Argument {
                name: "--strict-inertia".into(),
                reason: format!(
                    "applies to URDF files; the MJCF loader refuses every non-physical inertia \
                     ({spec})"
                ),
            });
        }
        let mo = MjcfOptions { floating_base: opts.floating_base };
        sodyn::model::mjcf::load_mjcf_file(Path::new(spec), &mo)?
    } else {
        sodyn::model::urdf::load_urdf_file(Path::new(spec), opts)?
    };
    for w in model.warnings() {
        errln!("sodyn: warning: {}", out::cli_message(w));
    }
    Ok(model)
}

/// Whether a model path names an MJCF file (extension `.xml`, any case).
fn is_mjcf(spec: &str) -> bool {
    Path::new(spec).extension().is_some_and(|e| e.eq_ignore_ascii_case("xml"))
}

/// Prints `v` as one line of JSON to `path`, or to standard output.
fn write_output(path: Option<&str>, v: &Value) -> Result<()> {
    let text = serde_json::to_string(v).map_err(|e| Error::Io(e.to_string()))?;
    match path {
        Some(path) => {
            std::fs::write(path, text + "\n").map_err(|e| Error::Io(format!("{path}: {e}")))
        }
        None => {
            outln!("{text}");
            Ok(())
        }
    }
}

/// The joint table of a model as printed by `sodyn info`.
fn joint_table(model: &Model) -> String {
    let reduced = if model.is_reduced() {
        format!(
            " (reduced coordinates; full tree nq = {}, nv = {})",
            model.nq_full(),
            model.nv_full()
        )
    } else {
        String::new()
    };
    let nmimic = if model.is_reduced() {
        format!("; {} mimic", model.mimic_joints().len())
    } else {
        String::new()
    };
    let mut s = format!(
        "model \"{}\": nq = {}, nv = {}{reduced}, njoints = {} (the world joint 0 included, as \
         Pinocchio's njoints{nmimic}), {} frames\n",
        model.name(),
        model.nq(),
        model.nv(),
        model.njoints(),
        model.frames().len()
    );
    s += &format!(
        "{:>4}  {:<32} {:<11} {:<28} {:>5} {:>3} {:>5} {:>3}  {:>9}  mimic\n",
        "id", "name", "type", "parent", "idx_q", "nq", "idx_v", "nv", "mass"
    );
    for i in 1..model.njoints() {
        let p = model.parents()[i];
        let (iq, nq, iv, nv, mimic) = match model.reduced_idx(i) {
            Some((a, b)) => {
                let note = match (&model.mimic()[i], model.is_reduced()) {
                    (Some(m), false) => format!("mimics \"{m}\" (independent without --mimic)"),
                    _ => String::new(),
                };
                (a.to_string(), model.nqs()[i], b.to_string(), model.nvs()[i], note)
            }
            None => {
                // An eliminated joint: q = Σ c · q[term] + offset (a mimic joint: one term).
                let rule = match model.linear_couplings().iter().find(|c| c.joint == i) {
                    Some(c) => {
                        let mut r: Vec<String> = c
                            .terms
                            .iter()
                            .map(|&(j, x)| format!("{x} * q[\"{}\"]", model.names()[j]))
                            .collect();
                        r.push(c.offset.to_string());
                        format!("q = {}", r.join(" + "))
                    }
                    None => String::new(),
                };
                ("-".into(), 0, "-".into(), 0, rule)
            }
        };
        s += &format!(
            "{:>4}  {:<32} {:<11} {:<28} {:>5} {:>3} {:>5} {:>3}  {:>9.4}  {}\n",
            i,
            model.names()[i],
            model.joints()[i].name(),
            model.names()[p],
            iq,
            nq,
            iv,
            nv,
            model.inertias()[i].mass,
            mimic
        );
    }
    if model.has_armature() {
        let a: Vec<String> = model.armature().iter().map(|x| format!("{x}")).collect();
        let of = if model.is_reduced() { " of the full tree" } else { "" };
        s += &format!("armature (per velocity coordinate{of}): [{}]\n", a.join(", "));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }
}
