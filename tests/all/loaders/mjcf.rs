//! MJCF loading without Python: what the test models parse to, the coordinate conventions that
//! the MuJoCo comparison (`python/tests/test_mjcf.py`) does not show, and bad input (an error
//! naming the file, line and element, never a panic).

use nalgebra::{DVector, Vector3};
use sodyn::algo::{Data, crba, frame_placement, rnea};
use sodyn::error::Error;
use sodyn::model::{JointType, MjcfOptions, Model, load_mjcf_file, load_mjcf_str};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mjcf")
}

fn load_str(xml: &str) -> sodyn::error::Result<Model> {
    load_mjcf_str(xml, "test.xml", &data_dir(), &MjcfOptions::default())
}

/// The error of loading `xml`, as `(line, element, reason)`.
fn error_of(xml: &str) -> (Option<u32>, String, String) {
    match load_str(xml) {
        Ok(_) => panic!("loaded, expected an error:\n{xml}"),
        Err(Error::Model { file, line, element, reason }) => {
            assert_eq!(file, "test.xml");
            (line, element, reason)
        }
        Err(e) => panic!("not a model error: {e}"),
    }
}

fn wrap(body: &str) -> String {
    format!("<mujoco>\n<worldbody>\n{body}\n</worldbody>\n</mujoco>")
}

#[test]
fn features_model_structure() {
    let m = Model::from_mjcf(data_dir().join("features.xml")).unwrap();
    assert_eq!(m.name(), "features");
    assert_eq!((m.nq(), m.nv()), (22, 20));
    let names: Vec<&str> = m.names()[1..].iter().map(String::as_str).collect();
    assert_eq!(
        names,
        [
            "root",
            "shoulder_y",
            "shoulder_x",
            "elbow",
            "neck",
            "neck_slide",
            "hip_x",
            "hip_y",
            "hip_slide",
            "knee",
            "joint10",
            "joint11",
            "swing"
        ]
    );
    let kinds: Vec<&str> = m.joints()[1..].iter().map(|j| j.name()).collect();
    assert_eq!(kinds[0], "free_flyer");
    assert_eq!(kinds[4], "spherical");
    assert_eq!(kinds[5], "prismatic");
    assert_eq!(kinds[1], "revolute");
    // The free joint hangs from the world at the identity; the second tree too.
    assert_eq!(m.parents()[1], 0);
    assert_eq!(m.parents()[13], 0);
    // Axes are unit vectors in the joint frame (the class "elbow" sets 1 0 0).
    assert_eq!(m.joints()[4], JointType::Revolute { axis: Vector3::x() });
    let a = Vector3::new(1.0, 0.0, 0.2).normalize();
    match m.joints()[3] {
        JointType::Revolute { axis } => assert!((axis - a).norm() < 1e-15),
        other => panic!("{other:?}"),
    }
    // Limits in radians (degrees in the file), from range with autolimits.
    let qi = m.idx_q()[2];
    assert!((m.lower()[qi] + PI / 2.0).abs() < 1e-15 && (m.upper()[qi] - PI / 2.0).abs() < 1e-15);
    assert!(m.lower()[m.idx_q()[3]].is_infinite(), "shoulder_x has no range");
    // Frames: named bodies and sites.
    for f in ["torso", "hand", "palm", "pedestal", "pedestal_top", "torso_site", "pendulum"] {
        m.frame_id(f).unwrap();
    }
    // The hand is welded to the forearm (joint "elbow").
    assert_eq!(m.frames()[m.frame_id("hand").unwrap()].joint, 4);
    // The armature of a free joint warns, naming the joint and line; damping and stiffness
    // are silent.
    assert_eq!(m.warnings().len(), 1, "{:?}", m.warnings());
    assert!(m.warnings()[0].contains("features.xml:"));
    assert!(m.warnings()[0].contains("joint \"root\": armature=\"0.03\" on a free joint"));
    // Armature: explicit, from the class defaults (limb 0.02, elbow 0, the main class 0.005),
    // on every DoF of the joint.
    let arm = |j: &str| {
        let i = m.joint_id(j).unwrap();
        m.armature()[m.idx_v()[i]..m.idx_v()[i] + m.nvs()[i]].to_vec()
    };
    assert_eq!(arm("root"), vec![0.03; 6]);
    assert_eq!(arm("shoulder_y"), vec![0.02]);
    assert_eq!(arm("elbow"), vec![0.0]);
    assert_eq!(arm("neck"), vec![0.02; 3]);
    assert_eq!(arm("hip_x"), vec![0.005]);
    assert_eq!(arm("swing"), vec![0.01]);
    assert!(m.has_armature());
    // Gravity from <option>.
    assert_eq!(m.gravity().lin, Vector3::new(0.5, -0.3, -9.7));
}

/// Masses of geoms by hand: defaults (density 1100 from the main class) and fromto.
#[test]
fn geom_masses_by_hand() {
    let m = Model::from_mjcf(data_dir().join("features.xml")).unwrap();
    let swing = m.joint_id("swing").unwrap();
    let cyl = 2700.0 * PI * 0.02f64.powi(2) * 0.5;
    let sphere = 1100.0 * 4.0 / 3.0 * PI * 0.05f64.powi(3);
    let got = m.inertias()[swing].mass;
    assert!((got - (cyl + sphere)).abs() < 1e-12 * got, "{got}");
    // The head's <inertial> (fullinertia): mass 1.2.
    let neck_slide = m.joint_id("neck_slide").unwrap();
    assert!((m.inertias()[neck_slide].mass - 1.2).abs() < 1e-15);
    // The intermediate joint of a multi-joint body is massless.
    assert_eq!(m.inertias()[m.joint_id("neck").unwrap()].mass, 0.0);
}

/// `ref` is folded into the placement: q = ref gives the pose written in the file, and a
/// joint `pos` is the point the body rotates about.
#[test]
fn hinge_ref_and_pos() {
    let with = |r: &str, pos: &str| {
        wrap(&format!(
            r#"<body name="b" pos="0 0 1"><joint name="j" axis="0 1 0" pos="{pos}" ref="{r}"/>
               <geom size="0.1"/><site name="s" pos="0.3 0 0"/></body>"#
        ))
    };
    let m0 = load_str(&with("0", "0 0 0")).unwrap();
    let m1 = load_str(&with("30", "0 0 0")).unwrap();
    let s = m0.frame_id("s").unwrap();
    let (mut d0, mut d1) = (Data::new(&m0), Data::new(&m1));
    for x in [-0.4, 0.0, 0.7] {
        let r = 30f64.to_radians();
        let a = frame_placement(&m0, &mut d0, &DVector::from_vec(vec![x]), s).unwrap();
        let b = frame_placement(&m1, &mut d1, &DVector::from_vec(vec![x + r]), s).unwrap();
        assert!((a.trans - b.trans).norm() < 1e-14 && (a.rot - b.rot).norm() < 1e-14);
    }
    // Rotating about the point (0.3, 0, 0) leaves the site there.
    let m2 = load_str(&with("0", "0.3 0 0")).unwrap();
    let mut d2 = Data::new(&m2);
    let p = frame_placement(&m2, &mut d2, &DVector::from_vec(vec![1.1]), s).unwrap();
    assert!((p.trans - Vector3::new(0.3, 0.0, 1.0)).norm() < 1e-14);
}

