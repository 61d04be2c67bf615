//! The test problem shared by `no_alloc.rs` and `threads.rs`.

use serde_json::json;
use sodyn_ocp::StateMultibody;
use std::sync::Arc;

/// A quadruped on four 3-D contacts (every cost type the gaits use), an impulse knot after
/// `before` running knots and `after` more, and box bounds on the controls; the running knots
/// are Runge-Kutta (RK4) ones with `rk`, the terminal knot an Euler one.
pub fn quadruped_problem(
    m: &Arc<sodyn::model::Model>,
    rk: bool,
    before: usize,
    after: usize,
) -> String {
    let x0 = StateMultibody::new(m.clone()).zero();
    let feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
    let contacts: Vec<_> =
        feet.iter().map(|f| json!({"name": f, "frame": f, "kd": 30.0})).collect();
    let mut costs = vec![
        json!({"name": "x", "weight": 10.0, "residual": {"type": "state", "xref": x0.as_slice()}}),
        json!({"name": "u", "weight": 1e-3, "residual": {"type": "control", "uref": vec![0.0; 12]}}),
        json!({"name": "com", "weight": 1e3, "residual": {"type": "com_position", "cref": [0.05, 0.0, 0.0]}}),
        json!({"name": "foot", "weight": 1.0, "residual": {"type": "frame_placement", "frame": "LF_FOOT",
               "rotation": [1, 0, 0, 0, 1, 0, 0, 0, 1], "translation": [0.2, 0.1, -0.2]}}),
    ];
    for f in feet {
        costs.push(json!({"name": format!("{f}_cone"), "weight": 10.0,
            "residual": {"type": "contact_cone", "contact": f, "A": [[1.0, 0.0, -0.6], [0.0, 0.0, 1.0]]},
            "activation": {"type": "quad_barrier", "lb": ["-inf", 0.0], "ub": [0.0, "inf"]}}));
    }
    let run = json!({"type": "euler", "dt": 0.02, "actuation": "floating_base", "contacts": contacts,
        "costs": costs, "u_lb": vec![-30.0; 12], "u_ub": vec![30.0; 12]});
    let imp = json!({"type": "impulse", "contacts": contacts, "costs": [costs[0].clone()]});
    let mut body = run.clone();
    if rk {
        body["type"] = json!("rk4");
    }
    let mut running = vec![body.clone(); before];
    running.push(imp);
    running.extend(vec![body; after]);
    json!({"x0": x0.as_slice(), "running": running, "terminal": run}).to_string()
}
