//! DDP with sodyn's derivatives (issue 30): `cargo run --release --example ddp [-- --quick]
//! [--csv PATH]`. One small solver, three variants that differ only in the dynamics'
//! second-order term of the backward pass (cost Hessians are Gauss–Newton in all three):
//! * `ilqr`: `Q_xx = ℓ_xx + f_xᵀ V′_xx f_x` (same for `Q_ux`, `Q_uu`), Gauss–Newton;
//! * `ddp`: `+ V′_x · f_xx` from `fd_so_contracted` (no `nv³` tensor);
//! * `ddp_dense`: the same term from the dense tensors of `fd_so_derivatives`, contracted here.
//!
//! Tasks: a swing-up of `builtin::pendulum(2)`; a reach of the panda's hand to a point; the same
//! reach on tiago (nv 48), each from a cold start (the start pose's gravity torques held) and a
//! warm start (`_warm`: the first cold iLQR iterate within 1 % of iLQR's final cost). Exits 1
//! unless `ddp` and `ddp_dense` agree: second-order terms to 1e-10 (relative), same first step.
//!
//! Discrete dynamics (semi-implicit Euler), `a = FD(q, v, u)`, `u = τ`; every joint of these
//! models is 1-DoF (`nq == nv`, checked), so `q ⊕ δ = q + δ`:
//!     `v′ = v + dt a`,   `q′ = q + dt v′ = q + dt v + dt² a`.
//! First order, with `a_q`, `a_v` and `a_u = M⁻¹` from `fd_derivatives`:
//!     `f_x = [[I + dt² a_q, dt I + dt² a_v], [dt a_q, I + dt a_v]]`, `f_u = [[dt² M⁻¹], [dt M⁻¹]]`.
//! Second order: only `a` is nonlinear, and it enters `q′` with `dt²` and `v′` with `dt`, so
//!     `V′_x · f_xx = V′_q · ∂²q′ + V′_v · ∂²v′ = ∂²(wᵀa)`,   `w = dt² V′_q + dt V′_v`,
//! whose blocks `fd_so_contracted(w)` returns: `Q_xx += [[C_qq, C_qv], [C_qvᵀ, C_vv]]`,
//! `Q_ux[:, q] += C_τq`, and nothing for `Q_uu` or `Q_ux[:, v]` (`a` is affine in `τ`, and
//! `∂a/∂τ = M⁻¹(q)` does not depend on `v`).
use sodyn::algo::{Data, aba, nonlinear_effects, point_jacobian, point_position};
use sodyn::deriv::{ContractedData, FdSoData, fd_derivatives, fd_so_contracted, fd_so_derivatives};
use sodyn::model::{Model, UrdfOptions, builtin, load_urdf_file};
use sodyn::nalgebra::{DMatrix, DMatrixView, DVector, Matrix3xX, Vector3};
use sodyn::tensor::Tensor3;
use std::ops::AddAssign;
use std::time::Instant;

type V = DVector<f64>;
type M = DMatrix<f64>;

const VARIANTS: [&str; 3] = ["ilqr", "ddp", "ddp_dense"];

/// Cost `Σ dt (½ wq |q − q_ref|² + ½ wv |v|² + ½ r |u|²) + ½ Wq |q_T − q_ref|² + ½ Wv |v_T|²
/// + ½ Wp |p(q_T) − p*|²`, `w = [wq, wv, r, Wq, Wv]`; the last term for a reach (frame, p*, Wp).
struct Task {
    name: &'static str,
    model: Model,
    horizon: usize,
    dt: f64,
    q0: V,
    q_ref: V,
    w: [f64; 5],
    reach: Option<(usize, Vector3<f64>, f64)>,
}

