//! Regression tests of the fuzz targets (`fuzz/`, issue 32 item 5; CI runs these, not the
//! fuzzer): every reproducer of `tests/data/fuzz/<target>/` and every seed of
//! `fuzz/corpus/<target>/` goes through the same checks as the fuzz target (the file
//! `fuzz/fuzz_targets/checks.rs`, included here), which panic on a failure; plus one test per
//! finding that states the expected error.

use sodyn::model::{MAX_URDF_DOFS, UrdfOptions, load_urdf_str};
use std::path::{Path, PathBuf};

#[allow(dead_code)]
#[path = "../../../fuzz/fuzz_targets/checks.rs"]
mod checks;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The files of `dir`, sorted (at least one).
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    assert!(!v.is_empty(), "{}: no files", dir.display());
    v
}

/// Runs `check` on every file of `tests/data/fuzz/<target>` and `fuzz/corpus/<target>`,
/// naming the file that fails.
fn replay(target: &str, check: impl Fn(&[u8])) {
    for dir in [format!("tests/data/fuzz/{target}"), format!("fuzz/corpus/{target}")] {
        for f in files(&Path::new(ROOT).join(dir)) {
            let bytes = std::fs::read(&f).unwrap();
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&bytes)));
            assert!(r.is_ok(), "{target}: {} fails the fuzz target's checks", f.display());
        }
    }
}

#[test]
fn urdf_reproducers_and_seeds() {
    replay("urdf", |b| {
        checks::urdf(b);
    });
}

#[test]
fn mjcf_reproducers_and_seeds() {
    replay("mjcf", |b| {
        checks::mjcf(b);
    });
    // The seeds are the test models, which load.
    for f in files(&Path::new(ROOT).join("fuzz/corpus/mjcf")) {
        if f.file_name().unwrap().to_string_lossy().starts_with("features") {
            continue; // it includes features_defaults.xml, not found from the fuzz directory
        }
        assert!(checks::mjcf(&std::fs::read(&f).unwrap()) > 0, "seed {}", f.display());
    }
}

/// Finding (review of the MJCF loader): `<include>` read any path, and `/dev/zero` never ends.
/// Only regular files of at most 256 MB are included now.
#[test]
fn mjcf_include_of_a_device_is_an_error() {
    let f = Path::new(ROOT).join("tests/data/fuzz/mjcf/include_dev_zero.xml");
    let xml = std::fs::read_to_string(f).unwrap();
    let e = sodyn::model::load_mjcf_str(&xml, "x.xml", Path::new("."), &Default::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("/dev/zero is not a regular file"), "{e}");
}

#[test]
fn state_reproducers_and_seeds() {
    replay("state", |b| {
        checks::state(b);
    });
    // The seeds are what they say: the valid ones evaluate (so the fuzzer starts from states
    // that reach every output of `eval`), `bad_*` and `not_json` fail.
    for f in files(&Path::new(ROOT).join("fuzz/corpus/state")) {
        let name = f.file_name().unwrap().to_string_lossy().to_string();
        let valid = !(name.starts_with("bad_") || name.starts_with("not_json"));
        assert_eq!(checks::state(&std::fs::read(&f).unwrap()), valid, "seed {name}");
    }
}

/// A chain of `n` `floating` joints (6 DoFs each): the shortest way for a URDF to ask for many
/// degrees of freedom (15 to 20 bytes per DoF).
fn floating_chain(n: usize) -> String {
    let mut s = String::from("<robot name=\"chain\"><link name=\"l0\"/>");
    for i in 1..=n {
        s += &format!(
            "<link name=\"l{i}\"/><joint name=\"j{i}\" type=\"floating\"><parent link=\"l{}\"/>\
             <child link=\"l{i}\"/></joint>",
            i - 1
        );
    }
    s + "</robot>"
}

/// Finding (review of the loader for the `urdf` target): nothing bounded the size of a model
/// that a URDF can ask for, and the model's DoF-ancestor lists and every workspace are
/// `O(nv²)`: a 2.2 MB chain of 20,000 `floating` joints (nv = 120,000) asked for about 58 GB
/// in the loader alone. The loader now stops at `MAX_URDF_DOFS` with an error naming the joint.
#[test]
fn urdf_dof_limit() {
    let fixed = UrdfOptions { floating_base: false, strict_inertia: false, mimic: false };
    let floating = UrdfOptions { floating_base: true, strict_inertia: false, mimic: false };
    let n_max = MAX_URDF_DOFS / 6;
    // At the limit: loads.
    let m = load_urdf_str(&floating_chain(n_max), "chain", &fixed).unwrap();
    assert_eq!(m.nv(), 6 * n_max);
    // One joint more, or the floating base's 6 on top: an error naming the joint.
    let e = load_urdf_str(&floating_chain(n_max + 1), "chain", &fixed).unwrap_err().to_string();
    let j = format!("joint \"j{}\"", n_max + 1);
    assert!(e.contains(&j) && e.contains("MAX_URDF_DOFS"), "{e}");
    if 6 * n_max + 6 > MAX_URDF_DOFS {
        let e = load_urdf_str(&floating_chain(n_max), "chain", &floating).unwrap_err().to_string();
        assert!(e.contains("MAX_URDF_DOFS") && e.contains("floating base"), "{e}");
    }
    // The large file is refused without building anything.
    let e = load_urdf_str(&floating_chain(20_000), "chain", &floating).unwrap_err().to_string();
    assert!(e.contains("MAX_URDF_DOFS"), "{e}");
    // The committed reproducer (171 floating joints, nv = 1026).
    let path = Path::new(ROOT).join("tests/data/fuzz/urdf/floating_chain_1026_dofs.urdf");
    let xml = std::fs::read_to_string(&path).unwrap();
    assert_eq!(checks::urdf(xml.as_bytes()), 0, "loads despite nv > MAX_URDF_DOFS");
}

