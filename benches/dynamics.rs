//! Criterion benchmarks of the dynamics and its derivatives on the shared robot models (or the
//! built-in ones when `../shared/models` is absent). One pre-generated state set per model, used
//! round robin, as `../shared/peer/pin_bench.cpp` does.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::DVector;
use sodyn::algo::{Data, aba, crba, rnea};
use sodyn::deriv::{fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};
use sodyn::model::{Model, builtin, urdf};
use sodyn::rng::Rng;
use std::hint::black_box;
use std::path::Path;

fn models() -> Vec<(String, Model)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/models");
    let table = [
        ("double_pendulum_continuous", false),
        ("ur5_robot", false),
        ("panda", false),
        ("solo12", true),
        ("hyq_no_sensors", true),
        ("anymal", true),
        ("talos_reduced", true),
        ("talos_full_v2", true),
    ];
    let mut out = vec![];
    if dir.is_dir() {
        for (name, ff) in table {
            let opts = urdf::UrdfOptions { floating_base: ff, strict_inertia: false, mimic: false };
            if let Ok(m) = urdf::load_urdf_file(&dir.join(format!("{name}.urdf")), &opts) {
                out.push((name.to_string(), m));
            }
        }
    } else {
        eprintln!("../shared/models not found: benchmarking built-in models");
        out.push(("quadruped".into(), builtin::quadruped()));
        out.push(("humanoid".into(), builtin::humanoid()));
    }
    out
}

struct States {
    q: Vec<DVector<f64>>,
    v: Vec<DVector<f64>>,
    a: Vec<DVector<f64>>,
    i: usize,
}

impl States {
    fn new(m: &Model, n: usize) -> Self {
        let mut rng = Rng::new(42);
        let mut s = States { q: vec![], v: vec![], a: vec![], i: 0 };
        for _ in 0..n {
            s.q.push(m.random_configuration(&mut rng));
            s.v.push(DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0)));
            s.a.push(DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0)));
        }
        s
    }
    fn next(&mut self) -> (&DVector<f64>, &DVector<f64>, &DVector<f64>) {
        self.i = (self.i + 1) % self.q.len();
        (&self.q[self.i], &self.v[self.i], &self.a[self.i])
    }
}

fn bench(c: &mut Criterion) {
    for (name, m) in models() {
        let mut g = c.benchmark_group(name.clone());
        let mut d = Data::with_second_order(&m);
        let mut st = States::new(&m, 100);
        g.bench_function("rnea", |b| {
            b.iter(|| {
                let (q, v, a) = st.next();
                black_box(rnea(&m, &mut d, q, v, a, None).unwrap());
            })
        });
        g.bench_function("crba", |b| {
            b.iter(|| {
                let (q, _, _) = st.next();
                black_box(crba(&m, &mut d, q).unwrap());
            })
        });
        g.bench_function("aba", |b| {
            b.iter(|| {
                let (q, v, a) = st.next();
                black_box(aba(&m, &mut d, q, v, a, None).unwrap());
            })
        });
        g.bench_function("id_fo", |b| {
            b.iter(|| {
                let (q, v, a) = st.next();
                id_derivatives(&m, &mut d, q, v, a, None).unwrap();
            })
        });
        g.bench_function("fd_fo", |b| {
            b.iter(|| {
                let (q, v, a) = st.next();
                fd_derivatives(&m, &mut d, q, v, a, None).unwrap();
            })
        });
        g.bench_function("id_so", |b| {
            b.iter(|| {
                let (q, v, a) = st.next();
                black_box(id_so_derivatives(&m, &mut d, q, v, a, None).unwrap());
            })
        });
        g.bench_function("fd_so", |b| {
            b.iter(|| {
                let (q, v, a) = st.next();
                black_box(fd_so_derivatives(&m, &mut d, q, v, a, None).unwrap());
            })
        });
        g.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).warm_up_time(std::time::Duration::from_millis(300)).measurement_time(std::time::Duration::from_secs(1));
    targets = bench
}
criterion_main!(benches);
