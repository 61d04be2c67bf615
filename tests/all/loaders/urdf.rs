//! URDF loader tests: the shared robot models (`../shared/models`, or their copy in
//! `tests/data/models`: dimensions, frames, masses, placements, joint order against Pinocchio's
//! fixtures), the depth-first numbering, and one test per malformed input.

use nalgebra::{Matrix3, Vector3};
use sodyn::Error;
use sodyn::model::{JointType, Model, UrdfOptions, load_urdf_file, load_urdf_str};
use sodyn::spatial::{Inertia, Transform};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

const SHARED_MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/models");
const COMMITTED_MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/models");
const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/urdf");
/// URDFs that Pinocchio and Bullet load and that need leniency (`tests/data/urdf` holds only
/// broken ones).
const LENIENT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/lenient");
const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

const FIXED: UrdfOptions =
    UrdfOptions { floating_base: false, strict_inertia: false, mimic: false };
const FLOATING: UrdfOptions =
    UrdfOptions { floating_base: true, strict_inertia: false, mimic: false };
const STRICT: UrdfOptions =
    UrdfOptions { floating_base: false, strict_inertia: true, mimic: false };

/// The robot models: `../shared/models` when it exists, otherwise the copy committed in
/// `tests/data/models` (so that these tests never skip).
fn models_dir() -> PathBuf {
    let shared = PathBuf::from(SHARED_MODELS);
    if shared.is_dir() { shared } else { PathBuf::from(COMMITTED_MODELS) }
}

/// One row of the models README table: file, floating base, nv.
struct Row {
    file: String,
    ff: bool,
    nv: usize,
}

fn readme_table(dir: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(dir.join("README.md")).expect("models README.md");
    let mut rows = Vec::new();
    for line in text.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() > 4 && cells[1].ends_with(".urdf") {
            let ff = match cells[2] {
                "ff" => true,
                "fixed" => false,
                other => panic!("README: unknown base {other:?} for {}", cells[1]),
            };
            let nv = cells[3].parse().expect("README nv column");
            rows.push(Row { file: cells[1].to_string(), ff, nv });
        }
    }
    assert!(!rows.is_empty(), "no model rows found in README.md");
    rows
}

fn load_shared(dir: &Path, row: &Row) -> Model {
    let opts = UrdfOptions { floating_base: row.ff, strict_inertia: false, mimic: false };
    let m = load_urdf_file(&dir.join(&row.file), &opts)
        .unwrap_or_else(|e| panic!("{} failed to load: {e}", row.file));
    assert!(m.warnings().is_empty(), "{}: {:?}", row.file, m.warnings());
    m
}

// ---------------------------------------------------------------------------------------------
// An independent, minimal reading of a URDF (no validation), used as the oracle.

struct RefLink {
    name: String,
    /// Inertia in the link frame (computed differently from the loader: via `act_inertia`).
    inertia: Inertia,
}

struct RefJoint {
    name: String,
    ty: String,
    parent: String,
    child: String,
    origin: Transform,
    mimic: Option<String>,
}

fn nums(s: Option<&str>, default: [f64; 3]) -> [f64; 3] {
    match s {
        None => default,
        Some(s) => {
            let v: Vec<f64> = s.split_whitespace().map(|t| t.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        }
    }
}

fn ref_origin(node: roxmltree::Node) -> Transform {
    match node.children().find(|c| c.has_tag_name("origin")) {
        None => Transform::identity(),
        Some(o) => Transform::from_rpy_xyz(
            nums(o.attribute("rpy"), [0.0; 3]),
            nums(o.attribute("xyz"), [0.0; 3]),
        ),
    }
}

fn ref_parse(xml: &str) -> (String, Vec<RefLink>, Vec<RefJoint>) {
    let doc = roxmltree::Document::parse(xml).unwrap();
    let robot = doc.root_element();
    let mut links = Vec::new();
    let mut joints = Vec::new();
    for n in robot.children().filter(|c| c.is_element()) {
        let child = |tag: &str| n.children().find(|c| c.has_tag_name(tag));
        if n.has_tag_name("link") {
            let inertia = match child("inertial") {
                None => Inertia::zero(),
                Some(i) => {
                    let f = |tag: &str, a: &str| -> f64 {
                        i.children()
                            .find(|c| c.has_tag_name(tag))
                            .unwrap()
                            .attribute(a)
                            .unwrap()
                            .parse()
                            .unwrap()
                    };
                    let (xx, xy, xz) =
                        (f("inertia", "ixx"), f("inertia", "ixy"), f("inertia", "ixz"));
                    let (yy, yz, zz) =
                        (f("inertia", "iyy"), f("inertia", "iyz"), f("inertia", "izz"));
                    let ic = Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz);
                    ref_origin(i).act_inertia(&Inertia::from_com(
                        f("mass", "value"),
                        Vector3::zeros(),
                        ic,
                    ))
                }
            };
            links.push(RefLink { name: n.attribute("name").unwrap().into(), inertia });
        } else if n.has_tag_name("joint") {
            joints.push(RefJoint {
                name: n.attribute("name").unwrap().into(),
                ty: n.attribute("type").unwrap().into(),
                parent: child("parent").unwrap().attribute("link").unwrap().into(),
                child: child("child").unwrap().attribute("link").unwrap().into(),
                origin: ref_origin(n),
                mimic: child("mimic").map(|m| m.attribute("joint").unwrap().into()),
            });
        }
    }
    (robot.attribute("name").unwrap().into(), links, joints)
}

fn ref_root(links: &[RefLink], joints: &[RefJoint]) -> String {
    let roots: Vec<&RefLink> =
        links.iter().filter(|l| !joints.iter().any(|j| j.child == l.name)).collect();
    assert_eq!(roots.len(), 1);
    roots[0].name.clone()
}

/// Movable joints in depth-first order; siblings in document order, or sorted by joint name
/// (urdfdom/Pinocchio) when `sort`.
fn ref_dfs(links: &[RefLink], joints: &[RefJoint], sort: bool) -> Vec<String> {
    fn visit(link: &str, joints: &[RefJoint], sort: bool, out: &mut Vec<String>) {
        let mut kids: Vec<&RefJoint> = joints.iter().filter(|j| j.parent == link).collect();
        if sort {
            kids.sort_by(|a, b| a.name.cmp(&b.name));
        }
        for j in kids {
            if j.ty != "fixed" {
                out.push(j.name.clone());
            }
            visit(&j.child, joints, sort, out);
        }
    }
    let mut out = Vec::new();
    visit(&ref_root(links, joints), joints, sort, &mut out);
    out
}

/// World pose of every link at the neutral configuration (all joint transforms identity).
fn ref_link_poses(links: &[RefLink], joints: &[RefJoint]) -> HashMap<String, Transform> {
    let mut poses = HashMap::new();
    let mut stack = vec![(ref_root(links, joints), Transform::identity())];
    while let Some((l, pose)) = stack.pop() {
        for j in joints.iter().filter(|j| j.parent == l) {
            stack.push((j.child.clone(), pose.compose(&j.origin)));
        }
        poses.insert(l, pose);
    }
    poses
}