/// Finding (review of the contact workspaces for the `state` target): nothing bounded the
/// number of contacts, and the contact workspaces hold several `(nv + 3 nc)²` matrices: a 63 KB
/// state file with 3,000 contacts on the quadruped took 7 GB and 19 s in `eval` before failing
/// (10,000 contacts, 210 KB, would ask for about 80 GB). `ContactData::new` now refuses more
/// than `MAX_CONTACTS` contacts with an error naming the limit.
#[test]
fn contact_count_limit() {
    use sodyn::algo::Contact;
    use sodyn::deriv::ContactData;
    use sodyn::deriv::contact::MAX_CONTACTS;
    let model = sodyn::model::builtin::quadruped();
    let feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
    let contacts = |n: usize| -> Vec<Contact> {
        (0..n)
            .map(|k| Contact::new(&model, feet[k % 4], nalgebra::Vector3::zeros()).unwrap())
            .collect()
    };
    assert!(ContactData::new(&model, &contacts(MAX_CONTACTS)).is_ok());
    for n in [MAX_CONTACTS + 1, 10_000] {
        let e = ContactData::new(&model, &contacts(n)).unwrap_err().to_string();
        assert!(e.contains("MAX_CONTACTS") && e.contains(&n.to_string()), "{e}");
    }
    // The committed reproducer (257 contacts) and a 10,000-contact state file: `eval` fails
    // without building the workspaces.
    let path = Path::new(ROOT).join("tests/data/fuzz/state/257_contacts.json");
    assert!(!checks::state(&std::fs::read(path).unwrap()));
    let list = vec!["{\"frame\": \"LF_FOOT\"}"; 10_000].join(", ");
    let text = format!("{{\"model\": \"quadruped\", \"contacts\": [{list}]}}");
    let t = std::time::Instant::now();
    assert!(!checks::state(text.as_bytes()));
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
}

/// Finding (review of the loader): `ModelBuilder::add_frame` checked for a duplicate name by a
/// linear scan, so loading a URDF was quadratic in its links (1.2 s for a 4.3 MB chain of
/// 40,000 `fixed` links, minutes for tens of megabytes). The check is now a hash-set lookup.
#[test]
fn urdf_many_fixed_links_load_in_linear_time() {
    let chain = |n: usize| {
        let mut s = String::from("<robot name=\"chain\"><link name=\"l0\"/>");
        for i in 1..=n {
            s += &format!(
                "<link name=\"l{i}\"/><joint name=\"j{i}\" type=\"fixed\"><parent link=\"l{}\"/>\
                 <child link=\"l{i}\"/></joint>",
                i - 1
            );
        }
        s + "</robot>"
    };
    let opts = UrdfOptions { floating_base: true, strict_inertia: false, mimic: false };
    let time = |n: usize| {
        let xml = chain(n);
        let t = std::time::Instant::now();
        let m = load_urdf_str(&xml, "chain", &opts).unwrap();
        assert_eq!(m.frames().len(), n + 2);
        t.elapsed().as_secs_f64()
    };
    // Twenty times the links: about twenty times the time (quadratic: four hundred). The best
    // of three runs each, and a wide margin against a loaded machine.
    let small = (0..3).map(|_| time(4_000)).fold(f64::INFINITY, f64::min);
    let large = (0..3).map(|_| time(80_000)).fold(f64::INFINITY, f64::min);
    eprintln!("4,000 links {small:.4} s, 80,000 links {large:.4} s");
    assert!(large < 120.0 * small.max(1e-3), "4,000 links {small:.4} s, 80,000 links {large:.4} s");
    // A duplicate link name is still reported.
    let dup = "<robot name=\"d\"><link name=\"a\"/><link name=\"b\"/><joint name=\"j\" \
               type=\"fixed\"><parent link=\"a\"/><child link=\"b\"/></joint><link name=\"b\"/></robot>";
    let e = load_urdf_str(dup, "dup", &opts).unwrap_err().to_string();
    assert!(e.contains("duplicate link name"), "{e}");
}
