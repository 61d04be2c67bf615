//! Hot paths allocate nothing: after the workspaces are built, every algorithm runs without a
//! single heap allocation (counted by a wrapping global allocator).

use nalgebra::{DVector, Vector3};
use sodyn::algo::*;
use sodyn::deriv::*;
use sodyn::model::builtin;
use sodyn::rng::Rng;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        COUNT.with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        COUNT.with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations(f: impl FnOnce()) -> usize {
    let before = COUNT.with(|c| c.get());
    f();
    COUNT.with(|c| c.get()) - before
}

/// `tests/data/mimic_arm.urdf` with a floating base, in reduced coordinates.
fn reduced_arm() -> sodyn::model::Model {
    let path =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf");
    let opts = sodyn::model::UrdfOptions { floating_base: true, mimic: true, ..Default::default() };
    let m = sodyn::model::load_urdf_file(&path, &opts).unwrap();
    assert!(m.is_reduced());
    m
}

#[test]
fn algorithms_do_not_allocate() {
    use ContactReference::{Local, LocalWorldAligned as Lwa};
    use ContactType::{D3, D6};
    let feet = || vec!["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
    // (model, frames, type, reference, Baumgarte gains): 3-D world-aligned points, and the
    // generic rows of 6-D and local contacts with gains.
    for (m, frames, kind, reference, gains) in [
        (builtin::humanoid(), vec!["left_sole", "right_sole"], D3, Lwa, 0.0),
        (builtin::quadruped(), feet(), D3, Lwa, 0.0),
        (builtin::humanoid(), vec!["left_sole", "right_sole"], D6, Local, 2.0),
        (builtin::humanoid(), vec!["left_sole", "right_sole"], D6, Lwa, 2.0),
        (builtin::quadruped(), feet(), D3, Local, 2.0),
        // With an armature (on the free flyer too).
        (builtin::quadruped().with_armature(&[0.1; 18]).unwrap(), feet(), D3, Local, 2.0),
        // A model in reduced coordinates (mimic joints) through the same functions.
        (reduced_arm(), vec!["tool", "thumb_tip"], D3, Local, 2.0),
        // Two-frame (closed-loop) constraints, "A:B", mixed with a world contact.
        (builtin::quadruped(), vec!["LF_FOOT:RH_FOOT", "RF_FOOT"], D3, Lwa, 0.0),
        (builtin::quadruped(), vec!["LF_FOOT:RH_FOOT", "RF_FOOT"], D6, Local, 0.0),
        (
            builtin::delta(),
            vec![
                "forearm_tip_1:platform_1",
                "forearm_tip_2:platform_2",
                "forearm_tip_3:platform_3",
            ],
            D3,
            Lwa,
            0.0,
        ),
    ] {
        let mut rng = Rng::new(1);
        let q = m.random_configuration(&mut rng);
        let v = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let a = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let mut d = Data::with_second_order(&m);
        let contacts: Vec<Contact> = frames
            .iter()
            .map(|f| {
                let (a, b) = f.split_once(':').map_or((*f, None), |(a, b)| (a, Some(b)));
                let c = Contact::new(&m, a, Vector3::zeros()).unwrap().with_reference(reference);
                let c = Contact { kind, ..c.with_baumgarte(gains, gains).unwrap() };
                match b {
                    Some(b) => c.with_frame2(&m, b, None).unwrap(),
                    None => c,
                }
            })
            .collect();
        let mut cd = ContactData::with_second_order(&m, &contacts).unwrap();
        let lam = DVector::from_element(cd.dim(), 1.0);
        let mut jac = nalgebra::Matrix3xX::zeros(m.nv());
        // Each algorithm twice: the first call may touch lazily initialised state.
        let mut report = vec![];
        let mut check = |name: &str, f: &mut dyn FnMut()| {
            f();
            let n = allocations(f);
            if n > 0 {
                report.push(format!("{name}: {n}"));
            }
        };
        let zero = Vector3::zeros();
        check("rnea", &mut || {
            rnea(&m, &mut d, &q, &v, &a, None).unwrap();
        });
        check("nonlinear_effects", &mut || {
            nonlinear_effects(&m, &mut d, &q, &v).unwrap();
        });
        check("crba", &mut || {
            crba(&m, &mut d, &q).unwrap();
        });
        // The tree-sparse factorisation is the full tree's only.
        if !m.is_reduced() {
            check("factorize_ltl", &mut || factorize_ltl(&m, &mut d).unwrap());
        }
        check("aba", &mut || {
            aba(&m, &mut d, &q, &v, &a, None).unwrap();
        });
        check("point_jacobian", &mut || {
            point_jacobian(&m, &mut d, &q, contacts[0].frame, &zero, &mut jac).unwrap()
        });
        check("point_drift", &mut || {
            point_drift(&m, &mut d, &q, &v, contacts[0].frame, &zero).unwrap();
        });
        check("id_fo", &mut || id_derivatives(&m, &mut d, &q, &v, &a, None).unwrap());
        check("fd_fo", &mut || fd_derivatives(&m, &mut d, &q, &v, &a, None).unwrap());
        check("id_so", &mut || {
            id_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
        });
        check("fd_so", &mut || {
            fd_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
        });
        check("constrained_id", &mut || {
            constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap()
        });
        check("kkt_fo", &mut || {
            kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &a).unwrap();
        });
        check("kkt_so", &mut || {
            kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a).unwrap();
        });
        check("impact_fo", &mut || {
            impact_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap();
        });
        check("impact_so", &mut || {
            impact_so_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap();
        });
        let w = DVector::from_fn(m.nv(), |i, _| 1.0 / (1.0 + i as f64));
        let wl = DVector::from_element(cd.dim(), 0.5);
        check("id_so_contracted", &mut || {
            id_so_contracted(&m, &mut d, &q, &v, &a, &w).unwrap();
        });
        check("fd_so_contracted", &mut || {
            fd_so_contracted(&m, &mut d, &q, &v, &a, &w).unwrap();
        });
        // The contracted second order on a contact set made with only that capacity.
        let mut cdc = ContactData::with_contracted(&m, &contacts).unwrap();
        check("kkt_so_contracted", &mut || {
            kkt_so_contracted(&m, &mut d, &mut cdc, &q, &v, &a, &w, &wl).unwrap();
        });
        check("impact_so_contracted", &mut || {
            impact_so_contracted(&m, &mut d, &mut cdc, &q, &v, &w, &wl).unwrap();
        });
        // Kinematics for costs: frames, centre of mass, centroidal momentum, configuration space.
        let f = m.frame_id(frames[0].split(':').next().unwrap_or_default()).unwrap();
        let mut j6 = nalgebra::Matrix6xX::zeros(m.nv());
        let (mut j6b, mut j6c) = (j6.clone(), j6.clone());
        for rf in [ReferenceFrame::Local, ReferenceFrame::World, ReferenceFrame::LocalWorldAligned]
        {
            check("frame_placement", &mut || {
                frame_placement(&m, &mut d, &q, f).unwrap();
            });
            check("frame_jacobian", &mut || {
                frame_jacobian(&m, &mut d, &q, f, rf, &mut j6).unwrap()
            });
            check("frame_velocity", &mut || {
                frame_velocity(&m, &mut d, &q, &v, f, rf).unwrap();
            });
            check("frame_classical_acceleration", &mut || {
                frame_classical_acceleration(&m, &mut d, &q, &v, &a, f, rf).unwrap();
            });
            check("frame_velocity_derivatives", &mut || {
                frame_velocity_derivatives(&m, &mut d, &q, &v, f, rf, &mut j6, &mut j6b).unwrap()
            });
            check("frame_acceleration_derivatives", &mut || {
                frame_acceleration_derivatives(
                    &m, &mut d, &q, &v, &a, f, rf, &mut j6, &mut j6b, &mut j6c,
                )
                .unwrap()
            });
        }
        check("center_of_mass_motion", &mut || {
            center_of_mass_motion(&m, &mut d, &q, &v, Some(&a)).unwrap();
        });
        check("center_of_mass_jacobian", &mut || {
            center_of_mass_jacobian(&m, &mut d, &q, &mut jac).unwrap()
        });
        check("center_of_mass_velocity_derivatives", &mut || {
            center_of_mass_velocity_derivatives(&m, &mut d, &q, &v, &mut jac).unwrap()
        });
        let mut jd = nalgebra::DMatrix::zeros(m.nv(), m.nv());
        let q1 = m.integrate(&q, &v).unwrap();
        for arg in [sodyn::model::Arg::First, sodyn::model::Arg::Second] {
            check("d_integrate_into", &mut || m.d_integrate_into(&q, &v, arg, &mut jd).unwrap());
            check("d_difference_into", &mut || m.d_difference_into(&q, &q1, arg, &mut jd).unwrap());
        }
        check("centroidal_dynamics_derivatives", &mut || {
            centroidal_dynamics_derivatives(&m, &mut d, &q, &v, &a).unwrap();
        });
        assert!(
            report.is_empty(),
            "{}: heap allocations in hot paths: {}",
            m.name(),
            report.join(", ")
        );
    }
}