/// World pose of every joint frame of `m` at the neutral configuration.
fn model_joint_poses(m: &Model) -> Vec<Transform> {
    let q = m.neutral();
    let mut o = vec![Transform::identity(); m.njoints()];
    for i in 1..m.njoints() {
        let (a, n) = (m.idx_q()[i], m.nqs()[i]);
        let xj = m.joints()[i].transform(&q.as_slice()[a..a + n]);
        o[i] = o[m.parents()[i]].compose(&m.placements()[i]).compose(&xj);
    }
    o
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

fn assert_transform_close(a: &Transform, b: &Transform, what: &str) {
    assert!((a.rot - b.rot).amax() < 1e-9, "{what}: rotation {} vs {}", a.rot, b.rot);
    assert!((a.trans - b.trans).amax() < 1e-9, "{what}: translation {} vs {}", a.trans, b.trans);
}

fn assert_inertia_close(a: &Inertia, b: &Inertia, what: &str) {
    let scale = 1.0 + a.mass.abs() + a.rot.amax();
    assert!(close(a.mass, b.mass, 1e-12), "{what}: mass {} vs {}", a.mass, b.mass);
    assert!((a.h - b.h).amax() < 1e-9 * scale, "{what}: first moment {} vs {}", a.h, b.h);
    assert!(
        (a.rot - b.rot).amax() < 1e-9 * scale,
        "{what}: rotational inertia {} vs {}",
        a.rot,
        b.rot
    );
}

// ---------------------------------------------------------------------------------------------
// Shared models.

#[test]
fn shared_models_dimensions_match_readme() {
    let dir = models_dir();
    let rows = readme_table(&dir);
    // Every URDF in the directory is in the table.
    for e in std::fs::read_dir(&dir).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        if name.ends_with(".urdf") {
            assert!(rows.iter().any(|r| r.file == name), "{name} is not in README.md's table");
        }
    }
    for row in &rows {
        let m = load_shared(&dir, row);
        let expected_nq = if row.ff { row.nv + 1 } else { row.nv };
        assert_eq!(m.nv(), row.nv, "{}: nv", row.file);
        assert_eq!(m.nq(), expected_nq, "{}: nq", row.file);
        if row.ff {
            assert_eq!(m.names()[1], "root_joint", "{}", row.file);
            assert_eq!(m.joints()[1], JointType::FreeFlyer, "{}", row.file);
        }
        // Also loadable with the other base option.
        let other = load_urdf_file(
            &dir.join(&row.file),
            &UrdfOptions { floating_base: !row.ff, strict_inertia: false, mimic: false },
        )
        .unwrap();
        assert_eq!(other.nv(), if row.ff { row.nv - 6 } else { row.nv + 6 }, "{}", row.file);
    }
}

#[test]
fn shared_models_name_and_joint_types() {
    let dir = models_dir();
    for row in readme_table(&dir) {
        let xml = std::fs::read_to_string(dir.join(&row.file)).unwrap();
        let (name, links, joints) = ref_parse(&xml);
        let m = load_shared(&dir, &row);
        assert_eq!(m.name(), name, "{}", row.file);
        // Every link is a frame (plus "universe").
        assert_eq!(m.frames().len(), links.len() + 1, "{}", row.file);
        for j in joints.iter().filter(|j| j.ty != "fixed") {
            let id = m.joint_id(&j.name).unwrap();
            let got = m.joints()[id].name();
            assert_eq!(got, j.ty.as_str(), "{}: joint {}", row.file, j.name);
            assert_eq!(m.mimic()[id], j.mimic, "{}: mimic of {}", row.file, j.name);
            // The child link sits at the joint frame.
            let f = &m.frames()[m.frame_id(&j.child).unwrap()];
            assert_eq!(f.joint, id);
            assert_eq!(f.placement, Transform::identity());
        }
        for j in joints.iter().filter(|j| j.ty == "fixed") {
            assert!(
                m.joint_id(&j.name).is_err(),
                "{}: fixed joint {} must be merged",
                row.file,
                j.name
            );
        }
    }
}