impl Task {
    /// `reach`: (frame, offset of the target from the frame's start position).
    fn new(
        name: &'static str,
        model: Model,
        hd: (usize, f64),
        q0: V,
        q_ref: V,
        w: [f64; 5],
        reach: Option<(&str, [f64; 3])>,
    ) -> Task {
        let mut d = Data::new(&model);
        let reach = reach.map(|(frame, offset)| {
            let f = model.frame_id(frame).unwrap();
            let p0 = point_position(&model, &mut d, &q0, f, &Vector3::zeros()).unwrap();
            (f, p0 + Vector3::from(offset), 1e3)
        });
        Task { name, model, horizon: hd.0, dt: hd.1, q0, q_ref, w, reach }
    }
}

/// Workspaces; `t_so`: seconds in the second-order term; with `check`, a `ddp` backward pass
/// also contracts the dense tensors with its `w` and keeps the largest relative difference.
struct Ws {
    data: Data,
    cd: ContractedData,
    fso: FdSoData,
    jac: Matrix3xX<f64>,
    t_so: f64,
    check: Option<f64>,
}

/// States `q[0..=T]`, `v[0..=T]`, controls `u[0..T]` and the cost.
struct Traj {
    q: Vec<V>,
    v: Vec<V>,
    u: Vec<V>,
    cost: f64,
}

/// `(f_x, f_u)` at one knot, and for `ddp_dense` the four `∂²q̈` tensors (`qq, vv, qv, τq`).
type Lin = (M, M, Option<[Tensor3; 4]>);

/// Feed-forward `k`, feedback `K`, expected decrease `α dv[0] + α² dv[1]`.
struct Gains {
    k: Vec<V>,
    kk: Vec<M>,
    dv: [f64; 2],
}

/// Costs and controls of the iterates; `info`: backward passes, regularisation, timings.
struct Run {
    costs: Vec<f64>,
    iterates: Vec<Vec<V>>,
    converged: bool,
    ms_per_iter: f64,
    info: String,
}

/// `[a; b]`.
fn stack(a: &V, b: &V) -> V {
    V::from_iterator(a.len() + b.len(), a.iter().chain(b.iter()).copied())
}

/// The state part of the cost at one knot: value, `ℓ_x` and the Gauss–Newton `ℓ_xx` (reach:
/// `Wp JᵀJ`, the `Σ r_i ∇²p_i` term left out).
fn state_cost(task: &Task, ws: &mut Ws, q: &V, v: &V, terminal: bool) -> (f64, V, M) {
    let n = q.len();
    let (wq, wv, s) =
        if terminal { (task.w[3], task.w[4], 1.0) } else { (task.w[0], task.w[1], task.dt) };
    let e = q - &task.q_ref;
    let mut c = 0.5 * s * (wq * e.norm_squared() + wv * v.norm_squared());
    let mut lx = stack(&(s * wq * &e), &(s * wv * v));
    let mut lxx = M::from_diagonal(&stack(&V::repeat(n, s * wq), &V::repeat(n, s * wv)));
    if let (true, Some((frame, target, wp))) = (terminal, task.reach) {
        let (o, m) = (Vector3::zeros(), &task.model);
        let p = point_position(m, &mut ws.data, q, frame, &o).unwrap();
        point_jacobian(m, &mut ws.data, q, frame, &o, &mut ws.jac).unwrap();
        c += 0.5 * wp * (p - target).norm_squared();
        lx.rows_mut(0, n).add_assign(wp * ws.jac.tr_mul(&(p - target)));
        lxx.view_mut((0, 0), (n, n)).add_assign(wp * ws.jac.tr_mul(&ws.jac));
    }
    (c, lx, lxx)
}