#[test]
fn every_orientation_form_agrees() {
    // The same rotation (90° about z) written six ways, in degrees and radians.
    let forms = [
        r#"quat="0.7071067811865476 0 0 0.7071067811865476""#,
        r#"axisangle="0 0 2 90""#,
        r#"euler="0 0 90""#,
        r#"xyaxes="0 1 0 -1 0 0""#,
    ];
    let site = |orient: &str, compiler: &str| {
        format!(
            "<mujoco><compiler {compiler}/><worldbody><body name=\"b\" {orient}><joint/>\
             <geom size=\"0.1\"/><site name=\"s\" pos=\"1 0 0\"/></body></worldbody></mujoco>"
        )
    };
    let mut xmls: Vec<String> = forms.iter().map(|f| site(f, "")).collect();
    xmls.push(site(r#"euler="1.5707963267948966 0 0""#, r#"angle="radian" eulerseq="zyx""#));
    xmls.push(site(r#"axisangle="0 0 1 1.5707963267948966""#, r#"angle="radian""#));
    for xml in &xmls {
        let m = load_str(xml).unwrap();
        let mut d = Data::new(&m);
        let p = frame_placement(&m, &mut d, &m.neutral(), m.frame_id("s").unwrap()).unwrap();
        assert!((p.trans - Vector3::y()).norm() < 1e-15, "{xml}: {}", p.trans);
    }
    // zaxis: the shortest arc from z.
    let m = load_str(&wrap(
        r#"<body name="b" zaxis="1 0 0"><joint/><geom size="0.1"/><site name="s" pos="0 0 1"/></body>"#,
    ))
    .unwrap();
    let mut d = Data::new(&m);
    let p = frame_placement(&m, &mut d, &m.neutral(), m.frame_id("s").unwrap()).unwrap();
    assert!((p.trans - Vector3::x()).norm() < 1e-15);
}

#[test]
fn include_relative_to_base_dir_and_floating_base() {
    let xml = std::fs::read_to_string(data_dir().join("features.xml")).unwrap();
    let a = Model::from_mjcf_str(&xml, data_dir()).unwrap();
    let b = Model::from_mjcf(data_dir().join("features.xml")).unwrap();
    assert_eq!(a.nv(), b.nv());
    assert_eq!(a.inertias(), b.inertias());
    // floating_base: a free-flyer "root_joint" in front of the only top-level body.
    let opts = MjcfOptions { floating_base: true };
    let m = load_mjcf_file(&data_dir().join("radian.xml"), &opts).unwrap();
    assert_eq!(m.names()[1], "root_joint");
    assert_eq!(m.joints()[1], JointType::FreeFlyer);
    assert_eq!(m.nv(), 10);
    let e = load_mjcf_file(&data_dir().join("features.xml"), &opts).unwrap_err().to_string();
    assert!(e.contains("exactly one body in <worldbody>, found 3"), "{e}");
}

/// The dynamics of a loaded model run (the values are checked against MuJoCo in Python).
#[test]
fn dynamics_run_on_every_test_model() {
    for name in ["features", "radian", "mass_rules", "chains"] {
        let m = Model::from_mjcf(data_dir().join(format!("{name}.xml"))).unwrap();
        let mut d = Data::new(&m);
        let q = m.neutral();
        let v = DVector::from_element(m.nv(), 0.3);
        let mm = crba(&m, &mut d, &q).unwrap().clone();
        assert!(mm.clone().cholesky().is_some(), "{name}: M not positive definite");
        let tau = rnea(&m, &mut d, &q, &v, &v, None).unwrap();
        assert!(tau.iter().all(|x| x.is_finite()));
    }
}

#[test]
fn errors_name_file_line_and_element() {
    let cases: &[(&str, u32, &str, &str)] = &[
        ("<mujoco>\n<worldbody>\n<body>\n</worldbody>\n</mujoco>", 4, "XML", "malformed XML"),
        ("<robot name=\"r\"/>", 1, "<robot>", "expected <mujoco>"),
        (
            "<mujoco>\n<worldbody>\n<body name=\"b\">\n<joint name=\"j\" type=\"screw\"/>\n<geom size=\".1\"/></body></worldbody></mujoco>",
            4,
            "joint \"j\"",
            "unknown joint type \"screw\"",
        ),
        (
            "<mujoco>\n<include file=\"no_such_file.xml\"/>\n</mujoco>",
            2,
            "<include file=\"no_such_file.xml\">",
            "cannot read the included file",
        ),
        (
            "<mujoco>\n<worldbody>\n<body name=\"b\" pos=\"0 x 0\"><joint/><geom size=\".1\"/></body></worldbody></mujoco>",
            3,
            "body \"b\"",
            "pos=\"0 x 0\": \"x\" is not a number",
        ),
        (
            "<mujoco>\n<worldbody>\n<body name=\"b\" pos=\"0 0\"><joint/><geom size=\".1\"/></body></worldbody></mujoco>",
            3,
            "body \"b\"",
            "expected 3 numbers, found 2",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"b\"><joint/>\n<inertial pos=\"0 0 0\" mass=\"-1\" diaginertia=\"1 1 1\"/></body></worldbody></mujoco>",
            3,
            "body \"b\"",
            "negative mass -1",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"b\"><joint/>\n<inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"1 1 3\"/></body></worldbody></mujoco>",
            3,
            "body \"b\"",
            "triangle",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"arm\"><joint/><geom type=\"mesh\" mesh=\"m\"/></body></worldbody></mujoco>",
            2,
            "body \"arm\"",
            "mesh geom",
        ),
        (
            "<mujoco>\n<compiler coordinate=\"global\"/></mujoco>",
            2,
            "<compiler>",
            "global coordinates are not supported",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint/><geom size=\".1\"/>\n<body name=\"b\"><freejoint name=\"f\"/><geom size=\".1\"/></body></body></worldbody></mujoco>",
            3,
            "joint \"f\"",
            "a free joint must be the only joint of a body directly in <worldbody>; body \"b\" is \
             nested in another body",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint class=\"nope\"/><geom size=\".1\"/></body></worldbody></mujoco>",
            2,
            "unnamed joint of body \"a\"",
            "unknown default class \"nope\"",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint name=\"j\" axis=\"0 0 0\"/><geom size=\".1\"/></body></worldbody></mujoco>",
            2,
            "joint \"j\"",
            "zero axis",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\" quat=\"1 0 0 0\" euler=\"0 0 0\"><joint/><geom size=\".1\"/></body></worldbody></mujoco>",
            2,
            "body \"a\"",
            "several orientations",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint/></body></worldbody></mujoco>",
            2,
            "body \"a\"",
            "a moving body (with the bodies welded to it) needs a positive mass",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint/>\n<geom name=\"g\" fromto=\"0 0 0 1 0 0\" size=\".1\"/></body></worldbody></mujoco>",
            3,
            "geom \"g\" of body \"a\"",
            "fromto requires a capsule",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint/><geom size=\".1\"/>\n<geom type=\"plane\" size=\"1 1 1\"/></body></worldbody></mujoco>",
            3,
            "geom of body \"a\"",
            "plane geom is only allowed in a static body",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint type=\"ball\"/>\n<joint name=\"h\"/><geom size=\".1\"/></body></worldbody></mujoco>",
            3,
            "joint \"h\"",
            "a rotation follows a ball joint",
        ),
        (
            "<mujoco><worldbody>\n<composite type=\"rope\"/></worldbody></mujoco>",
            2,
            "<composite>",
            "not supported",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint/><geom size=\".1\" density=\"-5\"/></body></worldbody></mujoco>",
            2,
            "geom of body \"a\"",
            "negative mass or density",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint name=\"j\" range=\"1 -1\"/><geom size=\".1\"/></body></worldbody></mujoco>",
            2,
            "joint \"j\"",
            "range [1 -1] is empty",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint name=\"j\"/><geom size=\".1\"/></body>\n<body name=\"a\"><joint/><geom size=\".1\"/></body></worldbody></mujoco>",
            3,
            "body \"a\"",
            "frame \"a\" is defined twice",
        ),
        (
            "<mujoco><worldbody>\n<body name=\"a\"><joint name=\"j\"/><geom size=\".1\"/></body>\n<body name=\"b\"><joint name=\"j\"/><geom size=\".1\"/></body></worldbody></mujoco>",
            3,
            "joint \"j\"",
            "defined twice",
        ),
        (
            "<mujoco><worldbody><body name=\"a\"><joint/>\n<inertial pos=\"0 0 0\" mass=\"1\" \
             fullinertia=\"1 1 1 0 0 0\" quat=\"1 0 0 0\"/></body></worldbody></mujoco>",
            2,
            "body \"a\"",
            "both fullinertia and quat",
        ),
        (
            "<mujoco><worldbody><body name=\"a\"><joint/>\n<geom size=\".1\" shellinertia=\"true\"/></body></worldbody></mujoco>",
            2,
            "geom of body \"a\"",
            "shellinertia",
        ),
        (
            "<mujoco><worldbody><body name=\"a\"><joint/>\n<geom mesh=\"m\" size=\".1\"/></body></worldbody></mujoco>",
            1,
            "body \"a\"",
            "sphere geom sized from a mesh (line 2)",
        ),
        (
            "<mujoco><compiler angle=\"grad\"/></mujoco>",
            1,
            "<compiler>",
            "expected degree or radian",
        ),
    ];
    for &(xml, line, element, reason) in cases {
        let (l, e, r) = error_of(xml);
        assert_eq!((l, e.as_str()), (Some(line), element), "{xml}\n-> {r}");
        assert!(r.contains(reason), "{xml}\n-> {r}\n(expected \"{reason}\")");
    }
}

#[test]
fn include_errors_name_the_included_file() {
    let dir = std::env::temp_dir().join(format!("sodyn_mjcf_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("a.xml"), "<mujoco>\n<include file=\"b.xml\"/>\n</mujoco>").unwrap();
    std::fs::write(dir.join("b.xml"), "<mujoco>\n\n<include file=\"a.xml\"/>\n</mujoco>").unwrap();
    std::fs::write(
        dir.join("c.xml"),
        "<mujoco>\n<worldbody>\n<body name=\"x\"><joint type=\"spiral\"/></body>\n</worldbody>\n</mujoco>",
    )
    .unwrap();
    std::fs::write(dir.join("main.xml"), "<mujoco>\n<include file=\"c.xml\"/>\n</mujoco>").unwrap();
    let e = Model::from_mjcf(dir.join("a.xml")).unwrap_err().to_string();
    assert!(e.contains("b.xml:3") && e.contains("include cycle"), "{e}");
    let e = Model::from_mjcf(dir.join("main.xml")).unwrap_err().to_string();
    assert!(e.contains("c.xml:3") && e.contains("unknown joint type \"spiral\""), "{e}");
    // Only regular files are included (not a directory, /dev/zero or a FIFO).
    std::fs::write(dir.join("d.xml"), "<mujoco>\n<include file=\".\"/>\n</mujoco>").unwrap();
    let e = Model::from_mjcf(dir.join("d.xml")).unwrap_err().to_string();
    assert!(e.contains("d.xml:2") && e.contains("is not a regular file"), "{e}");
    let e = Model::from_mjcf(dir.join("missing.xml")).unwrap_err().to_string();
    assert!(e.contains("missing.xml") && e.contains("cannot read the file"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every prefix of the test models (and a few byte edits) loads or fails with an error, never
/// a panic.
#[test]
fn truncated_and_edited_files_never_panic() {
    for name in ["features.xml", "radian.xml", "mass_rules.xml", "chains.xml"] {
        let xml = std::fs::read_to_string(data_dir().join(name)).unwrap();
        let bytes = xml.as_bytes();
        for cut in (0..bytes.len()).step_by(7) {
            if let Ok(s) = std::str::from_utf8(&bytes[..cut]) {
                let _ = load_str(s);
            }
        }
        for (from, to) in [("0", "-"), ("\"", "'"), ("1", "nan"), (" ", ""), ("e", "E")] {
            for (k, _) in xml.match_indices(from).step_by(3) {
                let edited = format!("{}{to}{}", &xml[..k], &xml[k + from.len()..]);
                let _ = load_str(&edited);
            }
        }
    }
}

/// A chain of bodies nested up to the degree-of-freedom limit loads (the loader recurses per
/// level); deeper nesting and more degrees of freedom are errors, not a stack overflow.
#[test]
fn deep_nesting_is_bounded() {
    let chain = |n: usize, joint: &str| {
        let mut s = String::from("<mujoco><worldbody>\n");
        for _ in 0..n {
            s += &format!("<body pos=\"0 0 0.1\">{joint}<geom size=\"0.01\"/>");
        }
        s += &"</body>".repeat(n);
        s + "\n</worldbody></mujoco>"
    };
    let m = load_str(&chain(sodyn::model::MAX_URDF_DOFS, "<joint/>")).unwrap();
    assert_eq!(m.nv(), sodyn::model::MAX_URDF_DOFS);
    let e = load_str(&chain(sodyn::model::MAX_URDF_DOFS + 1, "<joint/>")).unwrap_err();
    assert!(e.to_string().contains("more than 1024 degrees of freedom"), "{e}");
    // Free bodies count too.
    let free = wrap(&"<body><freejoint/><geom size=\"0.1\"/></body>".repeat(171));
    let e = load_str(&free).unwrap_err();
    assert!(e.to_string().contains("1026 up to this joint"), "{e}");
    let e = load_str(&chain(100_000, "")).unwrap_err();
    assert!(e.to_string().contains("nested more than"), "{e}");
}

/// A static body's mesh geoms do not matter (its inertia never reaches the dynamics), nor do
/// massless mesh geoms of a moving one; a `<connect>` loads as the model's constraint.
#[test]
fn static_meshes_and_equality_constraints() {
    let m = load_str(&wrap(
        r#"<body name="table"><geom type="mesh" mesh="t"/><geom mesh="t"/></body>
           <body name="a"><joint/><geom size=".1"/><geom type="mesh" mesh="m" density="0"/>
             <geom type="mesh" mesh="m" mass="0"/></body>"#,
    ))
    .unwrap();
    assert_eq!(m.nv(), 1);
    assert!(m.warnings().is_empty());
    let m = Model::from_mjcf(data_dir().join("chains.xml")).unwrap();
    // The world's sites are frames on the world.
    let f = &m.frames()[m.frame_id("world_frame_site").unwrap()];
    assert_eq!(f.joint, 0);
    // euler="0 0 30" with eulerseq="XzY": 30° about y.
    let (s, c) = 30f64.to_radians().sin_cos();
    let x = Vector3::new(0.5 * c, 0.0, 1.0 - 0.5 * s);
    assert!((f.placement.trans - x).norm() < 1e-15);
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    assert_eq!(m.constraints().len(), 1);
    let c = &m.constraints()[0];
    assert_eq!(m.frames()[c.frame].name, "chain2");
    assert_eq!(m.frames()[c.frame2.unwrap()].name, "masses");
}

/// MuJoCo's default classes (each accepted case's armature is MuJoCo 4.0's `dof_armature`;
/// `python/tests/test_mjcf.py` checks these and more against MuJoCo itself).
#[test]
fn default_classes_as_mujoco() {
    let arm = |defaults: &str, j: &str| -> f64 {
        let xml = format!(
            "<mujoco>\n{defaults}\n<worldbody><body><joint name=\"j\" {j}/><geom size=\"0.1\"/>\
             </body></worldbody>\n</mujoco>"
        );
        let m = load_str(&xml).unwrap_or_else(|e| panic!("{xml}\n-> {e}"));
        m.armature()[0]
    };
    // The root class "main": implicit, explicit, or an empty name; later top-level defaults
    // update it; a nested class is a copy of its parent when it is read.
    assert_eq!(arm("<default><joint armature=\"0.1\"/></default>", ""), 0.1);
    assert_eq!(arm("<default class=\"main\"><joint armature=\"0.1\"/></default>", ""), 0.1);
    assert_eq!(
        arm("<default class=\"\"><joint armature=\"0.1\"/></default>", "class=\"main\""),
        0.1
    );
    let two = "<default class=\"main\"><joint armature=\"0.1\"/><default class=\"a\"/></default>\n\
               <default><joint armature=\"0.2\"/><default class=\"b\"/></default>";
    assert_eq!(arm(two, ""), 0.2);
    assert_eq!(arm(two, "class=\"a\""), 0.1);
    assert_eq!(arm(two, "class=\"b\""), 0.2);
    // The class's own elements are read before its nested classes, whatever their order.
    let order = "<default><default class=\"a\"/><joint armature=\"0.1\"/></default>";
    assert_eq!(arm(order, "class=\"a\""), 0.1);
    // childclass, and class="main" from inside another class.
    let xml = "<mujoco><default><joint armature=\"0.1\"/><default class=\"a\"><joint \
               armature=\"0.3\"/></default></default><worldbody><body childclass=\"a\"><joint/>\
               <geom size=\"0.1\"/><body childclass=\"main\"><joint/><geom size=\"0.1\"/></body>\
               <body><joint class=\"main\"/><geom size=\"0.1\"/></body></body></worldbody>\
               </mujoco>";
    assert_eq!(load_str(xml).unwrap().armature(), &[0.3, 0.1, 0.1]);
    // A nested class's partial size keeps its parent's other entries (MuJoCo's mass 159.17...).
    let xml = "<mujoco><default><geom type=\"capsule\" size=\"0.1 0.5\"/><default class=\"a\">\
               <geom size=\"0.2\"/></default></default><worldbody><body><joint/><geom \
               class=\"a\"/></body></worldbody></mujoco>";
    let mass = load_str(xml).unwrap().inertias()[1].mass;
    assert!((mass - 159.174_027_781_882_9).abs() < 1e-9, "{mass}");

    // What MuJoCo refuses, at the line it names.
    let refused: &[(&str, u32, &str, &str)] = &[
        (
            "<default>\n</default>\n<default class=\"top\"/>",
            4,
            "<default class=\"top\">",
            "cannot be renamed",
        ),
        (
            "<default>\n<default class=\"main\"/></default>",
            3,
            "<default class=\"main\">",
            "defined twice",
        ),
        (
            "<default><default class=\"p\"><default class=\"a\"/></default>\n<default \
             class=\"q\"><default class=\"a\"/></default></default>",
            3,
            "<default class=\"a\">",
            "defined twice",
        ),
        (
            "<default><default class=\"a\"/></default>\n<default><default class=\"a\"/></default>",
            3,
            "<default class=\"a\">",
            "defined twice",
        ),
        ("<default>\n<default/></default>", 3, "<default>", "non-empty class"),
        ("<default>\n<default class=\"\"/></default>", 3, "<default>", "non-empty class"),
        (
            "<default>\n<joint/><joint/></default>",
            2,
            "<default class=\"main\">",
            "a second <joint>",
        ),
        ("<default>\n<body/></default>", 3, "<body>", "cannot be in a <default>"),
    ];
    for &(defaults, line, element, reason) in refused {
        let xml = format!(
            "<mujoco>\n{defaults}\n<worldbody><body><joint/><geom size=\"0.1\"/></body>\
             </worldbody></mujoco>"
        );
        let (l, e, r) = error_of(&xml);
        assert_eq!((l, e.as_str()), (Some(line), element), "{xml}\n-> {r}");
        assert!(r.contains(reason), "{xml}\n-> {r}\n(expected \"{reason}\")");
    }
    let (l, e, r) = error_of("<mujoco>\n<worldbody childclass=\"a\"/></mujoco>");
    assert_eq!((l, e.as_str()), (Some(2), "<worldbody>"), "{r}");
    let (l, e, r) =
        error_of(&wrap("<body name=\"b\" class=\"main\"><joint/><geom size=\"0.1\"/></body>"));
    assert_eq!((l, e.as_str()), (Some(3), "body \"b\""), "{r}");
    let (l, e, r) =
        error_of(&wrap("<body name=\"b\" childclass=\"zz\"><joint/><geom size=\"0.1\"/></body>"));
    assert_eq!((l, e.as_str()), (Some(3), "body \"b\""), "{r}");
}

/// A body with joints needs mass and moments with the bodies welded to it, as in MuJoCo: a
/// massless body with joints loads when a welded child carries the mass.
#[test]
fn weld_group_mass_rule() {
    let m = load_str(&wrap(
        "<body><joint/><body><body pos=\"0.2 0 0\"><geom size=\"0.1\"/></body></body></body>",
    ))
    .unwrap();
    let mass = 1000.0 * 4.0 / 3.0 * PI * 0.001;
    assert!((m.inertias()[1].mass - mass).abs() < 1e-12);
    for body in [
        "<body name=\"a\"><joint/><body><joint/><geom size=\"0.1\"/></body></body>",
        "<body name=\"a\"><joint/><inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"0 0 0\"/>\
         <body pos=\"0.5 0 0\"><inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"0 0 0\"/></body></body>",
    ] {
        let (l, e, r) = error_of(&wrap(body));
        assert_eq!((l, e.as_str()), (Some(3), "body \"a\""), "{r}");
        assert!(r.contains("with the bodies welded to it"), "{r}");
    }
}

/// `discardvisual` and `fusestatic` do not change the dynamics, except that MuJoCo refuses a
/// visual geom with mass when `inertiafromgeom="true"`.
#[test]
fn discardvisual_and_fusestatic() {
    let body = "<body><joint/><geom size=\"0.1\"/><geom size=\"0.2\" pos=\"0.3 0 0\" contype=\"0\" \
                conaffinity=\"0\"/><body pos=\"0.5 0 0\"><geom size=\"0.1\"/></body></body>";
    let with = |compiler: &str| {
        load_str(&format!("<mujoco><compiler {compiler}/><worldbody>\n{body}</worldbody></mujoco>"))
    };
    let plain = with("").unwrap().inertias()[1];
    for c in [
        "discardvisual=\"true\"",
        "fusestatic=\"true\"",
        "discardvisual=\"false\" fusestatic=\"false\"",
    ] {
        assert_eq!(with(c).unwrap().inertias()[1], plain, "{c}");
    }
    // MuJoCo's mass of this body: 4/3 π (0.1³ + 0.2³ + 0.1³) · 1000.
    assert!((plain.mass - 4000.0 / 3.0 * PI * 0.010).abs() < 1e-9);
    match with("discardvisual=\"true\" inertiafromgeom=\"true\"") {
        Err(Error::Model { line: Some(2), element, reason, .. }) => {
            assert_eq!(element, "geom of unnamed body");
            assert!(reason.contains("discardvisual"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

/// Tendons are recorded (fixed: joint indices and coefficients; spatial: the path), warned
/// about once, and leave M and τ alone (the same model without them agrees exactly).
#[test]
fn tendons_are_data() {
    use sodyn::model::{SpatialWrap, TendonPath};
    let m = Model::from_mjcf(data_dir().join("tendons.xml")).unwrap();
    let t = m.tendons();
    assert_eq!(t.len(), 3);
    let (f1, f2) = (m.joint_id("f1_base").unwrap(), m.joint_id("f1_tip").unwrap());
    assert_eq!(t[0].name.as_deref(), Some("coupling"));
    assert_eq!(t[0].path, TendonPath::Fixed(vec![(f1, 1.0), (f2, -0.5)]));
    let site = |s: &str| SpatialWrap::Site(s.into());
    assert_eq!(
        t[1].path,
        TendonPath::Spatial(vec![
            site("palm_site"),
            site("f1_a"),
            SpatialWrap::Geom { geom: "f1_knuckle".into(), sidesite: Some("f1_side".into()) },
            site("f1_b")
        ])
    );
    assert_eq!(
        t[2].path,
        TendonPath::Spatial(vec![
            site("palm_site"),
            site("f1_a"),
            SpatialWrap::Pulley { divisor: 2.0 },
            site("palm_site"),
            site("thumb_tip")
        ])
    );
    let w: Vec<&String> = m.warnings().iter().filter(|w| w.contains("<tendon>")).collect();
    assert_eq!(w.len(), 1);
    assert!(w[0].contains("tendons.xml:49: <tendon>: 3 tendons (1 fixed, 2 spatial)"), "{}", w[0]);
    // The joint equality is inactive: no reduction.
    assert!(!m.is_reduced() && m.constraints().is_empty());
    // Without the tendons: the same M and τ, bit for bit.
    let text = std::fs::read_to_string(data_dir().join("tendons.xml")).unwrap();
    let (a, b) = (text.find("<tendon>").unwrap(), text.find("</tendon>").unwrap() + 9);
    let bare = load_str(&format!("{}{}", &text[..a], &text[b..])).unwrap();
    assert!(bare.tendons().is_empty());
    let q = DVector::from_fn(m.nq(), |i, _| 0.1 * i as f64 - 0.4);
    let mut q = q;
    let n = q.rows(3, 4).norm();
    q.rows_mut(3, 4).unscale_mut(n);
    let n = q.rows(7, 4).norm();
    q.rows_mut(7, 4).unscale_mut(n);
    let v = DVector::from_fn(m.nv(), |i, _| (i as f64).sin());
    let (mut d1, mut d2) = (Data::new(&m), Data::new(&bare));
    assert_eq!(crba(&m, &mut d1, &q).unwrap(), crba(&bare, &mut d2, &q).unwrap());
    assert_eq!(
        rnea(&m, &mut d1, &q, &v, &v, None).unwrap(),
        rnea(&bare, &mut d2, &q, &v, &v, None).unwrap()
    );
}

#[test]
fn tendon_errors_as_mujoco() {
    let model = |tendon: &str| {
        format!(
            "<mujoco><worldbody><site name=\"w\"/><body><joint name=\"j\"/><joint name=\"k\" \
             type=\"slide\"/><geom name=\"g\" size=\"0.1\"/><site name=\"s1\"/><site name=\"s2\" \
             pos=\"0 0 1\"/><body><joint name=\"b\" type=\"ball\"/><geom size=\"0.1\"/></body>\
             </body></worldbody>\n<tendon>\n{tendon}</tendon></mujoco>"
        )
    };
    load_str(&model(
        "<fixed><joint joint=\"j\" coef=\"1\"/><joint joint=\"k\" coef=\"0\"/></fixed>",
    ))
    .unwrap();
    load_str(&model("<spatial><site site=\"w\"/><site site=\"s2\"/></spatial>")).unwrap();
    load_str(&model("<fixed armature=\"0\"><joint joint=\"j\" coef=\"1\"/></fixed>")).unwrap();
    let cases: &[(&str, u32, &str, &str)] = &[
        (
            "<fixed>\n<joint joint=\"zz\" coef=\"1\"/></fixed>",
            4,
            "<joint> of unnamed <fixed> tendon",
            "unknown joint \"zz\"",
        ),
        (
            "<fixed>\n<joint joint=\"j\"/></fixed>",
            4,
            "<joint> of unnamed <fixed> tendon",
            "joint and coef",
        ),
        (
            "<fixed>\n<joint joint=\"b\" coef=\"1\"/></fixed>",
            4,
            "<joint> of unnamed <fixed> tendon",
            "not a hinge or slide",
        ),
        (
            "<fixed><joint joint=\"j\" coef=\"1\"/>\n<joint joint=\"j\" coef=\"2\"/></fixed>",
            4,
            "<joint> of unnamed <fixed> tendon",
            "repeated",
        ),
        ("<fixed name=\"t\"/>", 3, "tendon \"t\"", "empty path"),
        (
            "<fixed name=\"t\" armature=\"0.1\"><joint joint=\"j\" coef=\"1\"/></fixed>",
            3,
            "tendon \"t\"",
            "tendon armature",
        ),
        (
            "<fixed name=\"t\" armature=\"-1\"><joint joint=\"j\" coef=\"1\"/></fixed>",
            3,
            "tendon \"t\"",
            "negative",
        ),
        ("<spatial name=\"t\"><site site=\"s1\"/></spatial>", 3, "tendon \"t\"", "at least two"),
        (
            "<spatial name=\"t\"><site site=\"s1\"/>\n<site site=\"zz\"/></spatial>",
            4,
            "<site> of tendon \"t\"",
            "unknown site",
        ),
        (
            "<spatial name=\"t\"><site site=\"s1\"/>\n<geom geom=\"zz\"/><site site=\"s2\"/></spatial>",
            4,
            "<geom> of tendon \"t\"",
            "unknown geom",
        ),
        (
            "<spatial name=\"t\"><site site=\"s1\"/>\n<geom geom=\"g\" sidesite=\"zz\"/><site site=\"s2\"/></spatial>",
            4,
            "<geom> of tendon \"t\"",
            "unknown side site",
        ),
        (
            "<spatial name=\"t\">\n<geom geom=\"g\"/><site site=\"s2\"/></spatial>",
            4,
            "tendon \"t\"",
            "not between two sites",
        ),
        (
            "<spatial name=\"t\"><site site=\"s1\"/><site site=\"s2\"/><pulley divisor=\"2\"/>\n<site site=\"s1\"/></spatial>",
            4,
            "tendon \"t\"",
            "no neighbour",
        ),
        (
            "<spatial name=\"t\"><site site=\"s1\"/><site site=\"s2\"/>\n<pulley/><site site=\"s1\"/><site site=\"s2\"/></spatial>",
            4,
            "<pulley> of tendon \"t\"",
            "missing divisor",
        ),
        (
            "<fixed name=\"t\"><joint joint=\"j\" coef=\"1\"/></fixed>\n<fixed name=\"t\"><joint joint=\"j\" coef=\"1\"/></fixed>",
            4,
            "tendon \"t\"",
            "a second tendon",
        ),
        (
            "<fixed name=\"t\" class=\"zz\"><joint joint=\"j\" coef=\"1\"/></fixed>",
            3,
            "tendon \"t\"",
            "unknown default class",
        ),
    ];
    for &(tendon, line, element, reason) in cases {
        let xml = model(tendon);
        let (l, e, r) = error_of(&xml);
        assert_eq!((l, e.as_str()), (Some(line), element), "{xml}\n-> {r}");
        assert!(r.contains(reason), "{xml}\n-> {r}\n(expected \"{reason}\")");
    }
    // A tendon armature from the class defaults is refused too.
    let xml = format!(
        "<mujoco><default><tendon armature=\"0.2\"/></default>{}",
        &model("<fixed><joint joint=\"j\" coef=\"1\"/></fixed>")["<mujoco>".len()..]
    );
    assert!(error_of(&xml).2.contains("tendon armature"));
}

/// An `<include>` of an included file: relative to the main file's directory, else to the
/// including file's (MuJoCo's fallback).
#[test]
fn nested_include_fallback() {
    let m = Model::from_mjcf(data_dir().join("nested_include/main.xml")).unwrap();
    assert_eq!(m.names()[1..], ["shoulder".to_string(), "hip".to_string()]);
}

/// World placement of a constraint's frame A and frame B contact frames at `q` (full tree).
fn constraint_frames(
    m: &Model,
    c: &sodyn::model::Contact,
    q: &DVector<f64>,
) -> (sodyn::spatial::Transform, sodyn::spatial::Transform) {
    let mut d = Data::new(m);
    let xa = frame_placement(m, &mut d, q, c.frame).unwrap().compose(&c.placement());
    let xb = frame_placement(m, &mut d, q, c.frame2.unwrap())
        .unwrap()
        .compose(&sodyn::spatial::Transform::new(c.rotation2, c.point2));
    (xa, xb)
}

/// `equality.xml`: MuJoCo's qpos0 in sodyn's full-tree coordinates (hinges at their `ref`, free
/// joints at their bodies' poses, `[p; x y z w]`).
fn equality_qpos0(full: &Model) -> DVector<f64> {
    let mut q = full.neutral();
    let mut set = |joint: &str, x: &[f64]| {
        let a = full.idx_q()[full.joint_id(joint).unwrap()];
        q.as_mut_slice()[a..a + x.len()].copy_from_slice(x);
    };
    set("j1", &[10f64.to_radians()]);
    set("j6", &[5f64.to_radians()]);
    let quat = |w: f64, x: f64, y: f64, z: f64| {
        let n = (w * w + x * x + y * y + z * z).sqrt();
        [x / n, y / n, z / n, w / n]
    };
    let b = quat(0.9, 0.1, 0.3, 0.2);
    set("box_free", &[0.6, 0.1, 0.8, b[0], b[1], b[2], b[3]]);
    let l = quat(0.8, 0.0, 0.6, 0.0);
    // The unnamed free joints are named joint<i> (MuJoCo's joint index).
    set("joint5", &[-0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]);
    set("joint6", &[0.0, 0.5, 0.3, l[0], l[1], l[2], l[3]]);
    q
}

/// `<equality>`: the constraints' frames, points and placements, each closed (zero residual) at
/// MuJoCo's reference configuration qpos0, the loop's point computed by hand; the joint
/// coupling as the model's mimic reduction; the inactive constraint skipped.
#[test]
fn equality_constraints_load_closed_at_qpos0() {
    use sodyn::model::ContactType;
    let m = Model::from_mjcf(data_dir().join("equality.xml")).unwrap();
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    // The coupling j6 = 0.1 + ref6 + 0.5 (j1 − ref1): a reduced model without j6's DoF.
    assert!(m.is_reduced());
    let full = m.full_tree();
    assert_eq!((full.nq(), full.nv()), (28, 24));
    assert_eq!((m.nq(), m.nv()), (27, 23));
    let mj = m.mimic_joints();
    assert_eq!(mj.len(), 1);
    assert_eq!(
        (full.names()[mj[0].joint].as_str(), full.names()[mj[0].reference].as_str()),
        ("j6", "j1")
    );
    assert_eq!(mj[0].multiplier, 0.5);
    let offset = 0.1 + 5f64.to_radians() - 0.5 * 10f64.to_radians();
    assert!((mj[0].offset - offset).abs() < 1e-15, "{}", mj[0].offset);
    // Four active constraints (the fifth is inactive), in document order.
    let cs = m.constraints();
    assert_eq!(cs.len(), 4);
    assert_eq!(full.constraints(), cs);
    let name = |f: usize| full.frames()[f].name.as_str();
    let who: Vec<(&str, &str, ContactType)> =
        cs.iter().map(|c| (name(c.frame), name(c.frame2.unwrap()), c.kind)).collect();
    assert_eq!(
        who,
        [
            ("link2", "link3", ContactType::D3),
            ("link3", "box", ContactType::D6),
            ("puck", "universe", ContactType::D3),
            // body1 is the world: frame A is the lid's side.
            ("lid", "universe", ContactType::D6),
        ]
    );
    // The loop: anchor (0.3, 0, 0) in link2, and by hand its point in link3 at qpos0, where
    // the bodies are placed as the file writes them (j1 at its ref = 10°): the link2 tip at
    // (0, 0, 1) + (0, 0, −0.3) + (0.3, 0, 0), link3's frame at (0.3, 0, 1).
    assert_eq!(cs[0].point, Vector3::new(0.3, 0.0, 0.0));
    let tip = Vector3::new(0.0, 0.0, 1.0) + Vector3::new(0.3, 0.0, -0.3);
    let point2 = tip - Vector3::new(0.3, 0.0, 1.0);
    assert!((cs[0].point2 - point2).norm() < 1e-15, "{:?} vs {point2:?}", cs[0].point2);
    // The weld to the box: frame B at the anchor in the box's frame.
    assert_eq!(cs[1].point2, Vector3::new(0.05, 0.0, 0.0));
    assert_eq!(cs[1].rotation2, nalgebra::Matrix3::identity());
    // The puck's pin: the anchor, and its world position at qpos0.
    assert_eq!(cs[2].point, Vector3::new(0.1, 0.0, 0.0));
    assert!((cs[2].point2 - Vector3::new(-0.4, 0.0, 0.5)).norm() < 1e-15);
    // The lid: held at relpose in the world.
    assert!((cs[3].point2 - Vector3::new(0.0, 0.5, 0.3)).norm() < 1e-15);
    // Every constraint is closed at qpos0: points coincide (3-D), frames coincide (6-D).
    let q0 = equality_qpos0(full);
    for (i, c) in cs.iter().enumerate() {
        let (xa, xb) = constraint_frames(full, c, &q0);
        let dp = (xa.trans - xb.trans).norm();
        assert!(dp < 1e-14, "constraint {i}: points apart by {dp}");
        if c.kind == ContactType::D6 {
            let dr = (xa.rot - xb.rot).amax();
            assert!(dr < 1e-14, "constraint {i}: frames turned by {dr}");
        }
    }
    // And open elsewhere (the residual is not zero by construction).
    let mut q = q0.clone();
    q[full.idx_q()[full.joint_id("j3").unwrap()]] += 0.1;
    let (xa, xb) = constraint_frames(full, &cs[0], &q);
    assert!((xa.trans - xb.trans).norm() > 1e-3);
}

/// An explicit weld `relpose` places frame A at `relpose · anchor` in body1; its default is the
/// relative pose at qpos0.
#[test]
fn weld_relpose_places_frame_a() {
    let xml = |relpose: &str| {
        format!(
            r#"<mujoco><worldbody>
<body name="a" pos="0 0 1"><joint axis="0 1 0"/><geom size="0.1"/></body>
<body name="b" pos="1 0 1" euler="0 0 90"><joint axis="1 0 0"/><geom size="0.1"/></body>
</worldbody><equality><weld body1="a" body2="b" anchor="0 0.2 0" {relpose}/></equality></mujoco>"#
        )
    };
    let m = load_str(&xml(r#"relpose="0.5 0 0 0 0 0 1""#)).unwrap();
    let c = &m.constraints()[0];
    // A half turn about z: (0, 0.2, 0) → (0, −0.2, 0), plus (0.5, 0, 0).
    assert!((c.point - Vector3::new(0.5, -0.2, 0.0)).norm() < 1e-15, "{:?}", c.point);
    assert!(
        (c.rotation - nalgebra::Matrix3::from_diagonal(&Vector3::new(-1.0, -1.0, 1.0))).amax()
            < 1e-15
    );
    assert_eq!(c.point2, Vector3::new(0.0, 0.2, 0.0));
    // Default: b's pose in a at q = 0 (a turn of 90° about z, 1 m along x).
    let m = load_str(&xml("")).unwrap();
    let c = &m.constraints()[0];
    assert!((c.point - Vector3::new(0.8, 0.0, 0.0)).norm() < 1e-15, "{:?}", c.point);
    let (xa, xb) = constraint_frames(&m, c, &m.neutral());
    assert!((xa.trans - xb.trans).norm() < 1e-15 && (xa.rot - xb.rot).amax() < 1e-15);
}

/// Bad `<equality>` elements: an error naming the element and its line.
#[test]
fn equality_errors_name_element_and_line() {
    let bodies = r#"<worldbody>
<body name="a"><joint name="ja" axis="0 1 0"/><geom size="0.1"/>
  <body name="a2"><geom size="0.1"/></body></body>
<body name="b" pos="1 0 0"><joint name="jb" type="slide"/><geom size="0.1"/></body>
<body name="c" pos="2 0 0"><joint name="jc"/><geom size="0.1"/></body>
</worldbody>"#;
    let case = |eq: &str| {
        error_of(&format!("<mujoco>\n{bodies}\n<equality>\n{eq}\n</equality>\n</mujoco>"))
    };
    // The equality element is on line 9.
    let (line, el, why) = case(r#"<joint name="sq" joint1="jc" joint2="ja" polycoef="0 1 0.5"/>"#);
    assert_eq!((line, el.as_str()), (Some(9), "<joint> \"sq\""));
    assert!(why.contains("coefficient 2 is 0.5") && why.contains("linear"), "{why}");
    let (line, el, why) = case(r#"<tendon name="t" tendon1="x"/>"#);
    assert_eq!((line, el.as_str()), (Some(9), "<tendon> \"t\""));
    assert!(why.contains("tendon1=\"x\": unknown tendon"), "{why}");
    let (line, el, why) = case(r#"<flex flex="f"/>"#);
    assert_eq!((line, el.as_str()), (Some(9), "<flex>"));
    assert!(why.contains("not supported"), "{why}");
    let (line, el, why) = case(r#"<connect name="x" body1="a" body2="nobody" anchor="0 0 0"/>"#);
    assert_eq!((line, el.as_str()), (Some(9), "<connect> \"x\""));
    assert!(why.contains("body2=\"nobody\": unknown body"), "{why}");
    let (_, _, why) = case(r#"<weld body1="a" body2="a2"/>"#);
    assert!(why.contains("same body"), "{why}");
    let (_, el, why) = case(r#"<joint joint1="ja" joint2="jb"/>"#);
    assert_eq!(el, "<joint>");
    assert!(why.contains("rotational") && why.contains("prismatic"), "{why}");
    let (_, _, why) = case(r#"<joint joint1="ja"/>"#);
    assert!(why.contains("no joint2"), "{why}");
    let (_, _, why) = case(r#"<joint joint1="nojoint" joint2="jc"/>"#);
    assert!(why.contains("joint1=\"nojoint\": unknown joint"), "{why}");
    let (_, _, why) = case(r#"<connect site1="s" site2="t"/>"#);
    assert!(why.contains("sites"), "{why}");
    // Inactive: skipped, whatever it is (here a tendon equality, and through its class).
    let xml = format!(
        "<mujoco><default><equality active=\"false\"/></default>\n{bodies}\n<equality>\
         <tendon tendon1=\"x\"/><connect body1=\"a\" body2=\"b\" anchor=\"0 0 0\" active=\"true\"/>\
         </equality></mujoco>"
    );
    let m = load_str(&xml).unwrap();
    assert_eq!(m.constraints().len(), 1);
}

/// MJCF: `armature` sets the model's, with the defaults; a `<freejoint>` takes none (as in
/// MuJoCo); a negative one is an error naming the line.
#[test]
fn mjcf_armature() {
    let xml = r#"<mujoco><default><joint armature="0.3"/></default><worldbody>
<body><freejoint/><geom size=".1"/>
<body pos="0 0 1"><joint type="ball"/><geom size=".1"/>
<body pos="0 0 1"><joint axis="1 0 0" armature="0.7"/><geom size=".1"/></body></body></body>
</worldbody></mujoco>"#;
    let m = Model::from_mjcf_str(xml, ".").unwrap();
    assert_eq!(m.armature(), [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.3, 0.3, 0.7]);
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    let bad = "<mujoco><worldbody><body>\n<joint armature=\"-1\"/><geom size=\".1\"/></body></worldbody></mujoco>";
    let e = Model::from_mjcf_str(bad, ".").unwrap_err().to_string();
    assert!(e.contains(":2:") && e.contains("armature=\"-1\" is negative"), "{e}");
}

/// The tendon lengths `L = Σ coef · q` of the fixed tendons of `m` at the full configuration
/// `qf`, by name (from the loader's records, not from the reduction).
fn tendon_lengths(m: &Model, qf: &DVector<f64>) -> std::collections::HashMap<String, f64> {
    use sodyn::model::TendonPath;
    let full = m.full_tree();
    m.tendons()
        .iter()
        .filter_map(|t| match &t.path {
            TendonPath::Fixed(p) => Some((
                t.name.clone().unwrap(),
                p.iter().map(|&(j, c)| c * qf[full.idx_q()[j]]).sum(),
            )),
            TendonPath::Spatial(_) => None,
        })
        .collect()
}

/// `<equality><tendon>` on fixed tendons (and a `<joint>` coupling among them): the loader
/// eliminates one joint per constraint (tendon1's last joint with a nonzero net coefficient;
/// through the couplings before it), `G` has several entries in those rows, and every
/// constraint holds on the expanded configurations, `L1 − L1₀ = c0 + c1 (L2 − L2₀)` with `₀`
/// at qpos0, evaluated from the tendon records; its velocity row annihilates `G`.
#[test]
fn tendon_equalities_load_as_linear_couplings() {
    let m = crate::util::mimic::tendon_model();
    let full = m.full_tree();
    assert_eq!((full.nq(), full.nv(), m.nq(), m.nv()), (18, 16, 14, 12));
    assert!(m.constraints().is_empty());
    let name = |j: usize| full.names()[j].as_str();
    let cs = m.linear_couplings();
    let elim: Vec<&str> = cs.iter().map(|c| name(c.joint)).collect();
    assert_eq!(elim, ["j3", "j4", "j5", "j6"]);
    let terms = |k: usize| -> Vec<&str> { cs[k].terms.iter().map(|t| name(t.0)).collect() };
    // j3 from e1 on j1, j2, s1; j4 (e3) and j5 (e4) through j3; j6 = −0.5 j1 + …
    assert_eq!(terms(0), ["j1", "j2", "s1"]);
    assert_eq!(terms(1), ["j1", "j2", "s1"]);
    assert_eq!(terms(2), ["j1", "j2", "s1"]);
    assert_eq!(terms(3), ["j1"]);
    // Net coefficients of e1: j1 0.5, j2 1 − 0.4 · 0.3, j3 −0.7, s1 −0.4 · 2.
    let t = &cs[0].terms;
    for (k, x) in [0.5 / 0.7, 0.88 / 0.7, -0.8 / 0.7].into_iter().enumerate() {
        assert!((t[k].1 - x).abs() < 1e-15, "{:?}", t);
    }
    // The mimic list has the one single-term coupling.
    let mj = m.mimic_joints();
    assert_eq!(mj.len(), 1);
    assert_eq!((name(mj[0].joint), name(mj[0].reference), mj[0].multiplier), ("j6", "j1", -0.5));
    // G: several entries in the eliminated rows; rank nv.
    let g = m.velocity_map();
    let row = |j: &str| full.idx_v()[full.joint_id(j).unwrap()];
    assert_eq!(g.row(row("j4")).iter().filter(|x| **x != 0.0).count(), 3);
    assert_eq!(g.clone().svd(false, false).rank(1e-12), m.nv());
    // qpos0 of the full tree (hinges at their ref).
    let mut q0 = full.neutral();
    for (j, r) in [("j1", 0.3), ("j3", -0.2), ("j6", 0.1)] {
        q0[full.idx_q()[full.joint_id(j).unwrap()]] = r;
    }
    let l0 = tendon_lengths(&m, &q0);
    let qj = |qf: &DVector<f64>, j: &str| qf[full.idx_q()[full.joint_id(j).unwrap()]];
    // The constraints' residuals and their rows (∂/∂v_full, constant).
    let residuals = |qf: &DVector<f64>| -> [f64; 4] {
        let l = tendon_lengths(&m, qf);
        let d = |t: &str| l[t] - l0[t];
        [
            d("t1") - 0.1 - 0.4 * d("t2"),
            (qj(qf, "j6") - 0.1) - 0.05 + 0.5 * (qj(qf, "j1") - 0.3),
            d("t4") - 0.02,
            d("t3"),
        ]
    };
    let mut rows = nalgebra::DMatrix::zeros(4, full.nv());
    for k in 0..full.nv() {
        let mut e = DVector::zeros(full.nv());
        e[k] = 1.0;
        let r = residuals(&full.integrate(&q0, &e).unwrap());
        let r0 = residuals(&q0);
        for i in 0..4 {
            rows[(i, k)] = r[i] - r0[i];
        }
    }
    let rg = &rows * &g;
    assert!(rg.amax() < 1e-13, "constraint rows · G = {rg}");
    assert_eq!(rows.clone().svd(false, false).rank(1e-9), 4);
    let mut rng = sodyn::rng::Rng::new(7);
    let mut worst = 0.0f64;
    for _ in 0..20 {
        let q = m.random_configuration(&mut rng);
        let qf = m.expand_q(&q).unwrap();
        for r in residuals(&qf) {
            worst = worst.max(r.abs());
        }
        // The independent coordinates are q's.
        assert_eq!(m.reduce_q(&qf).unwrap(), q);
    }
    assert!(worst < 1e-14, "residual {worst:e}");
    // At qpos0 the residuals are −c0 (MuJoCo's qpos0 need not satisfy the constraints).
    let r0 = residuals(&q0);
    for (r, c0) in r0.iter().zip([-0.1, -0.05, -0.02, 0.0]) {
        assert!((r - c0).abs() < 1e-15, "{r0:?}");
    }
    // with_armature keeps the couplings.
    let a: Vec<f64> = (0..full.nv()).map(|k| 0.01 * k as f64).collect();
    let ma = m.with_armature(&a).unwrap();
    assert_eq!(ma.linear_couplings(), m.linear_couplings());
    assert_eq!(ma.nv(), 12);
}

/// Bad `<equality><tendon>`s: an error naming the element and its line.
#[test]
fn tendon_equality_errors_name_element_and_line() {
    let bodies = r#"<worldbody>
<body name="a"><joint name="ja" axis="0 1 0"/><geom size="0.1"/><site name="sa"/>
<body name="b" pos="1 0 0"><joint name="jb" type="slide"/><geom size="0.1"/><site name="sb"/>
<body name="c" pos="1 0 0"><joint name="jc"/><geom size="0.1"/></body></body></body>
</worldbody>
<tendon><fixed name="f1"><joint joint="ja" coef="1"/><joint joint="jb" coef="2"/></fixed>
<fixed name="f2"><joint joint="jb" coef="1"/><joint joint="jc" coef="-1"/></fixed>
<fixed name="f3"><joint joint="ja" coef="2"/><joint joint="jb" coef="4"/></fixed>
<spatial name="sp"><site site="sa"/><site site="sb"/></spatial></tendon>"#;
    let case = |eq: &str| {
        error_of(&format!("<mujoco>\n{bodies}\n<equality>\n{eq}\n</equality>\n</mujoco>"))
    };
    // The (first) equality element is on line 12.
    let (line, el, why) = case(r#"<tendon name="s" tendon1="sp"/>"#);
    assert_eq!((line, el.as_str()), (Some(12), "<tendon> \"s\""));
    assert!(why.contains("tendon1=\"sp\" is a spatial tendon"), "{why}");
    let (line, _, why) = case(r#"<tendon tendon1="f1" tendon2="sp"/>"#);
    assert!(line == Some(12) && why.contains("tendon2=\"sp\" is a spatial tendon"), "{why}");
    let (line, el, why) =
        case(r#"<tendon name="p" tendon1="f1" tendon2="f2" polycoef="0 1 0.5"/>"#);
    assert_eq!((line, el.as_str()), (Some(12), "<tendon> \"p\""));
    assert!(why.contains("coefficient 2 is 0.5") && why.contains("linear"), "{why}");
    let (_, _, why) = case(r#"<tendon tendon1="f1" tendon2="nope"/>"#);
    assert!(why.contains("tendon2=\"nope\": unknown tendon"), "{why}");
    let (_, _, why) = case(r#"<tendon tendon2="f1"/>"#);
    assert!(why.contains("attribute tendon1 is missing"), "{why}");
    // Dependent: f3 = 2 f1, so f3 − 2 f1 constrains nothing; and a constraint that follows
    // from the one before it.
    let (line, el, why) = case(r#"<tendon name="d" tendon1="f3" tendon2="f1" polycoef="0 2"/>"#);
    assert_eq!((line, el.as_str()), (Some(12), "<tendon> \"d\""));
    assert!(why.contains("dependent"), "{why}");
    let (line, el, why) = case("<tendon tendon1=\"f1\"/>\n<tendon name=\"again\" tendon1=\"f3\"/>");
    assert_eq!((line, el.as_str()), (Some(13), "<tendon> \"again\""));
    assert!(why.contains("dependent"), "{why}");
    // Inconsistent: f1 held at 0.1 from its qpos0 length, f3 = 2 f1 at 0.5.
    let (line, el, why) = case(
        "<tendon tendon1=\"f1\" polycoef=\"0.1\"/>\n<tendon name=\"x\" tendon1=\"f3\" polycoef=\"0.5\"/>",
    );
    assert_eq!((line, el.as_str()), (Some(13), "<tendon> \"x\""));
    assert!(why.contains("inconsistent"), "{why}");
    // With a <joint> coupling: that coupling's own checks first, naming it.
    let (_, el, why) =
        case("<tendon tendon1=\"f2\"/>\n<joint name=\"jj\" joint1=\"ja\" joint2=\"jb\"/>");
    assert_eq!(el, "<joint> \"jj\"");
    assert!(why.contains("rotational") && why.contains("prismatic"), "{why}");
    // A <joint> coupling with a tendon coupling: chained through the elimination (jc from f2,
    // then ja = 0.5 jc), one DoF left.
    let xml = format!(
        "<mujoco>\n{bodies}\n<equality><tendon tendon1=\"f2\"/>\
         <joint joint1=\"ja\" joint2=\"jc\" polycoef=\"0 0.5\"/></equality></mujoco>"
    );
    let m = load_str(&xml).unwrap();
    assert_eq!(m.nv(), 1);
    let full = m.full_tree();
    let names: Vec<&str> =
        m.linear_couplings().iter().map(|c| full.names()[c.joint].as_str()).collect();
    assert_eq!(names, ["ja", "jc"]);
    // ja = 0.5 jc = 0.5 jb (f2: jb − jc = 0).
    let q = DVector::from_element(1, 0.4);
    let qf = m.expand_q(&q).unwrap();
    assert!((qf[0] - 0.2).abs() < 1e-15 && qf[1] == 0.4 && (qf[2] - 0.4).abs() < 1e-15, "{qf}");
    // Inactive: skipped.
    let xml = format!(
        "<mujoco>\n{bodies}\n<equality><tendon tendon1=\"sp\" active=\"false\"/></equality></mujoco>"
    );
    assert!(!load_str(&xml).unwrap().is_reduced());
}
