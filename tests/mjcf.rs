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
/// massless mesh geoms of a moving one; equality constraints load with a warning.
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
    assert_eq!(m.warnings().len(), 1, "{:?}", m.warnings());
    assert!(m.warnings()[0].contains("<connect> \"loop\": equality constraint ignored"));
}