/// Forward pass from `base.q[0]`: `u_i = U_i + α k_i + K_i (x_i − X_i)` with `gains`, or the
/// controls of `base` as they are. `None` if the state stops being finite.
fn rollout(task: &Task, ws: &mut Ws, base: &Traj, gains: Option<(&Gains, f64)>) -> Option<Traj> {
    let (dt, q, v) = (task.dt, vec![base.q[0].clone()], vec![base.v[0].clone()]);
    let mut t = Traj { q, v, u: vec![], cost: 0.0 };
    for i in 0..task.horizon {
        let mut u = base.u[i].clone();
        if let Some((g, alpha)) = gains {
            let dx = stack(&(&t.q[i] - &base.q[i]), &(&t.v[i] - &base.v[i]));
            u += alpha * &g.k[i] + &g.kk[i] * dx;
        }
        let a = aba(&task.model, &mut ws.data, &t.q[i], &t.v[i], &u, None).ok()?;
        let v1 = &t.v[i] + dt * a;
        let q1 = &t.q[i] + dt * &v1;
        if !v1.iter().chain(q1.iter()).all(|x| x.is_finite()) {
            return None;
        }
        t.cost += state_cost(task, ws, &t.q[i], &t.v[i], false).0
            + 0.5 * dt * task.w[2] * u.norm_squared();
        t.q.push(q1);
        t.v.push(v1);
        t.u.push(u);
    }
    t.cost += state_cost(task, ws, &t.q[task.horizon], &t.v[task.horizon], true).0;
    t.cost.is_finite().then_some(t)
}

/// `f_x`, `f_u` (module comment) at every knot; with `dense`, the `∂²q̈` tensors too (they do
/// not depend on `V′`: once per trajectory).
fn linearise(task: &Task, ws: &mut Ws, t: &Traj, dense: bool) -> Vec<Lin> {
    let (m, n, dt) = (&task.model, task.model.nv(), task.dt);
    let mut out = Vec::with_capacity(task.horizon);
    for i in 0..task.horizon {
        let (q, v, u) = (&t.q[i], &t.v[i], &t.u[i]);
        let dense = if dense {
            fd_so_derivatives(m, &mut ws.data, &mut ws.fso, q, v, u, None).unwrap();
            let f = &ws.fso;
            let d = [f.d2qdd_dq2(), f.d2qdd_dv2(), f.d2qdd_dqdv(), f.d2qdd_dtaudq()];
            Some(d.map(Tensor3::clone))
        } else {
            fd_derivatives(m, &mut ws.data, q, v, u, None).unwrap();
            None
        };
        let (aq, av, minv) = (ws.data.dqdd_dq(), ws.data.dqdd_dv(), ws.data.minv());
        let mut fx = M::identity(2 * n, 2 * n);
        fx.view_mut((0, n), (n, n)).fill_diagonal(dt);
        fx.view_mut((0, 0), (n, n)).add_assign(dt * dt * aq);
        fx.view_mut((0, n), (n, n)).add_assign(dt * dt * av);
        fx.view_mut((n, 0), (n, n)).add_assign(dt * aq);
        fx.view_mut((n, n), (n, n)).add_assign(dt * av);
        let mut fu = M::zeros(2 * n, n);
        fu.view_mut((0, 0), (n, n)).copy_from(&(dt * dt * minv));
        fu.view_mut((n, 0), (n, n)).copy_from(&(dt * minv));
        out.push((fx, fu, dense));
    }
    out
}

/// `C[(j, k)] = Σ_i w_i T[(i, j, k)]`: the tensor (`i` fastest) seen as an `n × n²` matrix, `Tᵀw`.
fn contract(t: &Tensor3, w: &V) -> M {
    let c = DMatrixView::from_slice(t.as_slice(), w.len(), w.len().pow(2)).tr_mul(w);
    M::from_column_slice(w.len(), w.len(), c.as_slice())
}

