//! Workspace reuse (issue 32, item 6): every public algorithm, called in several orders and at
//! several states on ONE set of workspaces (a `Data` with second-order capacity, holding the
//! `SoData`, `FdSoData` and `ContractedData` results, and a `ContactData` with second-order
//! capacity, holding the `KktData`, `ImpactData`, `KktContracted` and `ImpactContracted`
//! results), gives bit for bit what it gives on fresh workspaces made with only the capacity
//! the call needs. A difference means state leaking from one call into the next. Also: the model
//! and the workspaces are `Send + Sync` (checked at compile time), and threads that share one
//! `&Model`, each with its own workspaces, reproduce the same bits.
//!
//! Models: a fixed-base random tree (no contacts), the built-in floating-base quadruped with
//! point contacts at its four feet and the built-in humanoid with contacts at its two soles.

use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::algo::{Contact, Data, aba, crba, forward_kinematics, nonlinear_effects, rnea};
use sodyn::deriv::{
    ContactData, ContractedData, FdSoData, ImpactContracted, ImpactData, KktContracted, KktData,
    SoData, constrained_id_derivatives, constrained_id_so_derivatives, fd_derivatives,
    fd_so_contracted, fd_so_derivatives, id_derivatives, id_so_contracted, id_so_derivatives,
    idfoza, idsoza, impact_derivatives, impact_dynamics, impact_so_contracted,
    impact_so_derivatives, kkt_derivatives, kkt_dynamics, kkt_so_contracted, kkt_so_derivatives,
};
use sodyn::model::{Model, builtin};
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;

// The model and every workspace can be shared between threads (`&T` sent to several) and sent
// to another thread.
const _: fn() = || {
    fn assert<T: Send + Sync>() {}
    assert::<Model>();
    assert::<Data>();
    assert::<SoData>();
    assert::<FdSoData>();
    assert::<ContractedData>();
    assert::<ContactData>();
    assert::<KktData>();
    assert::<ImpactData>();
    assert::<KktContracted>();
    assert::<ImpactContracted>();
    assert::<Contact>();
    assert::<Tensor3>();
};

/// A state and the extra inputs of the algorithms that take them.
struct State {
    q: DVector<f64>,
    v: DVector<f64>,
    a: DVector<f64>,
    tau: DVector<f64>,
    /// Weights of the contracted Hessians.
    w: DVector<f64>,
    /// The vector of IDFOZA / IDSOZA.
    x: DVector<f64>,
    /// Contact forces of constrained inverse dynamics (length `3 nc`).
    lambda: DVector<f64>,
    /// Weights of the contracted contact Hessians (length `3 nc`).
    w_c: DVector<f64>,
}

fn state(model: &Model, nc: usize, seed: u64) -> State {
    let mut rng = Rng::new(seed);
    let q = model.random_configuration(&mut rng);
    let mut r = |n: usize, s: f64| DVector::from_fn(n, |_, _| s * rng.range(-1.0, 1.0));
    let nv = model.nv();
    State {
        q,
        v: r(nv, 2.0),
        a: r(nv, 3.0),
        tau: r(nv, 5.0),
        w: r(nv, 1.0),
        x: r(nv, 1.0),
        lambda: r(3 * nc, 20.0),
        w_c: r(3 * nc, 1.0),
    }
}

/// Every public algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Algo {
    Fk,
    Rnea,
    Nle,
    Crba,
    Aba,
    IdFo,
    FdFo,
    IdSo,
    FdSo,
    Idfoza,
    Idsoza,
    IdSoC,
    FdSoC,
    CidFo,
    CidSo,
    KktDyn,
    Kkt,
    KktSo,
    ImpDyn,
    Imp,
    ImpSo,
    KktSoC,
    ImpSoC,
}

const NO_CONTACT: [Algo; 13] = [
    Algo::Fk,
    Algo::Rnea,
    Algo::Nle,
    Algo::Crba,
    Algo::Aba,
    Algo::IdFo,
    Algo::FdFo,
    Algo::IdSo,
    Algo::FdSo,
    Algo::Idfoza,
    Algo::Idsoza,
    Algo::IdSoC,
    Algo::FdSoC,
];

const CONTACT: [Algo; 10] = [
    Algo::CidFo,
    Algo::CidSo,
    Algo::KktDyn,
    Algo::Kkt,
    Algo::KktSo,
    Algo::ImpDyn,
    Algo::Imp,
    Algo::ImpSo,
    Algo::KktSoC,
    Algo::ImpSoC,
];

