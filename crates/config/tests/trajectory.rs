//! A level's `trajectory = "FILE.csv"` (docs/tracking.md): read relative to
//! the scenario, its first row the level's goal; a bad file is refused with
//! the scenario's field and line, the CSV file, its row and the reason.

use hcc_config::Scenario;
use std::path::{Path, PathBuf};

fn repo(p: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(p)
}

/// The figure-eight scenario in a directory of its own, its URDF by absolute
/// path, `edit` applied to its text, and `files` written beside it.
fn scenario_with(tag: &str, edit: &dyn Fn(String) -> String, files: &[(&str, &str)]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hcc-trajectory-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("paths")).unwrap();
    let urdf = repo("config/robots/panda/panda.urdf")
        .canonicalize()
        .unwrap();
    let text = std::fs::read_to_string(repo("config/panda-figure-eight.toml"))
        .unwrap()
        .replace(
            "urdf = \"robots/panda/panda.urdf\"",
            &format!("urdf = {:?}", urdf.to_string_lossy()),
        );
    for f in [
        "panda-figure-eight-tcp.csv",
        "panda-figure-eight-joint3.csv",
    ] {
        std::fs::copy(
            repo(&format!("config/paths/{f}")),
            dir.join("paths").join(f),
        )
        .unwrap();
    }
    for (name, body) in files {
        std::fs::write(dir.join(name), body).unwrap();
    }
    let path = dir.join("scenario.toml");
    std::fs::write(&path, edit(text)).unwrap();
    path
}

fn load_err(path: &Path) -> String {
    let e = Scenario::load(path).expect_err("refused").to_string();
    std::fs::remove_dir_all(path.parent().unwrap()).ok();
    e
}

#[test]
fn the_shipped_paths_load_and_their_first_rows_are_the_goals() {
    let s = Scenario::load(repo("config/panda-figure-eight.toml")).expect("loads");
    let paths = &s.tracking.paths;
    assert!(paths[0].is_some() && paths[1].is_none() && paths[2].is_some());
    assert_eq!(s.tracking.feed_forward, vec![true; 3]);
    let tcp = &paths[0].as_ref().unwrap().trajectory;
    assert_eq!((tcp.rows(), tcp.duration()), (1001, 10.0));
    let goal = s.spec.levels[0].goal.as_slice();
    assert!((goal[0] - 0.484046815).abs() < 1e-12 && goal[1] == 0.0);
    assert_eq!(s.spec.levels[2].goal.as_slice(), &[0.0]);
}

/// A case: its tag, the scenario's edit, the files beside it, what the
/// error names.
type Case<'a> = (
    &'a str,
    &'a dyn Fn(String) -> String,
    &'a [(&'a str, &'a str)],
    &'a [&'a str],
);

#[test]
fn a_bad_path_is_refused_with_the_field_the_file_its_row_and_the_reason() {
    let with_tcp = |csv: &'static str| {
        move |t: String| {
            t.replace(
                "trajectory = \"paths/panda-figure-eight-tcp.csv\"",
                &format!("trajectory = {csv:?}"),
            )
        }
    };
    let cases: [Case; 5] = [
        (
            "decreasing",
            &with_tcp("bad.csv"),
            &[(
                "bad.csv",
                "t,x,y,z\n0,0.48,0,0.41\n0.5,0.48,0,0.41\n0.4,0.48,0,0.41\n",
            )],
            &[
                "level[0].trajectory",
                "scenario.toml:24:",
                "bad.csv",
                "row 4",
                "does not increase",
            ],
        ),
        (
            "columns",
            &with_tcp("bad.csv"),
            &[("bad.csv", "t,x,y\n0,0.48,0\n")],
            &[
                "bad.csv",
                "row 1",
                "header has 3 columns, this level needs 4",
            ],
        ),
        (
            "nan",
            &with_tcp("bad.csv"),
            &[("bad.csv", "t,x,y,z\n0,0.48,0,0.41\n1,0.48,NaN,0.41\n")],
            &["bad.csv", "row 3", "not finite"],
        ),
        (
            "missing",
            &with_tcp("none.csv"),
            &[],
            &["none.csv", "cannot be read"],
        ),
        (
            "both",
            &|t: String| {
                t.replace(
                    "trajectory = \"paths/panda-figure-eight-tcp.csv\"",
                    "trajectory = \"paths/panda-figure-eight-tcp.csv\"\ngoal = [0.5, 0.0, 0.4]",
                )
            },
            &[],
            &["level[0].goal", "is given with a trajectory"],
        ),
    ];
    for (tag, edit, files, wants) in cases {
        let e = load_err(&scenario_with(tag, edit, files));
        println!("{tag}: {e}");
        for w in wants {
            assert!(e.contains(w), "{tag}: {e:?} lacks {w:?}");
        }
    }
}

#[test]
fn the_feed_forward_needs_the_extended_form() {
    let path = scenario_with(
        "form",
        &|t: String| t.replace("form = \"extended\"", "form = \"projector\""),
        &[],
    );
    let e = load_err(&path);
    assert!(
        e.contains("level[0].trajectory") && e.contains("extended"),
        "{e}"
    );
    // Without the feed-forward the goal is only pulled along: any form.
    let path = scenario_with(
        "form-pulled",
        &|t: String| {
            t.replace("form = \"extended\"", "form = \"projector\"")
                .replace(".csv\"", ".csv\"\nfeed_forward = false")
        },
        &[],
    );
    let s = Scenario::load(&path).expect("pulled along in the projector form");
    assert!(!s.tracking.feed_forward[0]);
    std::fs::remove_dir_all(path.parent().unwrap()).ok();
}

#[test]
fn the_scenario_document_carries_the_paths_and_rebuilds_them_without_the_files() {
    let s = Scenario::load(repo("config/panda-figure-eight.toml")).expect("loads");
    let mut doc = s.document("ns");
    assert_eq!(
        doc.paths.keys().collect::<Vec<_>>(),
        [
            "paths/panda-figure-eight-joint3.csv",
            "paths/panda-figure-eight-tcp.csv"
        ]
    );
    // As a tool on another machine: the scenario's directory does not exist.
    doc.path = "/nonexistent/panda-figure-eight.toml".into();
    let again = Scenario::from_document(&doc).expect("rebuilt from the texts");
    assert_eq!(again.tracking, s.tracking);
    // A JSON round trip keeps them; a document without them reads as none.
    let json = String::from_utf8(doc.to_json()).unwrap();
    let back = hcc_msgs::scenario::ScenarioDoc::from_json(json.as_bytes()).unwrap();
    assert_eq!(back.paths, doc.paths);
    let old = json.replacen("\"paths\":", "\"unused_paths\":", 1);
    let old = hcc_msgs::scenario::ScenarioDoc::from_json(old.as_bytes()).unwrap();
    assert!(old.paths.is_empty());
}