/// One backward pass with regularisation `μ I` on `Q_uu`; `None` when `Q_uu + μ I` is not
/// positive definite at some knot.
fn backward(task: &Task, ws: &mut Ws, t: &Traj, l: &[Lin], var: &str, mu: f64) -> Option<Gains> {
    let (m, n, dt, r, nt) = (&task.model, task.model.nv(), task.dt, task.w[2], task.horizon);
    let (_, mut vx, mut vxx) = state_cost(task, ws, &t.q[nt], &t.v[nt], true);
    let mut g = Gains { k: vec![V::zeros(n); nt], kk: vec![M::zeros(n, 2 * n); nt], dv: [0.0; 2] };
    for i in (0..nt).rev() {
        let (fx, fu, dense) = &l[i];
        let (_, lx, lxx) = state_cost(task, ws, &t.q[i], &t.v[i], false);
        let qx = lx + fx.tr_mul(&vx);
        let qu = dt * r * &t.u[i] + fu.tr_mul(&vx);
        let vxx_fx = &vxx * fx;
        let mut qxx = lxx + fx.tr_mul(&vxx_fx);
        let mut qux = fu.tr_mul(&vxx_fx);
        let quu = M::identity(n, n) * (dt * r) + fu.tr_mul(&(&vxx * fu));
        if var != "ilqr" {
            let w = dt * (dt * vx.rows(0, n) + vx.rows(n, n));
            let clock = Instant::now();
            let c = match (var, dense) {
                ("ddp_dense", Some(d)) => d.each_ref().map(|t| contract(t, &w)),
                _ => {
                    let (q, v, u) = (&t.q[i], &t.v[i], &t.u[i]);
                    fd_so_contracted(m, &mut ws.data, &mut ws.cd, q, v, u, &w).unwrap();
                    [ws.cd.c_qq(), ws.cd.c_vv(), ws.cd.c_qv(), ws.cd.c_tauq()].map(M::clone)
                }
            };
            ws.t_so += clock.elapsed().as_secs_f64();
            if let (Some(err), Some(d)) = (ws.check.as_mut(), dense) {
                let cd = d.each_ref().map(|t| contract(t, &w));
                let scale = cd.iter().map(|x| x.amax()).fold(f64::MIN_POSITIVE, f64::max);
                let diff = c.iter().zip(&cd).map(|(a, b)| (a - b).amax()).fold(0.0, f64::max);
                *err = err.max(diff / scale);
            }
            let [cqq, cvv, cqv, ctq] = c;
            qxx.view_mut((0, 0), (n, n)).add_assign(&cqq);
            qxx.view_mut((0, n), (n, n)).add_assign(&cqv);
            qxx.view_mut((n, 0), (n, n)).add_assign(cqv.transpose());
            qxx.view_mut((n, n), (n, n)).add_assign(&cvv);
            qux.view_mut((0, 0), (n, n)).add_assign(&ctq);
        }
        let chol = (&quu + M::identity(n, n) * mu).cholesky()?;
        let (k, kk) = (-chol.solve(&qu), -chol.solve(&qux));
        // The value update for any (regularised) gains (Tassa, Erez, Todorov 2012, eq. 11).
        vx = qx + kk.tr_mul(&(&quu * &k)) + kk.tr_mul(&qu) + qux.tr_mul(&k);
        let vxx1 = &qxx + kk.tr_mul(&(&quu * &kk)) + kk.tr_mul(&qux) + qux.tr_mul(&kk);
        vxx = 0.5 * (&vxx1 + vxx1.transpose());
        g.dv = [g.dv[0] + k.dot(&qu), g.dv[1] + 0.5 * k.dot(&(&quu * &k))];
        (g.k[i], g.kk[i]) = (k, kk);
    }
    Some(g)
}

fn start(task: &Task, ws: &mut Ws, u: &[V]) -> Traj {
    let (q, v) = (vec![task.q0.clone()], vec![V::zeros(task.model.nv())]);
    rollout(task, ws, &Traj { q, v, u: u.to_vec(), cost: 0.0 }, None).expect("initial rollout")
}

/// The largest relative difference between the `ddp` and `ddp_dense` terms over the first
/// backward pass at the initial trajectory (raising `μ` until the pass reaches the first knot).
fn check_terms(task: &Task, ws: &mut Ws, u: &[V]) -> f64 {
    let (t, mut mu) = (start(task, ws, u), 1e-6);
    let lin = linearise(task, ws, &t, true);
    ws.check = Some(0.0);
    while backward(task, ws, &t, &lin, "ddp", mu).is_none() {
        mu *= 1e3;
    }
    ws.check.take().unwrap()
}