/// One set of workspaces.
struct Ws {
    /// With the capacity chosen when made (its second-order results live in it).
    data: Data,
    /// IDFOZA's output (filled with garbage when made: IDFOZA must overwrite all of it).
    out: DMatrix<f64>,
    /// With contacts only (the KKT, impact and constrained-ID results live in it).
    cd: Option<ContactData>,
}

const RESTITUTION: f64 = 0.4;

/// The second-order capacity of a workspace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Cap {
    FirstOrder,
    Contracted,
    SecondOrder,
}

impl Ws {
    /// Workspaces for `model` and `contacts`, `data` with capacity `data_cap` and the contact
    /// data with `cd_cap`.
    fn new(model: &Model, contacts: &[Contact], data_cap: Cap, cd_cap: Cap) -> Ws {
        let nv = model.nv();
        let cd = (!contacts.is_empty()).then(|| {
            let mut cd = match cd_cap {
                Cap::FirstOrder => ContactData::new(model, contacts),
                Cap::Contracted => ContactData::with_contracted(model, contacts),
                Cap::SecondOrder => ContactData::with_second_order(model, contacts),
            }
            .unwrap();
            cd.set_restitution(RESTITUTION).unwrap();
            cd
        });
        let data = match data_cap {
            Cap::FirstOrder => Data::new(model),
            Cap::Contracted => Data::with_contracted(model),
            Cap::SecondOrder => Data::with_second_order(model),
        };
        Ws { data, out: DMatrix::from_element(nv, nv, f64::NAN), cd }
    }

    /// The workspaces a user would make for this one call of `algo`: only the capacity it
    /// needs.
    fn fresh(model: &Model, contacts: &[Contact], algo: Algo) -> Ws {
        let data_cap = match algo {
            Algo::IdSo | Algo::FdSo | Algo::Idsoza | Algo::CidSo => Cap::SecondOrder,
            Algo::IdSoC | Algo::FdSoC => Cap::Contracted,
            _ => Cap::FirstOrder,
        };
        let cd_cap = match algo {
            Algo::KktSo | Algo::ImpSo => Cap::SecondOrder,
            Algo::KktSoC | Algo::ImpSoC => Cap::Contracted,
            _ => Cap::FirstOrder,
        };
        Ws::new(model, contacts, data_cap, cd_cap)
    }
}

