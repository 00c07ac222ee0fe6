//! `docs/ARCHITECTURE.md`'s crate table against the workspace's manifests (`cargo metadata`): every library crate
//! has a row, each row's "uses" column is exactly the workspace crates its manifest depends on (normal
//! dependencies, optional ones included), and every such arrow points to a row above it, so the table is the
//! layering and cannot drift from it.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

use serde_json::Value;

use crate::common;

/// Crates that stand outside the table: the binary (it uses everything) and the test-data helper (a
/// dev-dependency, described below the table).
const OUTSIDE_THE_TABLE: [&str; 2] = ["dggt", "dggt-test-data"];

/// Each workspace crate's normal dependencies on other workspace crates, from `cargo metadata`.
fn manifest_arrows() -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .args(["metadata", "--format-version", "1", "--no-deps", "--offline"])
        .current_dir(common::repo())
        .output()
        .expect("cargo runs");
    assert!(output.status.success(), "cargo metadata failed: {}", String::from_utf8_lossy(&output.stderr));
    let metadata: Value = serde_json::from_slice(&output.stdout).unwrap();
    let packages = metadata["packages"].as_array().unwrap();
    let members: BTreeSet<String> = packages.iter().map(|p| p["name"].as_str().unwrap().to_owned()).collect();
    packages
        .iter()
        .map(|package| {
            let uses = package["dependencies"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|d| d["kind"].is_null())
                .map(|d| d["name"].as_str().unwrap().to_owned())
                .filter(|name| members.contains(name))
                .collect();
            (package["name"].as_str().unwrap().to_owned(), uses)
        })
        .collect()
}

/// The table's rows in order: each crate and the crates its "uses" column names.
fn documented_arrows() -> Vec<(String, BTreeSet<String>)> {
    let text = std::fs::read_to_string(common::repo().join("docs/ARCHITECTURE.md")).unwrap();
    text.lines()
        .filter(|line| line.starts_with("| `dggt-"))
        .map(|line| {
            let cells: Vec<&str> = line.trim_matches('|').split(" | ").map(str::trim).collect();
            let name = cells[0].trim_matches('`').to_owned();
            let uses = cells.last().unwrap();
            let uses = match *uses {
                "—" => BTreeSet::new(),
                list => list.split(", ").map(|short| format!("dggt-{short}")).collect(),
            };
            (name, uses)
        })
        .collect()
}

#[test]
fn the_architecture_table_is_the_manifests_layering() {
    let manifests = manifest_arrows();
    let documented = documented_arrows();
    let position: BTreeMap<&str, usize> =
        documented.iter().enumerate().map(|(i, (name, _))| (name.as_str(), i)).collect();
    let short =
        |set: &BTreeSet<String>| set.iter().map(|name| name.trim_start_matches("dggt-")).collect::<Vec<_>>().join(", ");
    let mut problems = Vec::new();
    for name in manifests.keys().filter(|name| !OUTSIDE_THE_TABLE.contains(&name.as_str())) {
        if !position.contains_key(name.as_str()) {
            problems.push(format!("{name} has no row"));
        }
    }
    for (row, (name, uses)) in documented.iter().enumerate() {
        let Some(actual) = manifests.get(name) else {
            problems.push(format!("{name} is in the table but not in the workspace"));
            continue;
        };
        if uses != actual {
            problems.push(format!("{name}: the table says `{}`, the manifest `{}`", short(uses), short(actual)));
        }
        for used in actual {
            if position.get(used.as_str()).is_some_and(|&at| at > row) {
                problems.push(format!("{name} uses {used}, which stands below it"));
            }
        }
    }
    assert!(problems.is_empty(), "docs/ARCHITECTURE.md's crate table:\n{}", problems.join("\n"));
}