#[test]
fn reduced_model_algorithms_do_not_allocate() {
    let m = reduced_arm();
    let mut rng = Rng::new(2);
    let q = m.random_configuration(&mut rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let a = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let mut d = Data::with_second_order(&m);
    let mut report = vec![];
    let mut check = |name: &str, f: &mut dyn FnMut()| {
        f(); // warm-up
        let n = allocations(f);
        if n > 0 {
            report.push(format!("{name}: {n}"));
        }
    };
    check("reduced: rnea", &mut || {
        rnea(&m, &mut d, &q, &v, &a, None).unwrap();
    });
    check("reduced: nonlinear_effects", &mut || {
        nonlinear_effects(&m, &mut d, &q, &v).unwrap();
    });
    let fext = vec![
        sodyn::spatial::Force::new(Vector3::new(0.1, -0.2, 0.3), Vector3::zeros());
        m.full_tree().njoints()
    ];
    check("reduced: rnea (fext)", &mut || {
        rnea(&m, &mut d, &q, &v, &a, Some(&fext)).unwrap();
    });
    check("reduced: aba (fext)", &mut || {
        aba(&m, &mut d, &q, &v, &a, Some(&fext)).unwrap();
    });
    check("reduced: crba", &mut || {
        crba(&m, &mut d, &q).unwrap();
    });
    check("reduced: aba", &mut || {
        aba(&m, &mut d, &q, &v, &a, None).unwrap();
    });
    check("reduced: id_derivatives", &mut || id_derivatives(&m, &mut d, &q, &v, &a, None).unwrap());
    check("reduced: fd_derivatives", &mut || fd_derivatives(&m, &mut d, &q, &v, &a, None).unwrap());
    check("reduced: id_so_derivatives", &mut || {
        id_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
    });
    check("reduced: fd_so_derivatives", &mut || {
        fd_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
    });
    let full = m.full_tree();
    let p = nalgebra::Vector3::new(0.0, 0.0, 0.02);
    let contacts = vec![
        Contact::new(full, "tool", p).unwrap(),
        Contact::new(full, "finger_r", p).unwrap().with_baumgarte(1.0, 0.5).unwrap(),
    ];
    let mut cd = ContactData::new(&m, &contacts).unwrap();
    let lam = DVector::from_element(cd.dim(), 0.5);
    check("reduced: kkt_dynamics", &mut || {
        kkt_dynamics(&m, &mut d, &mut cd, &q, &v, &a).unwrap();
    });
    check("reduced: kkt_derivatives", &mut || {
        kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &a).unwrap();
    });
    let mut cd2 = ContactData::with_second_order(&m, &contacts).unwrap();
    check("reduced: kkt_so_derivatives", &mut || {
        kkt_so_derivatives(&m, &mut d, &mut cd2, &q, &v, &a).unwrap();
    });
    cd.set_restitution(0.3).unwrap();
    check("reduced: impact_dynamics", &mut || {
        impact_dynamics(&m, &mut d, &mut cd, &q, &v).unwrap();
    });
    check("reduced: impact_derivatives", &mut || {
        impact_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap();
    });
    cd2.set_restitution(0.3).unwrap();
    check("reduced: impact_so_derivatives", &mut || {
        impact_so_derivatives(&m, &mut d, &mut cd2, &q, &v).unwrap();
    });
    check("reduced: id_so_contracted", &mut || {
        id_so_contracted(&m, &mut d, &q, &v, &a, &v).unwrap();
    });
    check("reduced: fd_so_contracted", &mut || {
        fd_so_contracted(&m, &mut d, &q, &v, &a, &v).unwrap();
    });
    let mut xo = nalgebra::DMatrix::zeros(m.nv(), m.nv());
    check("reduced: idfoza", &mut || idfoza(&m, &mut d, &q, &a, &mut xo).unwrap());
    check("reduced: idsoza", &mut || {
        idsoza(&m, &mut d, &q, &a).unwrap();
    });
    // The contracted KKT and impact second order, with these contacts (3-D world points, one
    // with Baumgarte gains) and with a 6-D local contact (the generic path).
    let six = vec![
        Contact::new(full, "tool", p).unwrap(),
        Contact {
            kind: sodyn::model::ContactType::D6,
            ..Contact::new(full, "thumb_tip", p)
                .unwrap()
                .with_reference(sodyn::model::ContactReference::Local)
                .with_baumgarte(3.0, 0.5)
                .unwrap()
        },
    ];
    for (set, cs) in [("3-D", &contacts), ("6-D", &six)] {
        let mut cd3 = ContactData::with_contracted(&m, cs).unwrap();
        let wl = DVector::from_element(cd3.dim(), 0.5);
        check(&format!("reduced: kkt_so_contracted ({set})"), &mut || {
            kkt_so_contracted(&m, &mut d, &mut cd3, &q, &v, &a, &v, &wl).unwrap();
        });
        cd3.set_restitution(0.3).unwrap();
        check(&format!("reduced: impact_so_contracted ({set})"), &mut || {
            impact_so_contracted(&m, &mut d, &mut cd3, &q, &v, &a, &wl).unwrap();
        });
    }
    check("reduced: constrained_id_derivatives", &mut || {
        constrained_id_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
    });
    check("reduced: constrained_id_derivatives", &mut || {
        constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap()
    });
    let rf = sodyn::algo::ReferenceFrame::LocalWorldAligned;
    let fr = m.frames().len() - 1;
    let mut j6 = [
        nalgebra::Matrix6xX::zeros(m.nv()),
        nalgebra::Matrix6xX::zeros(m.nv()),
        nalgebra::Matrix6xX::zeros(m.nv()),
    ];
    let mut j3 = nalgebra::Matrix3xX::zeros(m.nv());
    check("reduced: frame_placement", &mut || {
        frame_placement(&m, &mut d, &q, fr).unwrap();
    });
    check("reduced: frame_jacobian", &mut || {
        frame_jacobian(&m, &mut d, &q, fr, rf, &mut j6[0]).unwrap()
    });
    check("reduced: frame_classical_acceleration", &mut || {
        frame_classical_acceleration(&m, &mut d, &q, &v, &a, fr, rf).unwrap();
    });
    check("reduced: frame_velocity_derivatives", &mut || {
        let [x, y, _] = &mut j6;
        frame_velocity_derivatives(&m, &mut d, &q, &v, fr, rf, x, y).unwrap()
    });
    check("reduced: frame_acceleration_derivatives", &mut || {
        let [x, y, z] = &mut j6;
        frame_acceleration_derivatives(&m, &mut d, &q, &v, &a, fr, rf, x, y, z).unwrap()
    });
    check("reduced: center_of_mass_jacobian", &mut || {
        center_of_mass_jacobian(&m, &mut d, &q, &mut j3).unwrap()
    });
    let mut sq = nalgebra::DMatrix::zeros(m.nv(), m.nv());
    let q1 = m.random_configuration(&mut Rng::new(3));
    check("Model::d_integrate_into (reduced)", &mut || {
        m.d_integrate_into(&q, &v, sodyn::model::Arg::First, &mut sq).unwrap()
    });
    check("Model::d_difference_into (reduced)", &mut || {
        m.d_difference_into(&q, &q1, sodyn::model::Arg::Second, &mut sq).unwrap()
    });
    check("reduced: center_of_mass_motion", &mut || {
        center_of_mass_motion(&m, &mut d, &q, &v, Some(&a)).unwrap();
    });
    check("reduced: center_of_mass_velocity_derivatives", &mut || {
        center_of_mass_velocity_derivatives(&m, &mut d, &q, &v, &mut j3).unwrap()
    });
    let mut t6 = sodyn::tensor::Tensor3::zeros(6, m.nv(), m.nv());
    check("reduced: frame_jacobian_derivative", &mut || {
        frame_jacobian_derivative(&m, &mut d, &q, fr, rf, &mut t6).unwrap()
    });
    let mut t6w = t6.clone();
    check("reduced: frame_placement_hessian", &mut || {
        frame_placement_hessian(&m, &mut d, &q, fr, &mut t6, &mut t6w).unwrap()
    });
    check("reduced: centroidal_dynamics_derivatives", &mut || {
        centroidal_dynamics_derivatives(&m, &mut d, &q, &v, &a).unwrap();
    });
    assert!(
        report.is_empty(),
        "heap allocations in the hot paths of a reduced model: {}",
        report.join(", ")
    );
}