/// DDP / iLQR from the controls `u`: regularisation by Tassa's schedule, a backtracking line
/// search accepting `actual decrease ≥ 1e-4 × expected`. Converged (as in Tassa's iLQG) when,
/// with `μ < 1e-5`, a full step is expected to lower the cost by less than `tol` (relative) or
/// an accepted step did.
fn solve(task: &Task, ws: &mut Ws, var: &str, u: &[V], iters: usize, tol: f64) -> Run {
    let clock = Instant::now();
    let mut t = start(task, ws, u);
    let (mut costs, mut iterates) = (vec![t.cost], vec![t.u.clone()]);
    let (mut mu, mut delta, mut converged, mut lin) = (1e-6, 1.0, false, None);
    // time: linearisations (s, count), complete backward passes (s, second-order term s, count).
    let (mut time, mut passes, mut max_mu) = ([0.0; 5], [0, 0], 0.0f64);
    while costs.len() <= iters && !converged && mu <= 1e10 {
        let (c0, new) = (Instant::now(), lin.is_none() as u8 as f64);
        let l = lin.get_or_insert_with(|| linearise(task, ws, &t, var == "ddp_dense"));
        (time[0], time[1], ws.t_so) = (time[0] + c0.elapsed().as_secs_f64(), time[1] + new, 0.0);
        let (c1, mut accepted) = (Instant::now(), None);
        if let Some(g) = backward(task, ws, &t, l, var, mu) {
            (time[2], time[3]) = (time[2] + c1.elapsed().as_secs_f64(), time[3] + ws.t_so);
            time[4] += 1.0;
            if -(g.dv[0] + g.dv[1]) < tol * t.cost && mu < 1e-5 {
                converged = true;
                break;
            }
            let expected = |a: f64| -(a * g.dv[0] + a * a * g.dv[1]);
            accepted = (0..12).map(|e| 0.5f64.powi(e)).find_map(|a| {
                rollout(task, ws, &t, Some((&g, a)))
                    .filter(|n| t.cost - n.cost >= 1e-4 * expected(a))
            });
        }
        passes[0] += 1;
        let Some(tn) = accepted else {
            // Not positive definite, or no step length lowered the cost: raise μ and retry.
            (passes[1], delta) = (passes[1] + 1, f64::max(2.0, delta * 2.0));
            (mu, max_mu) = (f64::max(1e-8, mu * delta), max_mu.max(mu * delta));
            continue;
        };
        converged = t.cost - tn.cost < tol * tn.cost && mu < 1e-5;
        delta = f64::min(0.5, delta / 2.0);
        mu = if mu * delta > 1e-8 { mu * delta } else { 0.0 };
        (t, lin) = (tn, None);
        costs.push(t.cost);
        iterates.push(t.u.clone());
    }
    let ms_per_iter = clock.elapsed().as_secs_f64() * 1e3 / (costs.len() - 1).max(1) as f64;
    let [l, b, s] = [time[0] / time[1], time[2] / time[4], time[3] / time[4]].map(|x| 1e3 * x);
    let ([p, f], nl) = (passes, time[1]);
    let info = format!(
        "{p} backward passes ({f} failed: Q_uu not PD or line search), largest mu {max_mu:.0e}; \
         ms per linearisation {l:.3} ({nl}), per complete backward pass {b:.3} (second-order term {s:.3})"
    );
    Run { costs, iterates, converged, ms_per_iter, info }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let csv_path = match args.iter().position(|a| a == "--csv") {
        Some(i) => args.get(i + 1).expect("--csv PATH").clone(),
        None => "target/ddp_costs.csv".to_string(),
    };
    let (iters, tol) = if quick { (40, 1e-6) } else { (500, 1e-8) };
    // Pendulum: from hanging at rest (q = 0) to upright at rest (q = (π, 0)) in 2 s.
    let hd = if quick { (50, 0.04) } else { (100, 0.02) };
    let up = V::from_vec(vec![std::f64::consts::PI, 0.0]);
    let w = [1.0, 0.1, 1e-2, 100.0, 10.0];
    let mut tasks =
        vec![Task::new("pendulum2_swingup", builtin::pendulum(2), hd, V::zeros(2), up, w, None)];
    // Reaches: the hand moves by a fixed offset in 1 s, from rest at the start pose.
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/models");
    if shared.is_dir() {
        let load = |f: &str| load_urdf_file(&shared.join(f), &UrdfOptions::default()).unwrap();
        let w = [1e-2, 0.1, 1e-3, 1e-2, 10.0];
        let q0 = V::from_vec(vec![0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.02, 0.02]);
        let hd = if quick { (40, 0.025) } else { (100, 0.01) };
        let reach = Some(("panda_hand", [0.1, 0.4, -0.2]));
        tasks.push(Task::new("panda_reach", load("panda.urdf"), hd, q0.clone(), q0, w, reach));
        let (tiago, hd) = (load("tiago.urdf"), if quick { (20, 0.05) } else { (50, 0.02) });
        let (q0, reach) = (tiago.neutral(), Some(("hand_palm_link", [0.4, 0.3, 0.2])));
        tasks.push(Task::new("tiago_reach", tiago, hd, q0.clone(), q0, w, reach));
    } else {
        println!("# note: {} is absent: the panda and tiago reaches are skipped", shared.display());
    }
    let mut csv = String::from("task,variant,iteration,cost\n");
    let mut ok = true;
    for task in &tasks {
        let (m, name) = (&task.model, task.name);
        assert_eq!(m.nq(), m.nv(), "{name}: the example's q ⊕ δ = q + δ needs 1-DoF joints");
        let (nv, nt, dt) = (m.nv(), task.horizon, task.dt);
        println!("# {name}: nq = nv = {nv} (1-DoF joints: q ⊕ δ = q + δ), {nt} steps of {dt} s");
        let (data, cd, fso) = (Data::new(m), ContractedData::new(m), FdSoData::new(m));
        let mut ws = Ws { data, cd, fso, jac: Matrix3xX::zeros(nv), t_so: 0.0, check: None };
        // The cold start: the gravity torques of the start pose, held (the arms stay still).
        let g = nonlinear_effects(m, &mut ws.data, &task.q0, &V::zeros(nv)).unwrap().clone();
        let cold = vec![g; nt];
        let err = check_terms(task, &mut ws, &cold);
        println!("# {name}: ddp vs ddp_dense terms, first backward pass: max rel. diff. {err:.1e}");
        ok &= err <= 1e-10;
        let mut start = (name.to_string(), cold);
        for warm in [false, true] {
            let (tname, u) = &start;
            let runs = VARIANTS.map(|v| solve(task, &mut ws, v, u, iters, tol));
            for (run, vname) in runs.iter().zip(VARIANTS) {
                let (n, c) = (run.costs.len() - 1, run.costs.last().unwrap());
                println!(
                    "task={tname} variant={vname} iterations={n} final_cost={c:.9e} ms_per_iter={:.3} converged={}",
                    run.ms_per_iter, run.converged
                );
                println!("#   {}", run.info);
                for (i, c) in run.costs.iter().enumerate() {
                    csv += &format!("{tname},{vname},{i},{c:.15e}\n");
                }
            }
            let (a, b) = (&runs[1].costs, &runs[2].costs);
            let same = a.len().min(2) == b.len().min(2)
                && (a.len() < 2 || (a[1] - b[1]).abs() <= 1e-9 * a[1]);
            println!("# {tname}: ddp and ddp_dense take the same first step: {same}");
            ok &= same;
            if !warm {
                let c = &runs[0].costs;
                let it =
                    c.iter().position(|&x| x - c[c.len() - 1] <= 0.01 * c[c.len() - 1]).unwrap();
                println!("# {name}_warm starts from cold iLQR iterate {it} (cost {:.6e})", c[it]);
                start = (format!("{name}_warm"), runs[0].iterates[it].clone());
            }
        }
    }
    std::fs::create_dir_all(std::path::Path::new(&csv_path).parent().unwrap()).ok();
    std::fs::write(&csv_path, csv).unwrap();
    println!("# wrote {csv_path}");
    if !ok {
        eprintln!("ddp and ddp_dense disagree (second-order terms or first step)");
        std::process::exit(1);
    }
}