/// The outputs of one call: named arrays of bits, or the error's message.
type Outputs = Result<Vec<(&'static str, Vec<u64>)>, String>;

fn bits(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

fn t3(t: &Tensor3) -> Vec<u64> {
    bits(t.as_slice())
}

/// Runs `algo` at `s` on `ws` and collects everything it documents as its output.
fn run(algo: Algo, model: &Model, ws: &mut Ws, s: &State) -> Outputs {
    let e = |e: sodyn::Error| e.to_string();
    let Ws { data, out, cd } = ws;
    let mut o: Vec<(&'static str, Vec<u64>)> = Vec::new();
    // The first-order ID outputs in `data` (id_derivatives and the algorithms that also fill
    // them).
    let id_fo = |data: &Data, o: &mut Vec<(&'static str, Vec<u64>)>| {
        o.push(("data.tau", bits(data.tau().as_slice())));
        o.push(("data.dtau_dq", bits(data.dtau_dq().as_slice())));
        o.push(("data.dtau_dv", bits(data.dtau_dv().as_slice())));
        o.push(("data.m", bits(data.m().as_slice())));
    };
    let fd_fo = |data: &Data, o: &mut Vec<(&'static str, Vec<u64>)>| {
        o.push(("data.qdd", bits(data.qdd().as_slice())));
        o.push(("data.dqdd_dq", bits(data.dqdd_dq().as_slice())));
        o.push(("data.dqdd_dv", bits(data.dqdd_dv().as_slice())));
        o.push(("data.minv", bits(data.minv().as_slice())));
    };
    let id_so = |so: &SoData, o: &mut Vec<(&'static str, Vec<u64>)>| {
        o.push(("so.d2tau_dq2", t3(so.d2tau_dq2())));
        o.push(("so.d2tau_dv2", t3(so.d2tau_dv2())));
        o.push(("so.d2tau_dqdv", t3(so.d2tau_dqdv())));
        o.push(("so.dm_dq", t3(so.dm_dq())));
    };
    let kkt_fo = |cd: &ContactData, o: &mut Vec<(&'static str, Vec<u64>)>| {
        o.push(("kkt.qdd", bits(cd.kkt().qdd().as_slice())));
        o.push(("kkt.lambda", bits(cd.kkt().lambda().as_slice())));
        o.push(("kkt.cd.jac", bits(cd.jac().as_slice())));
        o.push(("kkt.cd.drift", bits(cd.drift().as_slice())));
    };
    let imp_fo = |cd: &ContactData, o: &mut Vec<(&'static str, Vec<u64>)>| {
        o.push(("impact.vplus", bits(cd.impact().vplus().as_slice())));
        o.push(("impact.impulse", bits(cd.impact().impulse().as_slice())));
        o.push(("impact.cd.jac", bits(cd.jac().as_slice())));
    };
    match algo {
        Algo::Fk => {
            forward_kinematics(model, data, &s.q, Some(&s.v), Some(&s.a)).map_err(e)?;
            let flat = |x: &[sodyn::spatial::Transform]| {
                x.iter()
                    .flat_map(|t| t.rot.iter().chain(t.trans.iter()).map(|v| v.to_bits()))
                    .collect()
            };
            o.push(("data.o_m_i", flat(data.o_m_i())));
            o.push(("data.li_m_i", flat(data.li_m_i())));
            o.push((
                "data.v",
                data.v().iter().flat_map(|m| bits(m.to_vec6().as_slice())).collect(),
            ));
            o.push((
                "data.a",
                data.a().iter().flat_map(|m| bits(m.to_vec6().as_slice())).collect(),
            ));
        }
        Algo::Rnea => {
            let t = rnea(model, data, &s.q, &s.v, &s.a, None).map_err(e)?;
            o.push(("rnea", bits(t.as_slice())));
        }
        Algo::Nle => {
            let b = nonlinear_effects(model, data, &s.q, &s.v).map_err(e)?;
            o.push(("nle", bits(b.as_slice())));
        }
        Algo::Crba => {
            let m = crba(model, data, &s.q).map_err(e)?;
            o.push(("crba", bits(m.as_slice())));
        }
        Algo::Aba => {
            let qdd = aba(model, data, &s.q, &s.v, &s.tau, None).map_err(e)?;
            o.push(("aba", bits(qdd.as_slice())));
        }
        Algo::IdFo => {
            id_derivatives(model, data, &s.q, &s.v, &s.a, None).map_err(e)?;
            id_fo(data, &mut o);
        }
        Algo::FdFo => {
            fd_derivatives(model, data, &s.q, &s.v, &s.tau, None).map_err(e)?;
            fd_fo(data, &mut o);
        }
        Algo::IdSo => {
            id_so_derivatives(model, data, &s.q, &s.v, &s.a, None).map_err(e)?;
            id_fo(data, &mut o);
            id_so(data.id_so().unwrap(), &mut o);
        }
        Algo::FdSo => {
            let fso = fd_so_derivatives(model, data, &s.q, &s.v, &s.tau, None).map_err(e)?;
            o.push(("fso.d2qdd_dq2", t3(fso.d2qdd_dq2())));
            o.push(("fso.d2qdd_dv2", t3(fso.d2qdd_dv2())));
            o.push(("fso.d2qdd_dqdv", t3(fso.d2qdd_dqdv())));
            o.push(("fso.d2qdd_dtaudq", t3(fso.d2qdd_dtaudq())));
        }
        Algo::Idfoza => {
            idfoza(model, data, &s.q, &s.x, out).map_err(e)?;
            o.push(("idfoza", bits(out.as_slice())));
        }
        Algo::Idsoza => {
            let t = idsoza(model, data, &s.q, &s.x).map_err(e)?;
            o.push(("idsoza", t3(t)));
        }
        Algo::IdSoC => {
            let con = id_so_contracted(model, data, &s.q, &s.v, &s.a, &s.w).map_err(e)?;
            o.push(("con.c_qq", bits(con.c_qq().as_slice())));
            o.push(("con.c_vv", bits(con.c_vv().as_slice())));
            o.push(("con.c_qv", bits(con.c_qv().as_slice())));
            o.push(("con.c_mq", bits(con.c_mq().as_slice())));
        }
        Algo::FdSoC => {
            fd_so_contracted(model, data, &s.q, &s.v, &s.tau, &s.w).map_err(e)?;
            let con = data.contracted().unwrap();
            o.push(("con.c_qq", bits(con.c_qq().as_slice())));
            o.push(("con.c_vv", bits(con.c_vv().as_slice())));
            o.push(("con.c_qv", bits(con.c_qv().as_slice())));
            o.push(("con.c_tauq", bits(con.c_tauq().as_slice())));
            fd_fo(data, &mut o);
        }
        Algo::CidFo => {
            let cd = cd.as_mut().unwrap();
            constrained_id_derivatives(model, data, cd, &s.q, &s.v, &s.a, &s.lambda).map_err(e)?;
            id_fo(data, &mut o);
            o.push(("cd.jac", bits(cd.jac().as_slice())));
        }
        Algo::CidSo => {
            let cd = cd.as_mut().unwrap();
            constrained_id_so_derivatives(model, data, cd, &s.q, &s.v, &s.a, &s.lambda)
                .map_err(e)?;
            id_fo(data, &mut o);
            o.push(("cd.jac", bits(cd.jac().as_slice())));
            id_so(data.id_so().unwrap(), &mut o);
        }
        Algo::KktDyn => {
            let cd = cd.as_mut().unwrap();
            kkt_dynamics(model, data, cd, &s.q, &s.v, &s.tau).map_err(e)?;
            kkt_fo(cd, &mut o);
            o.push(("data.minv", bits(data.minv().as_slice())));
        }
        Algo::Kkt | Algo::KktSo | Algo::KktSoC => {
            let cd = cd.as_mut().unwrap();
            if algo == Algo::Kkt {
                kkt_derivatives(model, data, cd, &s.q, &s.v, &s.tau).map_err(e)?;
            } else if algo == Algo::KktSoC {
                let kc = kkt_so_contracted(model, data, cd, &s.q, &s.v, &s.tau, &s.w, &s.w_c)
                    .map_err(e)?;
                o.push(("kc.c_qq", bits(kc.c_qq().as_slice())));
                o.push(("kc.c_vv", bits(kc.c_vv().as_slice())));
                o.push(("kc.c_qv", bits(kc.c_qv().as_slice())));
                o.push(("kc.c_tauq", bits(kc.c_tauq().as_slice())));
            } else {
                kkt_so_derivatives(model, data, cd, &s.q, &s.v, &s.tau).map_err(e)?;
            }
            kkt_fo(cd, &mut o);
            let kd = cd.kkt();
            o.push(("kkt.dqdd_dq", bits(kd.dqdd_dq().as_slice())));
            o.push(("kkt.dqdd_dv", bits(kd.dqdd_dv().as_slice())));
            o.push(("kkt.dqdd_dtau", bits(kd.dqdd_dtau().as_slice())));
            o.push(("kkt.dlambda_dq", bits(kd.dlambda_dq().as_slice())));
            o.push(("kkt.dlambda_dv", bits(kd.dlambda_dv().as_slice())));
            o.push(("kkt.dlambda_dtau", bits(kd.dlambda_dtau().as_slice())));
            if algo == Algo::KktSo {
                let t = kd.so().unwrap();
                o.push(("kkt.so.d2qdd_dq2", t3(t.d2qdd_dq2())));
                o.push(("kkt.so.d2qdd_dv2", t3(t.d2qdd_dv2())));
                o.push(("kkt.so.d2qdd_dqdv", t3(t.d2qdd_dqdv())));
                o.push(("kkt.so.d2qdd_dtaudq", t3(t.d2qdd_dtaudq())));
                o.push(("kkt.so.d2lambda_dq2", t3(t.d2lambda_dq2())));
                o.push(("kkt.so.d2lambda_dv2", t3(t.d2lambda_dv2())));
                o.push(("kkt.so.d2lambda_dqdv", t3(t.d2lambda_dqdv())));
                o.push(("kkt.so.d2lambda_dtaudq", t3(t.d2lambda_dtaudq())));
            }
        }
        Algo::ImpDyn => {
            let cd = cd.as_mut().unwrap();
            impact_dynamics(model, data, cd, &s.q, &s.v).map_err(e)?;
            imp_fo(cd, &mut o);
        }
        Algo::Imp | Algo::ImpSo | Algo::ImpSoC => {
            let cd = cd.as_mut().unwrap();
            if algo == Algo::Imp {
                impact_derivatives(model, data, cd, &s.q, &s.v).map_err(e)?;
            } else if algo == Algo::ImpSoC {
                let ic =
                    impact_so_contracted(model, data, cd, &s.q, &s.v, &s.w, &s.w_c).map_err(e)?;
                o.push(("ic.c_qq", bits(ic.c_qq().as_slice())));
                o.push(("ic.c_qvminus", bits(ic.c_qvminus().as_slice())));
            } else {
                impact_so_derivatives(model, data, cd, &s.q, &s.v).map_err(e)?;
            }
            imp_fo(cd, &mut o);
            let im = cd.impact();
            o.push(("impact.dvplus_dq", bits(im.dvplus_dq().as_slice())));
            o.push(("impact.dvplus_dvminus", bits(im.dvplus_dvminus().as_slice())));
            o.push(("impact.dimpulse_dq", bits(im.dimpulse_dq().as_slice())));
            o.push(("impact.dimpulse_dvminus", bits(im.dimpulse_dvminus().as_slice())));
            if algo == Algo::ImpSo {
                let t = im.so().unwrap();
                o.push(("impact.so.d2vplus_dq2", t3(t.d2vplus_dq2())));
                o.push(("impact.so.d2vplus_dqdvminus", t3(t.d2vplus_dqdvminus())));
                o.push(("impact.so.d2impulse_dq2", t3(t.d2impulse_dq2())));
                o.push(("impact.so.d2impulse_dqdvminus", t3(t.d2impulse_dqdvminus())));
            }
        }
    }
    Ok(o)
}

/// The first difference between two outputs of the same call, or `None`.
fn diff(a: &Outputs, b: &Outputs) -> Option<String> {
    match (a, b) {
        (Ok(a), Ok(b)) => {
            assert_eq!(a.len(), b.len());
            for ((name, x), (_, y)) in a.iter().zip(b) {
                if x.len() != y.len() {
                    return Some(format!("{name}: length {} vs {}", x.len(), y.len()));
                }
                if let Some(k) = (0..x.len()).find(|&k| x[k] != y[k]) {
                    let n = (0..x.len()).filter(|&k| x[k] != y[k]).count();
                    return Some(format!(
                        "{name}[{k}] = {:e}, fresh {:e} ({n} of {} entries differ)",
                        f64::from_bits(x[k]),
                        f64::from_bits(y[k]),
                        x.len()
                    ));
                }
            }
            None
        }
        (Err(a), Err(b)) if a == b => None,
        _ => Some(format!("{:?} vs fresh {:?}", a.as_ref().err(), b.as_ref().err())),
    }
}

/// A model with its contacts, states, the algorithms that apply and their fresh results.
struct Case {
    name: &'static str,
    model: Model,
    contacts: Vec<Contact>,
    states: Vec<State>,
    algos: Vec<Algo>,
    /// `fresh[a][s]`: algorithm `algos[a]` at state `s` on fresh workspaces.
    fresh: Vec<Vec<Outputs>>,
}

impl Case {
    fn new(name: &'static str, model: Model, feet: &[&str]) -> Case {
        let contacts: Vec<Contact> =
            feet.iter().map(|f| Contact::new(&model, f, Vector3::zeros()).unwrap()).collect();
        let states: Vec<State> = (0..3).map(|k| state(&model, feet.len(), 100 + k)).collect();
        let mut algos = NO_CONTACT.to_vec();
        if !contacts.is_empty() {
            algos.extend(CONTACT);
        }
        let fresh: Vec<Vec<Outputs>> = algos
            .iter()
            .map(|&a| {
                states
                    .iter()
                    .map(|s| {
                        let mut ws = Ws::fresh(&model, &contacts, a);
                        let r = run(a, &model, &mut ws, s);
                        // Deterministic: the same call on fresh workspaces twice.
                        let mut ws2 = Ws::fresh(&model, &contacts, a);
                        assert!(diff(&r, &run(a, &model, &mut ws2, s)).is_none(), "{a:?}");
                        r
                    })
                    .collect()
            })
            .collect();
        // The test can see stale results: every output differs between two states.
        for (a, r) in algos.iter().zip(&fresh) {
            if let (Ok(x), Ok(y)) = (&r[0], &r[1]) {
                for ((name, x), (_, y)) in x.iter().zip(y) {
                    assert!(x != y, "{a:?}: {name} is the same at two states");
                }
            }
        }
        Case { name, model, contacts, states, algos, fresh }
    }

    /// Runs `calls` (algorithm index, state index) in order on one set of workspaces (with all
    /// the second-order capacity: every algorithm runs on it); returns the differences from the
    /// fresh results.
    fn replay(&self, order: &str, calls: &[(usize, usize)]) -> Vec<String> {
        let mut ws = Ws::new(&self.model, &self.contacts, Cap::SecondOrder, Cap::SecondOrder);
        let mut bad = Vec::new();
        for (n, &(a, s)) in calls.iter().enumerate() {
            let algo = self.algos[a];
            let r = run(algo, &self.model, &mut ws, &self.states[s]);
            if let Some(d) = diff(&r, &self.fresh[a][s]) {
                let prev = calls[..n]
                    .iter()
                    .rev()
                    .take(3)
                    .map(|&(a, s)| format!("{:?}@{s}", self.algos[a]))
                    .collect::<Vec<_>>()
                    .join(" <- ");
                bad.push(format!(
                    "{}, order {order}, call {n}: {algo:?} at state {s} after [{prev}]: {d}",
                    self.name
                ));
            }
        }
        bad
    }

    /// The orders: as listed, reversed, each algorithm twice in a row, and random sequences
    /// (with repeats) over the states.
    fn orders(&self) -> Vec<(String, Vec<(usize, usize)>)> {
        let n = self.algos.len();
        let ns = self.states.len();
        let mut orders = vec![
            ("listed".to_string(), (0..n).map(|a| (a, 0)).collect::<Vec<_>>()),
            ("reversed".to_string(), (0..n).rev().map(|a| (a, 1)).collect()),
            ("each twice".to_string(), (0..n).flat_map(|a| [(a, 2), (a, 2)]).collect()),
            (
                "listed, states interleaved".to_string(),
                (0..n).flat_map(|a| (0..ns).map(move |s| (a, s))).collect(),
            ),
        ];
        for seed in 0..6 {
            let mut rng = Rng::new(1000 + seed);
            let calls = (0..3 * n).map(|_| (rng.below(n), rng.below(ns))).collect();
            orders.push((format!("random {seed}"), calls));
        }
        // Every ordered pair (x then y), each at a state different from the previous call's.
        let pairs = (0..n)
            .flat_map(|x| (0..n).flat_map(move |y| [(x, (x + y) % ns), (y, (x + y + 1) % ns)]))
            .collect();
        orders.push(("all pairs".to_string(), pairs));
        orders
    }

    fn check(&self) {
        let mut bad = Vec::new();
        for (name, calls) in self.orders() {
            bad.extend(self.replay(&name, &calls));
        }
        let shown = bad.iter().take(40).cloned().collect::<Vec<_>>().join("\n");
        assert!(bad.is_empty(), "{} reused-workspace results differ:\n{shown}", bad.len());
    }
}

fn random_tree_case() -> Case {
    Case::new("random_tree(12, seed 7, fixed base)", builtin::random_tree(12, 7, false), &[])
}

fn quadruped_case() -> Case {
    Case::new(
        "quadruped, 4 feet",
        builtin::quadruped(),
        &["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"],
    )
}

fn humanoid_case() -> Case {
    Case::new("humanoid, 2 soles", builtin::humanoid(), &["left_sole", "right_sole"])
}

/// Every algorithm succeeds at the states of `c` on fresh workspaces.
fn all_ok(c: &Case) {
    for (a, r) in c.algos.iter().zip(&c.fresh) {
        assert!(r.iter().all(|x| x.is_ok()), "{}: {a:?}: {:?}", c.name, r[0].as_ref().err());
    }
}

#[test]
fn reuse_fixed_base_random_tree() {
    let c = random_tree_case();
    all_ok(&c);
    c.check();
}

#[test]
fn reuse_quadruped_with_contacts() {
    let c = quadruped_case();
    all_ok(&c);
    c.check();
}

/// A larger floating-base tree (nv = 38: the kernels for longer chains) with two foot contacts.
#[test]
fn reuse_humanoid_with_contacts() {
    let c = humanoid_case();
    all_ok(&c);
    c.check();
}

/// Threads sharing one `&Model` (and the fresh results), each with its own workspaces running
/// its own random order, reproduce the fresh bits.
#[test]
fn threads_share_the_model() {
    let c = quadruped_case();
    let bad: Vec<String> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..4)
            .map(|t| {
                let c = &c;
                scope.spawn(move || {
                    let n = c.algos.len();
                    let mut rng = Rng::new(5000 + t);
                    let calls: Vec<(usize, usize)> =
                        (0..2 * n).map(|_| (rng.below(n), rng.below(c.states.len()))).collect();
                    c.replay(&format!("thread {t}"), &calls)
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
