//! The map of the crates in `docs/internals.md` ("The crates": the
//! dependency block and the table of jobs) names every crate of the
//! workspace, with its path, and no crate that is not one: a crate added
//! without its place on the map (or removed and left on it) fails here.

use std::collections::BTreeSet;

use hcc_system_tests::repo_root;

/// The workspace's crates: (package name, path), from the root `Cargo.toml`.
fn workspace_crates() -> Vec<(String, String)> {
    let root = repo_root();
    let read = |p: &std::path::Path| -> toml::Table {
        let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        text.parse()
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let ws = read(&root.join("Cargo.toml"));
    let members = ws["workspace"]["members"]
        .as_array()
        .expect("workspace.members");
    members
        .iter()
        .map(|m| {
            let path = m.as_str().expect("a member path").to_string();
            let manifest = read(&root.join(&path).join("Cargo.toml"));
            let name = manifest["package"]["name"].as_str().expect("package.name");
            (name.to_string(), path)
        })
        .collect()
}

/// The section "The crates" of `docs/internals.md`.
fn crate_map() -> String {
    let text = std::fs::read_to_string(repo_root().join("docs/internals.md")).unwrap();
    let start = text
        .find("## The crates")
        .expect("a section \"The crates\"");
    let rest = &text[start + 1..];
    let end = rest.find("\n## ").map_or(rest.len(), |e| e);
    rest[..end].to_string()
}

#[test]
fn the_crate_map_names_every_workspace_crate_and_only_those() {
    let crates = workspace_crates();
    let map = crate_map();
    assert!(crates.len() > 10, "{crates:?}");
    for (name, path) in &crates {
        assert!(
            map.lines().any(|l| {
                l.split_whitespace().next() == Some(name.as_str())
                    && l.split_whitespace().any(|w| w == path)
            }),
            "docs/internals.md: the dependency block lacks `{name}  {path}`"
        );
        assert!(
            map.contains(&format!("| `{name}` |")),
            "docs/internals.md: the table of jobs lacks `{name}`"
        );
    }
    let names: BTreeSet<&str> = crates.iter().map(|(n, _)| n.as_str()).collect();
    for row in map.lines().filter(|l| l.starts_with("| `")) {
        let name = row[3..].split('`').next().unwrap_or_default();
        assert!(
            names.contains(name),
            "docs/internals.md names `{name}`, which is not a crate of the workspace"
        );
    }
}