#[test]
fn shared_models_foot_frames_exist() {
    let dir = models_dir();
    let feet: &[(&str, &[&str])] = &[
        ("solo12.urdf", &["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]),
        ("hyq_no_sensors.urdf", &["lf_foot", "rf_foot", "lh_foot", "rh_foot"]),
        ("anymal.urdf", &["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]),
        ("talos_reduced.urdf", &["left_sole_link", "right_sole_link"]),
        ("talos_full_v2.urdf", &["left_sole_link", "right_sole_link"]),
    ];
    for (file, names) in feet {
        let m = load_urdf_file(&dir.join(file), &FLOATING).unwrap();
        for n in *names {
            let f = &m.frames()[m.frame_id(n).unwrap_or_else(|_| panic!("{file}: no frame {n}"))];
            // On a leg body, below the free flyer.
            assert!(f.joint > 1, "{file}: frame {n} is on joint {}", f.joint);
            assert!(m.is_ancestor(1, f.joint));
        }
    }
}

#[test]
fn shared_models_total_mass_is_sum_of_link_masses() {
    let dir = models_dir();
    for row in readme_table(&dir) {
        let xml = std::fs::read_to_string(dir.join(&row.file)).unwrap();
        let (_, links, _) = ref_parse(&xml);
        let urdf_mass: f64 = links.iter().map(|l| l.inertia.mass).sum();
        for opts in [FIXED, FLOATING] {
            let m = load_urdf_file(&dir.join(&row.file), &opts).unwrap();
            let total: f64 = m.inertias().iter().map(|i| i.mass).sum();
            assert!(close(total, urdf_mass, 1e-12), "{}: {total} vs {urdf_mass}", row.file);
        }
    }
}

/// Frames and lumped inertias land where the URDF puts them: at the neutral configuration,
/// every frame's world pose equals the link's pose from composing joint origins, and the sum of
/// body inertias in the world frame equals the sum of link inertias.
#[test]
fn shared_models_frames_and_inertias_in_world() {
    let dir = models_dir();
    for row in readme_table(&dir) {
        let xml = std::fs::read_to_string(dir.join(&row.file)).unwrap();
        let (_, links, joints) = ref_parse(&xml);
        let poses = ref_link_poses(&links, &joints);
        let mut expected = Inertia::zero();
        for l in &links {
            expected += poses[&l.name].act_inertia(&l.inertia);
        }
        for opts in [FIXED, FLOATING] {
            let m = load_urdf_file(&dir.join(&row.file), &opts).unwrap();
            let o = model_joint_poses(&m);
            for f in &m.frames()[1..] {
                let got = o[f.joint].compose(&f.placement);
                assert_transform_close(
                    &got,
                    &poses[&f.name],
                    &format!("{}: frame {}", row.file, f.name),
                );
            }
            let mut total = Inertia::zero();
            for (oi, yi) in o.iter().zip(m.inertias()) {
                total += oi.act_inertia(yi);
            }
            assert_inertia_close(&total, &expected, &row.file);
            // Every body inertia is physical.
            for (i, y) in m.inertias().iter().enumerate() {
                assert!(
                    y.check_physical().is_ok(),
                    "{}: body {} inertia {:?}",
                    row.file,
                    m.names()[i],
                    y
                );
            }
        }
    }
}

/// Our numbering is the document-order depth-first walk; Pinocchio's (fixtures) is the
/// depth-first walk with siblings sorted by joint name. Both are checked, and that the two
/// trees are the same (same joints, same parents, same dimensions).
#[test]
fn joint_order_matches_pinocchio_fixtures_up_to_sibling_order() {
    let dir = models_dir();
    let fixtures = Path::new(FIXTURES);
    let mut checked = 0;
    let rows = readme_table(&dir);
    for row in &rows {
        let stem = row.file.trim_end_matches(".urdf");
        let path = fixtures.join(format!("{stem}.json"));
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("fixture {}: {e}", path.display()));
        let fx: serde_json::Value = serde_json::from_str(&text).unwrap();
        let fm = &fx["model"];
        let ff = !fm["root_joint"].is_null();
        assert_eq!(ff, row.ff, "{stem}: fixture base type vs README");
        let fj = fm["joints"].as_array().unwrap();
        let pin_names: Vec<String> =
            fj.iter().map(|j| j["name"].as_str().unwrap().to_string()).collect();
        let pin_index: HashMap<i64, &str> = fj
            .iter()
            .map(|j| (j["index"].as_i64().unwrap(), j["name"].as_str().unwrap()))
            .collect();

        let m = load_urdf_file(
            &dir.join(&row.file),
            &UrdfOptions { floating_base: ff, strict_inertia: false, mimic: false },
        )
        .unwrap();
        let skip = if ff { 2 } else { 1 };
        let ours: Vec<String> = m.names()[skip..].to_vec();
        let pin_movable: Vec<String> =
            pin_names.iter().filter(|n| *n != "root_joint").cloned().collect();

        let xml = std::fs::read_to_string(dir.join(&row.file)).unwrap();
        let (_, links, joints) = ref_parse(&xml);
        assert_eq!(ours, ref_dfs(&links, &joints, false), "{stem}: document-order depth-first");
        assert_eq!(
            pin_movable,
            ref_dfs(&links, &joints, true),
            "{stem}: Pinocchio order = name-sorted DFS"
        );

        // Same tree: joint set, parents, dimensions.
        let mut a = ours.clone();
        let mut b = pin_movable.clone();
        a.sort();
        b.sort();
        assert_eq!(a, b, "{stem}: joint sets");
        for j in fj {
            let name = j["name"].as_str().unwrap();
            let id = m.joint_id(name).unwrap();
            let pin_parent = match j["parent"].as_i64().unwrap() {
                0 => "universe",
                p => pin_index[&p],
            };
            assert_eq!(m.names()[m.parents()[id]], pin_parent, "{stem}: parent of {name}");
            assert_eq!(m.nvs()[id] as i64, j["nv"].as_i64().unwrap(), "{stem}: nv of {name}");
            let pin_nq = j["nq"].as_i64().unwrap();
            let expect_nq = if matches!(m.joints()[id], JointType::Continuous { .. }) {
                2
            } else {
                m.nqs()[id] as i64
            };
            assert_eq!(expect_nq, pin_nq, "{stem}: nq of {name} (Pinocchio continuous: nq = 2)");
        }
        assert_eq!(m.nv() as i64, fm["nv"].as_i64().unwrap(), "{stem}: nv");
        let ncont =
            m.joints().iter().filter(|t| matches!(t, JointType::Continuous { .. })).count() as i64;
        assert_eq!(m.nq() as i64 + ncont, fm["nq"].as_i64().unwrap(), "{stem}: nq");
        checked += 1;
    }
    assert_eq!(checked, rows.len());
    eprintln!("checked the joint order of {checked} models against Pinocchio fixtures");
}

#[test]
fn shared_mimic_joints_are_recorded() {
    let dir = models_dir();
    let m = load_urdf_file(&dir.join("panda.urdf"), &FIXED).unwrap();
    let id = m.joint_id("panda_finger_joint2").unwrap();
    assert_eq!(m.mimic()[id].as_deref(), Some("panda_finger_joint1"));
    assert_eq!(m.mimic()[m.joint_id("panda_finger_joint1").unwrap()], None);
    let talos = load_urdf_file(&dir.join("talos_full_v2.urdf"), &FLOATING).unwrap();
    assert_eq!(talos.mimic().iter().filter(|x| x.is_some()).count(), 12);
    // In talos_reduced the mimic joints are fixed, hence merged: nothing recorded.
    let reduced = load_urdf_file(&dir.join("talos_reduced.urdf"), &FLOATING).unwrap();
    assert!(reduced.mimic().iter().all(|x| x.is_none()));
}

// ---------------------------------------------------------------------------------------------
// Hand-written models.

const BRANCHY: &str = r#"<?xml version="1.0"?>
<robot name="branchy">
  <joint name="z_first" type="revolute">
    <parent link="base"/>
    <child link="a"/>
    <origin xyz="1 0 0"/>
    <axis xyz="0 0 2"/>
    <limit lower="-1.5" upper="2.5" effort="1" velocity="1"/>
  </joint>
  <link name="base">
    <inertial><mass value="3"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>
  </link>
  <link name="a"/>
  <link name="a_child"/>
  <link name="b"/>
  <link name="b_fixed"/>
  <link name="b_fixed_2">
    <inertial>
      <origin xyz="0 0 0.5" rpy="0 0 1.5707963267948966"/>
      <mass value="2"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.25"/>
    </inertial>
  </link>
  <link name="b_grandchild"/>
  <joint name="y_second" type="continuous">
    <parent link="base"/>
    <child link="b"/>
    <origin xyz="0 1 0" rpy="0 0 0.3"/>
  </joint>
  <joint name="a_under_z" type="prismatic">
    <parent link="a"/>
    <child link="a_child"/>
    <axis xyz="0 1 0"/>
  </joint>
  <joint name="b_weld" type="fixed">
    <parent link="b"/>
    <child link="b_fixed"/>
    <origin xyz="0 0 1"/>
  </joint>
  <joint name="b_weld_2" type="fixed">
    <parent link="b_fixed"/>
    <child link="b_fixed_2"/>
    <origin xyz="0 0 2" rpy="0.1 0 0"/>
  </joint>
  <joint name="b_deep" type="revolute">
    <parent link="b_fixed_2"/>
    <child link="b_grandchild"/>
    <origin xyz="0 0 3"/>
  </joint>
  <visual><geometry><box size="1 1 1"/></geometry></visual>
  <transmission name="t"><joint name="ignored_transmission_joint"/></transmission>
  <gazebo><link name="ignored_gazebo_link"/></gazebo>
</robot>
"#;

#[test]
fn depth_first_order_in_document_order() {
    let m = load_urdf_str(BRANCHY, "branchy.urdf", &FIXED).unwrap();
    assert_eq!(m.name(), "branchy");
    assert_eq!(m.names(), ["universe", "z_first", "a_under_z", "y_second", "b_deep"]);
    assert_eq!(m.parents(), [0, 0, 1, 0, 3]);
    let frames: Vec<&str> = m.frames().iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        frames,
        ["universe", "base", "a", "a_child", "b", "b_fixed", "b_fixed_2", "b_grandchild"]
    );
    assert_eq!((m.nq(), m.nv()), (4, 4));
    assert!(m.frame_id("ignored_gazebo_link").is_err());
}

#[test]
fn joint_types_axes_and_limits() {
    let m = load_urdf_str(BRANCHY, "branchy.urdf", &FIXED).unwrap();
    // Axis normalised; default axis x.
    assert_eq!(m.joints()[1], JointType::Revolute { axis: Vector3::z() });
    assert_eq!(m.joints()[2], JointType::Prismatic { axis: Vector3::y() });
    assert_eq!(m.joints()[3], JointType::Continuous { axis: Vector3::x() });
    assert_eq!(m.joints()[4], JointType::Revolute { axis: Vector3::x() });
    assert_eq!((m.lower()[0], m.upper()[0]), (-1.5, 2.5));
    // Prismatic and revolute without <limit>, continuous: unlimited.
    for k in 1..4 {
        assert_eq!(
            (m.lower()[k], m.upper()[k]),
            (f64::NEG_INFINITY, f64::INFINITY),
            "coordinate {k}"
        );
    }
}

#[test]
fn fixed_joints_are_merged_with_composed_placements() {
    let m = load_urdf_str(BRANCHY, "branchy.urdf", &FIXED).unwrap();
    let b = m.joint_id("y_second").unwrap();
    let weld1 = Transform::from_rpy_xyz([0.0; 3], [0.0, 0.0, 1.0]);
    let weld2 = weld1.compose(&Transform::from_rpy_xyz([0.1, 0.0, 0.0], [0.0, 0.0, 2.0]));
    let f1 = &m.frames()[m.frame_id("b_fixed").unwrap()];
    let f2 = &m.frames()[m.frame_id("b_fixed_2").unwrap()];
    assert_eq!(f1.joint, b);
    assert_eq!(f2.joint, b);
    assert_transform_close(&f1.placement, &weld1, "b_fixed");
    assert_transform_close(&f2.placement, &weld2, "b_fixed_2");
    // The joint below the welded links is placed through them.
    let deep = m.joint_id("b_deep").unwrap();
    assert_eq!(m.parents()[deep], b);
    assert_transform_close(
        &m.placements()[deep],
        &weld2.compose(&Transform::from_translation(Vector3::new(0.0, 0.0, 3.0))),
        "b_deep placement",
    );
    // b_fixed_2's inertia lumped into body "y_second" at the composed placement.
    let r = Transform::from_rpy_xyz([0.0, 0.0, std::f64::consts::FRAC_PI_2], [0.0, 0.0, 0.5]);
    let ic = Matrix3::from_diagonal(&Vector3::new(0.1, 0.2, 0.25));
    let in_link = r.act_inertia(&Inertia::from_com(2.0, Vector3::zeros(), ic));
    assert_inertia_close(&m.inertias()[b], &weld2.act_inertia(&in_link), "lumped inertia");
    // The rotated inertial: about the COM, Ixx and Iyy swap.
    let about_com = in_link.inertia_about_com();
    assert!((about_com[(0, 0)] - 0.2).abs() < 1e-12 && (about_com[(1, 1)] - 0.1).abs() < 1e-12);
    // Root inertia on joint 0 with a fixed base.
    assert_eq!(m.inertias()[0].mass, 3.0);
    let total: f64 = m.inertias().iter().map(|i| i.mass).sum();
    assert_eq!(total, 5.0);
}

#[test]
fn floating_base_adds_root_joint() {
    let m = load_urdf_str(BRANCHY, "branchy.urdf", &FLOATING).unwrap();
    assert_eq!(m.names(), ["universe", "root_joint", "z_first", "a_under_z", "y_second", "b_deep"]);
    assert_eq!(m.joints()[1], JointType::FreeFlyer);
    assert_eq!((m.nq(), m.nv()), (11, 10));
    assert_eq!(m.parents(), [0, 0, 1, 2, 1, 4]);
    let base = &m.frames()[m.frame_id("base").unwrap()];
    assert_eq!((base.joint, base.placement), (1, Transform::identity()));
    assert_eq!(m.inertias()[0].mass, 0.0);
    assert_eq!(m.inertias()[1].mass, 3.0);
    // Limits follow the joints (the free flyer's 7 coordinates are unlimited).
    assert_eq!((m.lower()[7], m.upper()[7]), (-1.5, 2.5));
    // A movable joint named root_joint clashes with the free flyer.
    let clash = BRANCHY.replace("\"z_first\"", "\"root_joint\"");
    let e = load_urdf_str(&clash, "clash.urdf", &FLOATING).unwrap_err().to_string();
    assert!(
        e.contains("clash.urdf:3:") && e.contains("joint \"root_joint\"") && e.contains("reserved"),
        "{e}"
    );
    assert!(load_urdf_str(&clash, "clash.urdf", &FIXED).is_ok());
}

fn tiny(joint: &str) -> String {
    format!(
        r#"<robot name="tiny">
  <link name="base"/>
  <link name="moved"/>
  <joint name="j" {joint}
</robot>"#
    )
}

#[test]
fn floating_and_planar_joints() {
    let j = |ty: &str, axis: &str| {
        tiny(&format!(r#"type="{ty}"><parent link="base"/><child link="moved"/>{axis}</joint>"#))
    };
    let m = load_urdf_str(&j("floating", ""), "f.urdf", &FIXED).unwrap();
    assert_eq!(m.joints()[1], JointType::FreeFlyer);
    assert_eq!((m.nq(), m.nv()), (7, 6));
    for axis in ["", r#"<axis xyz="0 0 1"/>"#, r#"<axis xyz="0 0 3"/>"#] {
        let m = load_urdf_str(&j("planar", axis), "p.urdf", &FIXED).unwrap();
        assert_eq!(m.joints()[1], JointType::Planar, "{axis}");
        assert_eq!((m.nq(), m.nv()), (3, 3));
    }
    let e = load_urdf_str(&j("planar", r#"<axis xyz="0 0 -1"/>"#), "p.urdf", &FIXED).unwrap_err();
    assert!(e.to_string().contains("unsupported joint type \"planar\""), "{e}");
}

#[test]
fn mimic_joint_is_recorded() {
    let xml = r#"<robot name="gripper">
  <link name="palm"/><link name="left"/><link name="right"/>
  <joint name="left_finger" type="prismatic">
    <parent link="palm"/><child link="left"/><limit lower="0" upper="0.04"/>
  </joint>
  <joint name="right_finger" type="prismatic">
    <parent link="palm"/><child link="right"/><axis xyz="0 -1 0"/><limit lower="0" upper="0.04"/>
    <mimic joint="left_finger" multiplier="1" offset="0"/>
  </joint>
</robot>"#;
    let m = load_urdf_str(xml, "gripper.urdf", &FIXED).unwrap();
    assert_eq!((m.nq(), m.nv()), (2, 2));
    assert_eq!(m.mimic()[1], None);
    assert_eq!(m.mimic()[2].as_deref(), Some("left_finger"));
    assert_eq!(m.joints()[2], JointType::Prismatic { axis: -Vector3::y() });
    assert_eq!((m.lower()[1], m.upper()[1]), (0.0, 0.04));

    assert!(m.warnings().is_empty(), "{:?}", m.warnings());

    // A <mimic> naming an unknown joint (alex_psyonic_hands of example-robot-data) or the joint
    // itself: loads (the joint is independent anyway) with a warning naming file, line and
    // joint; nothing is recorded. Also with strict_inertia, which is about inertias only.
    for (target, what) in
        [("lfet_finger", "the unknown joint \"lfet_finger\""), ("right_finger", "the joint itself")]
    {
        let bad = xml.replace("mimic joint=\"left_finger\"", &format!("mimic joint=\"{target}\""));
        for opts in [FIXED, STRICT] {
            let m = load_urdf_str(&bad, "gripper.urdf", &opts).unwrap();
            assert_eq!((m.nq(), m.nv()), (2, 2));
            assert_eq!(m.mimic()[2], None);
            assert_eq!(m.warnings().len(), 1, "{:?}", m.warnings());
            let w = &m.warnings()[0];
            assert!(
                w.starts_with("gripper.urdf:8: joint \"right_finger\": <mimic> refers to ")
                    && w.contains(what)
                    && w.contains("loaded as independent"),
                "{w}"
            );
        }
    }
    // A <mimic> without a joint attribute stays an error (urdfdom refuses it too).
    let bad = xml.replace("mimic joint=\"left_finger\"", "mimic");
    let e = load_urdf_str(&bad, "gripper.urdf", &FIXED).unwrap_err().to_string();
    assert!(e.contains("gripper.urdf:8:") && e.contains("<mimic> has no joint attribute"), "{e}");
}

#[test]
fn massless_links_and_missing_origins_are_valid() {
    let xml = r#"<robot name="m">
  <link name="base"/>
  <link name="tip"><inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="tip"/></joint>
</robot>"#;
    let m = load_urdf_str(xml, "m.urdf", &FIXED).unwrap();
    assert!(m.inertias().iter().all(|i| *i == Inertia::zero()));
    assert_eq!(m.placements()[1], Transform::identity());
    // A single link and no joint: an empty tree.
    let m = load_urdf_str(r#"<robot name="one"><link name="only"/></robot>"#, "one.urdf", &FIXED)
        .unwrap();
    assert_eq!((m.njoints(), m.nq(), m.frames().len()), (1, 0, 2));
}

// ---------------------------------------------------------------------------------------------
// Malformed inputs: one test per error, each checking file, line, element and reason.

/// `file` of `tests/data/urdf` is refused with `strict_inertia` (every one of them is; only
/// `triangle.urdf` loads without it, with a warning).
#[track_caller]
fn expect_file_error(file: &str, line: u32, element: &str, reason: &str) {
    let path = Path::new(DATA).join(file);
    if file != "triangle.urdf" {
        load_urdf_file(&path, &FIXED).expect_err(file);
    }
    let e = load_urdf_file(&path, &STRICT).expect_err(file);
    let msg = e.to_string();
    assert!(msg.contains(file), "message lacks the file name: {msg}");
    assert!(msg.contains(&format!("{file}:{line}: ")), "message lacks line {line}: {msg}");
    assert!(msg.contains(element), "message lacks element {element:?}: {msg}");
    assert!(msg.contains(reason), "message lacks reason {reason:?}: {msg}");
    match e {
        Error::Model { line: l, element: el, .. } => {
            assert_eq!(l, Some(line), "{msg}");
            assert_eq!(el, element, "{msg}");
        }
        other => panic!("expected Error::Model, got {other:?}"),
    }
}

#[track_caller]
fn expect_str_error(xml: &str, line: u32, element: &str, reason: &str) {
    let e = load_urdf_str(xml, "inline.urdf", &FIXED).expect_err("must fail");
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("inline.urdf:{line}: {element}: ")), "{msg}");
    assert!(msg.contains(reason), "message lacks reason {reason:?}: {msg}");
}

#[test]
fn error_bad_xml() {
    expect_file_error("bad_xml.urdf", 4, "XML", "malformed XML");
}

#[test]
fn error_root_not_robot() {
    expect_file_error("not_robot.urdf", 2, "<model>", "expected <robot>");
}

#[test]
fn error_missing_robot_name() {
    expect_file_error("robot_no_name.urdf", 3, "<robot>", "missing name attribute");
}

#[test]
fn error_missing_link_name() {
    expect_file_error("link_no_name.urdf", 4, "<link>", "missing name attribute");
}

#[test]
fn error_missing_joint_name() {
    expect_file_error("joint_no_name.urdf", 5, "<joint>", "missing name attribute");
}

#[test]
fn error_duplicate_link() {
    expect_file_error(
        "duplicate_link.urdf",
        6,
        "link \"arm\"",
        "duplicate link name (first defined at line 4)",
    );
}

#[test]
fn error_duplicate_joint() {
    expect_file_error(
        "duplicate_joint.urdf",
        10,
        "joint \"shoulder\"",
        "duplicate joint name (first defined at line 6)",
    );
}

#[test]
fn error_unknown_parent_link() {
    expect_file_error(
        "unknown_parent.urdf",
        6,
        "joint \"shoulder\"",
        "parent link \"bsae\" is not defined",
    );
}

#[test]
fn error_unknown_child_link() {
    expect_file_error(
        "unknown_child.urdf",
        11,
        "joint \"wrist\"",
        "child link \"hand\" is not defined",
    );
}

#[test]
fn error_link_with_two_parents() {
    expect_file_error(
        "two_parents.urdf",
        14,
        "joint \"closing_joint\"",
        "link \"right\" already has the parent joint \"right_joint\" (line 10)",
    );
}

#[test]
fn error_cycle() {
    expect_file_error(
        "cycle.urdf",
        15,
        "joint \"j_ca\"",
        "kinematic cycle: link \"a\" -> joint \"j_ab\" -> link \"b\" -> joint \"j_bc\" -> link \"c\" -> joint \"j_ca\" -> link \"a\"",
    );
    // Without any root (every link is a child), and a joint from a link to itself.
    expect_str_error(
        r#"<robot name="r">
  <link name="a"/>
  <link name="b"/>
  <joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>
  <joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>
</robot>"#,
        5,
        "joint \"ba\"",
        "kinematic cycle",
    );
    expect_str_error(
        r#"<robot name="r">
  <link name="base"/>
  <link name="a"/>
  <joint name="aa" type="revolute"><parent link="a"/><child link="a"/></joint>
</robot>"#,
        4,
        "joint \"aa\"",
        "kinematic cycle: link \"a\" -> joint \"aa\" -> link \"a\"",
    );
}

#[test]
fn error_two_roots() {
    expect_file_error(
        "two_roots.urdf",
        5,
        "link \"floating_box\"",
        "2 root links (links that are no joint's child): \"base\" (line 3), \"floating_box\" (line 5)",
    );
}

#[test]
fn error_no_links() {
    expect_file_error("no_links.urdf", 2, "robot \"no_links\"", "no <link> elements");
}

#[test]
fn error_unparsable_vector() {
    expect_file_error(
        "bad_xyz.urdf",
        7,
        "joint \"elbow\"",
        "<origin> attribute xyz=\"1 2\": expected 3 numbers, found 2",
    );
}

#[test]
fn error_unparsable_mass() {
    expect_file_error(
        "bad_mass.urdf",
        6,
        "link \"base\"",
        "<mass> attribute value=\"abc\": \"abc\" is not a number",
    );
}

#[test]
fn error_non_finite_number() {
    expect_file_error(
        "non_finite.urdf",
        7,
        "link \"foot\"",
        "<inertia> attribute ixx=\"inf\": \"inf\" is not finite",
    );
    expect_str_error(
        &tiny(
            r#"type="revolute"><origin rpy="0 NaN 0"/><parent link="base"/><child link="moved"/></joint>"#,
        ),
        4,
        "joint \"j\"",
        "\"NaN\" is not finite",
    );
}

#[test]
fn error_negative_mass() {
    expect_file_error("negative_mass.urdf", 6, "link \"foot\"", "negative mass -2.5");
}

#[test]
fn error_inertia_not_positive_semi_definite() {
    expect_file_error("not_psd.urdf", 7, "link \"thigh\"", "not positive semi-definite");
}

/// A positive semi-definite inertia that violates the triangle inequality: an error with
/// `strict_inertia`, otherwise a warning naming file, line and link (romeo_small of
/// example-robot-data), the inertia loaded as written.
#[test]
fn error_inertia_triangle_inequality() {
    expect_file_error("triangle.urdf", 7, "link \"shin\"", "violate the triangle inequality");
    let path = Path::new(DATA).join("triangle.urdf");
    let m = load_urdf_file(&path, &FIXED).unwrap();
    assert_eq!(m.warnings().len(), 1, "{:?}", m.warnings());
    let w = &m.warnings()[0];
    assert!(
        w.starts_with(&format!("{}:7: link \"shin\": ", path.display()))
            && w.contains("violate the triangle inequality")
            && w.contains("positive semi-definite")
            && w.contains("strict_inertia"),
        "{w}"
    );
    assert_eq!(m.inertias()[1].rot, Matrix3::from_diagonal(&Vector3::new(0.1, 0.1, 0.5)));
}

/// Principal moments negative by round-off (below `1e-12` of the largest or `1e-15` kg m², as
/// icub's `ixx="-5.42101e-20"` of example-robot-data) are taken as zero, also with
/// `strict_inertia`; larger negative moments stay errors, with or without it.
#[test]
fn inertia_round_off_is_zero() {
    let xml = |ixx: &str, iyy: &str, izz: &str| {
        format!(
            r#"<robot name="r">
  <link name="base"/>
  <link name="hip">
    <inertial><origin xyz="0 0 0.03045"/><mass value="0.526"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>
  </link>
  <joint name="j" type="revolute"><parent link="base"/><child link="hip"/></joint>
</robot>"#
        )
    };
    // icub's r_hip_2: every moment within 1e-15 of zero: a point mass.
    for opts in [FIXED, STRICT] {
        let m = load_urdf_str(&xml("-5.42101e-20", "-5.42101e-20", "0"), "r.urdf", &opts).unwrap();
        assert!(m.warnings().is_empty(), "{:?}", m.warnings());
        let i = &m.inertias()[1];
        assert_eq!(i.mass, 0.526);
        assert!(i.inertia_about_com().amax() < 1e-18, "{}", i.inertia_about_com());
        // Relative: -1e-14 against a largest moment of 0.1 (1e-13 of it) is zero.
        let m = load_urdf_str(&xml("-1e-14", "0.1", "0.1"), "r.urdf", &opts).unwrap();
        let ic = m.inertias()[1].inertia_about_com();
        assert!(ic[(0, 0)] == 0.0 || ic[(0, 0)].abs() < 1e-17, "{ic}");
        assert!(close(ic[(1, 1)], 0.1, 1e-14) && close(ic[(2, 2)], 0.1, 1e-14), "{ic}");
        // Not round-off: -1e-14 alone (above 1e-15), -1e-9 against 0.1 (1e-8 of it).
        for bad in [xml("-1e-14", "0", "0"), xml("-1e-9", "0.1", "0.1")] {
            let e = load_urdf_str(&bad, "r.urdf", &opts).unwrap_err().to_string();
            assert!(
                e.starts_with("r.urdf:5: link \"hip\": ")
                    && e.contains("not positive semi-definite"),
                "{e}"
            );
        }
    }
    // A moment that is not negative is never changed.
    let m = load_urdf_str(&xml("0.01", "0.02", "0.025"), "r.urdf", &FIXED).unwrap();
    assert_eq!(m.inertias()[1].inertia_about_com().diagonal(), Vector3::new(0.01, 0.02, 0.025));
}

/// A point mass off the joint axis, alone in its body: `Ī_c = Ī_o + m [c]×²` computes to
/// principal moments of ±1e-19 instead of 0, which the model's check took for a
/// non-positive-semi-definite body (the tolerance now includes the rounding of the shift).
#[test]
fn point_mass_off_the_origin_loads() {
    for com in ["0.0123 -0.0456 0.0789", "0.031 0.0721 0.0113", "1.3 -2.7 0.9"] {
        let xml = format!(
            r#"<robot name="pm">
  <link name="base"/>
  <link name="a"><inertial><origin xyz="{com}" rpy="0.3 0.2 0.1"/><mass value="0.731"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="a"/><origin rpy="0.1 0.2 0.3"/></joint>
</robot>"#
        );
        for opts in [FIXED, STRICT] {
            let m = load_urdf_str(&xml, "pm.urdf", &opts).unwrap_or_else(|e| panic!("{com}: {e}"));
            assert!(m.warnings().is_empty());
            assert_eq!(m.inertias()[1].mass, 0.731);
        }
    }
}

/// A link that is not positive semi-definite is an error with or without `strict_inertia`
/// (Pinocchio loads romeo_laas_small of example-robot-data, whose "body", "LHipPitch_link"
/// and "RHipPitch_link" have principal moments down to -2.1e-2: we do not).
#[test]
fn not_positive_semi_definite_is_always_an_error() {
    for opts in [FIXED, STRICT, FLOATING] {
        let e = load_urdf_file(&Path::new(DATA).join("not_psd.urdf"), &opts).unwrap_err();
        assert!(e.to_string().contains("not positive semi-definite"), "{e}");
    }
}

#[test]
fn error_missing_joint_type() {
    expect_file_error("missing_joint_type.urdf", 5, "joint \"shoulder\"", "missing type attribute");
}

#[test]
fn error_unknown_joint_type() {
    expect_file_error(
        "unknown_joint_type.urdf",
        5,
        "joint \"shoulder\"",
        "unknown or unsupported joint type \"spherical\"",
    );
}

#[test]
fn error_unsupported_planar_axis() {
    expect_file_error(
        "planar_axis.urdf",
        8,
        "joint \"table\"",
        "unsupported joint type \"planar\" with normal axis [1 0 0]",
    );
}

#[test]
fn error_zero_axis() {
    expect_file_error("zero_axis.urdf", 8, "joint \"shoulder\"", "axis [0 0 0] has zero length");
}

#[test]
fn error_missing_parent_element_and_missing_file() {
    expect_str_error(
        &tiny(r#"type="revolute"><child link="moved"/></joint>"#),
        4,
        "joint \"j\"",
        "missing <parent> element",
    );
    let missing = Path::new(DATA).join("does_not_exist.urdf");
    let e = load_urdf_file(&missing, &FIXED).unwrap_err().to_string();
    assert!(e.contains("does_not_exist.urdf") && e.contains("cannot read"), "{e}");
}

#[test]
fn error_reserved_link_name() {
    expect_str_error(
        r#"<robot name="r">
  <link name="universe"/>
</robot>"#,
        2,
        "link \"universe\"",
        "reserved",
    );
}

/// Placeholder inertials (non-physical but negligible, as on the dummy links of hyq, anymal and
/// tiago) are accepted when the body they are merged into is physical; otherwise the link is
/// reported.
#[test]
fn placeholder_inertia_merged_into_physical_body() {
    let xml = |heavy: &str| {
        format!(
            r#"<robot name="placeholder">
  <link name="base"/>
  <link name="shin">
    <inertial><mass value="{heavy}"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.002"/></inertial>
  </link>
  <link name="foot">
    <inertial><mass value="0.000001"/><inertia ixx="0.000001" ixy="0.000001" ixz="0.000001" iyy="0.000001" iyz="0.000001" izz="0.000001"/></inertial>
  </link>
  <joint name="knee" type="revolute"><parent link="base"/><child link="shin"/></joint>
  <joint name="ankle" type="fixed"><parent link="shin"/><child link="foot"/><origin xyz="0 0 -0.3"/></joint>
</robot>"#
        )
    };
    let m = load_urdf_str(&xml("1.5"), "placeholder.urdf", &FIXED).unwrap();
    assert!(m.inertias()[1].check_physical().is_ok());
    assert!(close(m.inertias()[1].mass, 1.5 + 1e-6, 1e-15));
    // A massless, inertia-less shin leaves the placeholder alone in its body: reported.
    let bad = xml("0").replace(
        "ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.002\"",
        "ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"",
    );
    let reason = "violate the triangle inequality; the body of joint \"knee\" (links \"shin\", \"foot\" merged) is not physical either";
    let e = load_urdf_str(&bad, "inline.urdf", &STRICT).unwrap_err().to_string();
    assert!(e.starts_with("inline.urdf:7: link \"foot\": ") && e.contains(reason), "{e}");
    // Without strict_inertia: the body is positive semi-definite, a warning.
    let m = load_urdf_str(&bad, "inline.urdf", &FIXED).unwrap();
    assert_eq!(m.warnings().len(), 1);
    let w = &m.warnings()[0];
    assert!(w.starts_with("inline.urdf:7: link \"foot\": ") && w.contains(reason), "{w}");
    // A heavy shin: no warning.
    assert!(load_urdf_str(&xml("1.5"), "p.urdf", &STRICT).unwrap().warnings().is_empty());
}

// ---------------------------------------------------------------------------------------------
// What Pinocchio and Bullet load: reversed limits, and an XML declaration after whitespace
// (python/tests/test_urdf_leniency.py checks the same files against Pinocchio 4.1).

#[test]
fn reversed_limits_load_as_unlimited_with_a_warning() {
    let path = Path::new(LENIENT).join("reversed_limits.urdf");
    let file = path.display().to_string();
    for opts in [FIXED, STRICT, FLOATING] {
        let m = load_urdf_file(&path, &opts).unwrap();
        let q0 = if opts.floating_base { 7 } else { 0 };
        let names: Vec<&str> = m.names()[1..].iter().map(String::as_str).collect();
        let skip = usize::from(opts.floating_base);
        assert_eq!(&names[skip..], ["x_to_world", "shoulder", "elbow", "wrist"]);
        let lim = |k: usize| (m.lower()[q0 + k], m.upper()[q0 + k]);
        // Reversed: unlimited. Equal (the absent lower and upper of `elbow`): kept. Ordered: kept.
        assert_eq!(lim(0), (f64::NEG_INFINITY, f64::INFINITY));
        assert_eq!(lim(1), (f64::NEG_INFINITY, f64::INFINITY));
        assert_eq!(lim(2), (0.0, 0.0));
        assert_eq!(lim(3), (-1.5, 1.5));
        assert_eq!(
            m.warnings(),
            [
                format!(
                    "{file}:27: joint \"x_to_world\": <limit lower=\"1\" upper=\"-1\">: lower > \
                     upper, read as \"not limited\": loaded without limits"
                ),
                format!(
                    "{file}:32: joint \"shoulder\": <limit lower=\"0.5\" upper=\"-0.5\">: lower \
                     > upper, read as \"not limited\": loaded without limits"
                ),
            ]
        );
        // Random configurations sample the reversed joints as unlimited ones (prismatic in
        // [-1, 1], revolute in [-π, π]), like the zero-width `elbow`; `wrist` within its limits.
        let mut rng = sodyn::rng::Rng::new(3);
        let (mut lo, mut hi) = ([f64::INFINITY; 4], [f64::NEG_INFINITY; 4]);
        for _ in 0..2000 {
            let q = m.random_configuration(&mut rng);
            for k in 0..4 {
                lo[k] = lo[k].min(q[q0 + k]);
                hi[k] = hi[k].max(q[q0 + k]);
            }
        }
        let pi = std::f64::consts::PI;
        for (k, bound) in [(0, 1.0), (1, pi), (2, pi), (3, 1.5)] {
            assert!(lo[k] >= -bound && hi[k] <= bound, "q[{k}] in [{}, {}]", lo[k], hi[k]);
            assert!(
                lo[k] < -0.9 * bound && hi[k] > 0.9 * bound,
                "q[{k}] in [{}, {}]",
                lo[k],
                hi[k]
            );
        }
    }
}

/// The files of the whitespace class load as the file without it: same model, no warning.
#[test]
fn xml_declaration_after_whitespace_loads() {
    let plain = |f: &str| {
        let text = std::fs::read_to_string(Path::new(LENIENT).join(f)).unwrap();
        let start = text.find("<robot").unwrap();
        // The same text with nothing before the root element, each line at its place.
        let lines = text[..start].matches('\n').count();
        "\n".repeat(lines) + &text[start..]
    };
    for (file, name) in [
        ("declaration_after_blank_line.urdf", "declaration_after_blank_line"),
        ("declaration_after_bom_and_whitespace.urdf", "declaration_after_bom_and_whitespace"),
    ] {
        let m = load_urdf_file(&Path::new(LENIENT).join(file), &FIXED).unwrap();
        let reference = load_urdf_str(&plain(file), file, &FIXED).unwrap();
        assert_eq!(m.name(), name);
        assert_eq!((m.nq(), m.nv(), m.njoints()), (2, 2, 3));
        assert_eq!(m.names(), reference.names());
        assert_eq!(m.placements(), reference.placements());
        assert_eq!(m.inertias(), reference.inertias());
        assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    }
    // Lines stay those of the file: an error after the moved declaration, and one inside it.
    let text =
        std::fs::read_to_string(Path::new(LENIENT).join("declaration_after_blank_line.urdf"))
            .unwrap();
    let bad = text.replace(r#"<axis xyz="0 1 0"/>"#, r#"<axis xyz="0 one 0"/>"#);
    let line = 1 + text[..text.find(r#"<axis xyz="0 1 0"/>"#).unwrap()].matches('\n').count();
    expect_str_error(&bad, line as u32, "joint \"j1\"", "\"one\" is not a number");
    let bad = text.replace(r#"<?xml version="1.0" ?>"#, r#"<?xml version="1.0" encodin="x"?>"#);
    let e = load_urdf_str(&bad, "inline.urdf", &FIXED).unwrap_err().to_string();
    assert!(e.starts_with("inline.urdf:2: XML: malformed XML: ") && e.contains(" at 2:"), "{e}");
    // A BOM directly before the declaration, and CRLF line ends before it.
    for prefix in ["\u{FEFF}", "\r\n\r\n", "\u{FEFF}\r\n \t"] {
        let xml = format!("{prefix}{}", text.trim_start());
        let m = load_urdf_str(&xml, "inline.urdf", &FIXED).unwrap();
        assert_eq!(m.nv(), 2, "{prefix:?}");
    }
}

/// Anything but whitespace (and a BOM) before the XML declaration stays an error naming the
/// declaration's line, as in urdfdom.
#[test]
fn xml_declaration_after_other_content_is_an_error() {
    let body = r#"<robot name="r"><link name="a"/></robot>"#;
    for (prefix, line) in [
        ("<!-- comment -->\n", 2),
        ("\n\n<!-- comment -->\n\n", 5),
        ("x\n", 1),
        ("<?xml version=\"1.0\"?>\n", 2),
        ("\n<?xml version=\"1.0\"?>\n", 3),
    ] {
        let xml = format!("{prefix}<?xml version=\"1.0\"?>\n{body}");
        let e = load_urdf_str(&xml, "inline.urdf", &FIXED).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with(&format!("inline.urdf:{line}: XML: malformed XML")), "{msg}");
    }
}

/// The MJCF loader shares the declaration handling.
#[test]
fn mjcf_xml_declaration_after_whitespace_loads() {
    use sodyn::model::{MjcfOptions, load_mjcf_str};
    let body = r#"<mujoco model="m">
  <worldbody>
    <body name="b"><joint name="h" type="hinge"/><geom type="sphere" size="0.1"/></body>
  </worldbody>
</mujoco>"#;
    let opts = MjcfOptions::default();
    for prefix in ["", "\n", "\u{FEFF}\n  \n", "\r\n\t"] {
        let xml = format!("{prefix}<?xml version=\"1.0\" encoding=\"utf-8\"?>\n{body}");
        let m = load_mjcf_str(&xml, "m.xml", Path::new("."), &opts)
            .unwrap_or_else(|e| panic!("{prefix:?}: {e}"));
        assert_eq!(m.nv(), 1, "{prefix:?}");
    }
    let xml = format!("<!-- c -->\n<?xml version=\"1.0\"?>\n{body}");
    let e = load_mjcf_str(&xml, "m.xml", Path::new("."), &opts).unwrap_err().to_string();
    assert!(e.starts_with("m.xml:2: XML: malformed XML"), "{e}");
    // Lines after a moved declaration are the file's.
    let bad = format!("\n\n<?xml version=\"1.0\"?>\n{}", body.replace("hinge", "hinj"));
    let e = load_mjcf_str(&bad, "m.xml", Path::new("."), &opts).unwrap_err().to_string();
    assert!(e.starts_with("m.xml:6:"), "{e}");
}

fn mimic_urdf(finger_r: &str, mimic: &str) -> String {
    format!(
        r#"<robot name="t">
  <link name="base"/>
  <link name="a"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="c"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint>
  <joint name="jb" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/></joint>
  <joint name="jc" type="{finger_r}"><parent link="b"/><child link="c"/><axis xyz="0 1 0"/>
    {mimic}
  </joint>
</robot>"#
    )
}

fn load_err(xml: &str) -> String {
    sodyn::model::load_urdf_str(xml, "t.urdf", &crate::util::mimic::opts(false))
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_mimic_elements_are_errors_naming_the_joint() {
    let ok = sodyn::model::load_urdf_str(
        &mimic_urdf("continuous", r#"<mimic joint="ja" multiplier="2" offset="0.5"/>"#),
        "t.urdf",
        &crate::util::mimic::opts(false),
    )
    .unwrap();
    assert_eq!((ok.nq(), ok.nv()), (2, 2));
    for (kind, mimic, expect) in [
        ("revolute", r#"<mimic joint="nope"/>"#, "\"nope\" is not a joint of the file"),
        ("revolute", r#"<mimic joint="jc"/>"#, "cannot mimic itself"),
        ("revolute", r#"<mimic joint="jb"/>"#, "both must be rotational"),
        ("prismatic", r#"<mimic joint="ja"/>"#, "both must be rotational"),
        ("floating", r#"<mimic joint="ja"/>"#, "must be revolute, continuous or prismatic"),
        ("revolute", r#"<mimic joint="ja" multiplier="x"/>"#, "is not a number"),
        ("revolute", r#"<mimic joint="ja" offset="nan"/>"#, "offset"),
    ] {
        let e = load_err(&mimic_urdf(kind, mimic));
        assert!(e.contains("joint \"jc\"") && e.contains(expect), "{kind} {mimic}: {e}");
        assert!(e.contains("t.urdf:"), "{e}");
    }
    // A reference that is itself a mimic joint; a fixed reference.
    let chain = mimic_urdf("revolute", r#"<mimic joint="ja"/>"#).replace(
        r#"<child link="a"/><axis xyz="0 0 1"/>"#,
        r#"<child link="a"/><axis xyz="0 0 1"/><mimic joint="jc"/>"#,
    );
    let e = load_err(&chain);
    assert!(e.contains("is itself a mimic joint"), "{e}");
    let fixed_ref = mimic_urdf("revolute", r#"<mimic joint="ja"/>"#)
        .replace(r#"name="ja" type="revolute""#, r#"name="ja" type="fixed""#);
    let e = load_err(&fixed_ref);
    assert!(e.contains("joint \"jc\"") && e.contains("is fixed"), "{e}");
    // Without the option, the same files load (unknown references as a warning).
    let plain = sodyn::model::load_urdf_str(
        &mimic_urdf("revolute", r#"<mimic joint="nope"/>"#),
        "t.urdf",
        &UrdfOptions::default(),
    )
    .unwrap();
    assert_eq!(plain.warnings().len(), 1);
}