/// The point kinematics and centroidal momentum of a model in reduced coordinates (mimic
/// joints), and its batched functions on
/// a one-thread pool (the caller alone: no thread hand-off), allocate nothing.
#[test]
fn reduced_model_kinematics_and_batches_do_not_allocate() {
    use nalgebra::{DMatrix, Matrix3xX};
    use sodyn::batch::BatchPool;
    use sodyn::batch::{self, BatchData};
    use std::sync::Arc;
    let m = reduced_arm();
    let mut rng = Rng::new(5);
    let n = 6;
    let qs: Vec<_> = (0..n).map(|_| m.random_configuration(&mut rng)).collect();
    let mut r = || DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let vs: Vec<_> = (0..n).map(|_| r()).collect();
    let xs: Vec<_> = (0..n).map(|_| r()).collect();
    let (q, v, a) = (&qs[0], &vs[0], &xs[0]);
    let mut d = Data::new(&m);
    let fr = m.frames().len() - 1;
    let p = Vector3::new(0.01, 0.02, 0.03);
    let mut j3 = Matrix3xX::zeros(m.nv());
    let pool = Arc::new(BatchPool::new(1).unwrap());
    let mut bd = BatchData::from_workspace(pool, Data::with_second_order(&m));
    let mut out_v = vec![DVector::zeros(m.nv()); n];
    let mut out_m1 = vec![DMatrix::zeros(m.nv(), m.nv()); n];
    let mut out_m2 = out_m1.clone();
    let mut out_so = vec![batch::IdSoResult::zeros(&m); n];
    let mut out_fso = vec![batch::FdSoResult::zeros(&m); n];
    let mut report = vec![];
    let mut check = |name: &str, f: &mut dyn FnMut()| {
        f(); // warm-up
        let n = allocations(f);
        if n > 0 {
            report.push(format!("{name}: {n}"));
        }
    };
    check("reduced: forward_kinematics", &mut || {
        forward_kinematics(&m, &mut d, q, Some(v), Some(a)).unwrap()
    });
    check("reduced: point_position", &mut || {
        point_position(&m, &mut d, q, fr, &p).unwrap();
    });
    check("reduced: point_jacobian", &mut || {
        point_jacobian(&m, &mut d, q, fr, &p, &mut j3).unwrap()
    });
    check("reduced: point_drift", &mut || {
        point_drift(&m, &mut d, q, v, fr, &p).unwrap();
    });
    check("reduced: centroidal_momentum", &mut || {
        centroidal_momentum(&m, &mut d, q, v).unwrap();
    });
    check("reduced: batch::rnea_batch", &mut || {
        batch::rnea_batch(&m, &mut bd, &qs, &vs, &xs, &mut out_v).unwrap()
    });
    check("reduced: batch::crba_batch", &mut || {
        batch::crba_batch(&m, &mut bd, &qs, &mut out_m1).unwrap()
    });
    check("reduced: batch::aba_batch", &mut || {
        batch::aba_batch(&m, &mut bd, &qs, &vs, &xs, &mut out_v).unwrap()
    });
    check("reduced: batch::id_derivatives_batch", &mut || {
        batch::id_derivatives_batch(&m, &mut bd, &qs, &vs, &xs, &mut out_m1, &mut out_m2).unwrap()
    });
    check("reduced: batch::fd_derivatives_batch", &mut || {
        batch::fd_derivatives_batch(&m, &mut bd, &qs, &vs, &xs, &mut out_m1, &mut out_m2).unwrap()
    });
    check("reduced: batch::id_so_derivatives_batch", &mut || {
        batch::id_so_derivatives_batch(&m, &mut bd, &qs, &vs, &xs, &mut out_so).unwrap()
    });
    check("reduced: batch::fd_so_derivatives_batch", &mut || {
        batch::fd_so_derivatives_batch(&m, &mut bd, &qs, &vs, &xs, &mut out_fso).unwrap()
    });
    assert!(
        report.is_empty(),
        "heap allocations in the hot paths of a reduced model: {}",
        report.join(", ")
    );
}
