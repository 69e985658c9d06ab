//! Snapshots (`insta`) of what a user reads: the final table of a campaign, its JUnit XML, the
//! error messages of bad scenario files, the canonical scenario TOML and the report page's
//! skeleton. What varies between runs and machines (the run directory's path, wall times,
//! timestamps, the tool's version) is redacted; everything else, in virtual time on the embedded
//! simulated car, is the same on every machine.
//!
//! A snapshot that differs fails the test. When the change is meant, accept the new output with
//! `INSTA_UPDATE=always cargo test -p drivecheck --test drivecheck user_output` (or `cargo insta review`)
//! and commit the changed `snapshots/*.snap` files with it.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{path, text};

/// The workspace's root: the commands run there and name fixtures relative to it, so the paths in
/// their messages are the same on every machine.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the orchestrator crate is in the workspace")
        .to_owned()
}

/// Runs `drivecheck args` in the workspace's root.
fn drivecheck_in_root(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the drivecheck binary runs")
}

/// Settings that redact wall times and timestamps.
fn redacting() -> insta::Settings {
    let mut settings = insta::Settings::clone_current();
    settings.set_prepend_module_to_snapshot(false);
    settings.add_filter(r"\d+(\.\d+)? s wall time", "[WALL] s wall time");
    // JUnit: a suite's time is the wall clock's.
    settings.add_filter(
        r#"(<testsuites? [^>]*)time="[0-9.]+""#,
        r#"${1}time="[WALL]""#,
    );
    settings.add_filter(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?Z", "[TIMESTAMP]");
    settings.add_filter(r#"(name="tool_version" value=")[^"]*""#, r#"$1[VERSION]""#);
    settings
}

/// `text` with the temporary directory `dir` named `[DIR]`.
fn without(text: &str, dir: &Path) -> String {
    text.replace(path(dir), "[DIR]")
}

/// `drivecheck run --tests 3 --seed 1` on the embedded simulated car in virtual time: the final
/// table on standard output, the JUnit XML, and the skeleton of `drivecheck report` of its run
/// directory.
#[test]
fn a_campaigns_table_junit_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let junit = dir.path().join("junit.xml");
    let out = drivecheck_in_root(&[
        "run",
        "--tests",
        "3",
        "--seed",
        "1",
        "--out",
        path(&run),
        "--junit",
        path(&junit),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let settings = redacting();
    settings.bind(|| {
        insta::assert_snapshot!(
            "run_table",
            without(&String::from_utf8_lossy(&out.stdout), dir.path())
        );
        insta::assert_snapshot!(
            "run_junit",
            without(&std::fs::read_to_string(&junit).unwrap(), dir.path())
        );
    });

    let out = drivecheck_in_root(&["report", path(&run)]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let page = std::fs::read_to_string(run.join("report.html")).unwrap();
    settings.bind(|| insta::assert_snapshot!("report_skeleton", skeleton(&page)));
}

/// `drivecheck scenario check` of every malformed fixture (and of the one with warnings): the
/// message names the file, line, column and field.
#[test]
fn the_errors_of_bad_scenario_files() {
    let mut report = String::new();
    for folder in ["tests/fixtures/malformed", "tests/fixtures/warnings"] {
        let mut files: Vec<String> = std::fs::read_dir(root().join(folder))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        for file in files {
            let file = format!("{folder}/{file}");
            let out = drivecheck_in_root(&["scenario", "check", &file]);
            report.push_str(&format!(
                "$ drivecheck scenario check {file}\nstatus {}\n{}\n",
                out.status
                    .code()
                    .map_or("none".to_owned(), |c| c.to_string()),
                String::from_utf8_lossy(&out.stderr).trim_end()
            ));
        }
    }
    insta::with_settings!({prepend_module_to_snapshot => false}, {
        insta::assert_snapshot!("scenario_errors", report);
    });
}

/// `drivecheck scenario import` of reference XML fixtures: the canonical scenario TOML.
#[test]
fn the_canonical_toml_of_imported_reference_xml() {
    for name in ["parking-lot-2anchors", "courtyard"] {
        let out = drivecheck_in_root(&[
            "scenario",
            "import",
            &format!("tests/fixtures/xml/{name}.xml"),
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        insta::with_settings!({prepend_module_to_snapshot => false}, {
            insta::assert_snapshot!(
                format!("import_{name}"),
                String::from_utf8_lossy(&out.stdout)
            );
        });
    }
}

/// The page reduced to its structure: one line per element (its name, `#id` and `.class`es),
/// indented by depth, with the text of the title, the headings and the table headers only;
/// what is inside `<svg>`, `<style>` and `<pre>` (the pictures' numbers, the stylesheet, the
/// coverage text) is left out. Identical neighbouring elements are one line with `×N`.
fn skeleton(html: &str) -> String {
    let root = parse(html);
    let mut out = String::new();
    for child in collapse(&root.children) {
        write_node(&mut out, &child.0, child.1, 0);
    }
    out
}

/// An element of the page.
#[derive(Debug, Clone, PartialEq)]
struct Node {
    /// `name#id.class.class`.
    label: String,
    /// Its text, for the elements whose text is kept.
    text: String,
    children: Vec<Node>,
}

const VOID: [&str; 6] = ["meta", "br", "hr", "img", "input", "link"];
const OPAQUE: [&str; 3] = ["svg", "style", "pre"];
const WITH_TEXT: [&str; 8] = ["title", "h1", "h2", "h3", "h4", "h5", "h6", "th"];

fn parse(html: &str) -> Node {
    let mut stack = vec![Node {
        label: String::new(),
        text: String::new(),
        children: Vec::new(),
    }];
    let mut names = vec![String::new()];
    let mut rest = html;
    while let Some(open) = rest.find('<') {
        let text = &rest[..open];
        if names.iter().any(|n| WITH_TEXT.contains(&n.as_str())) {
            let top = stack.last_mut().unwrap();
            top.text.push_str(text);
        }
        rest = &rest[open..];
        if let Some(comment) = rest.strip_prefix("<!--") {
            rest = comment.split_once("-->").map_or("", |(_, r)| r);
            continue;
        }
        let close = rest.find('>').expect("every tag is closed");
        let tag = &rest[1..close];
        rest = &rest[close + 1..];
        if tag.starts_with('!') {
            continue;
        }
        if let Some(name) = tag.strip_prefix('/') {
            let name = name.trim();
            let at = names
                .iter()
                .rposition(|n| n == name)
                .unwrap_or_else(|| panic!("</{name}> closes no open element"));
            while names.len() > at {
                names.pop();
                let node = stack.pop().unwrap();
                stack.last_mut().unwrap().children.push(node);
            }
            continue;
        }
        let name: String = tag
            .chars()
            .take_while(|c| !c.is_whitespace() && *c != '/')
            .collect();
        let mut label = name.clone();
        if let Some(id) = attribute(tag, "id") {
            label.push('#');
            label.push_str(&id);
        }
        if let Some(class) = attribute(tag, "class") {
            for c in class.split_whitespace() {
                label.push('.');
                label.push_str(c);
            }
        }
        let node = Node {
            label,
            text: String::new(),
            children: Vec::new(),
        };
        if tag.ends_with('/') || VOID.contains(&name.as_str()) {
            stack.last_mut().unwrap().children.push(node);
        } else if OPAQUE.contains(&name.as_str()) {
            let end = format!("</{name}>");
            let at = rest.find(&end).expect("an opaque element is closed");
            rest = &rest[at + end.len()..];
            stack.last_mut().unwrap().children.push(node);
        } else {
            stack.push(node);
            names.push(name);
        }
    }
    assert_eq!(names.len(), 1, "unclosed elements: {names:?}");
    stack.pop().unwrap()
}

/// The value of attribute `name` in a tag's text.
fn attribute(tag: &str, name: &str) -> Option<String> {
    let key = format!(" {name}=\"");
    let from = tag.find(&key)? + key.len();
    let len = tag[from..].find('"')?;
    Some(tag[from..from + len].to_owned())
}

/// Neighbouring identical nodes as one, with their count.
fn collapse(nodes: &[Node]) -> Vec<(Node, usize)> {
    let mut out: Vec<(Node, usize)> = Vec::new();
    for node in nodes {
        match out.last_mut() {
            Some((last, n)) if last == node => *n += 1,
            _ => out.push((node.clone(), 1)),
        }
    }
    out
}

fn write_node(out: &mut String, node: &Node, count: usize, depth: usize) {
    out.push_str(&"  ".repeat(depth));
    out.push_str(&node.label);
    let text = node.text.split_whitespace().collect::<Vec<_>>().join(" ");
    if !text.is_empty() {
        out.push_str(&format!(" {text:?}"));
    }
    if count > 1 {
        out.push_str(&format!(" ×{count}"));
    }
    out.push('\n');
    for (child, n) in collapse(&node.children) {
        write_node(out, &child, n, depth + 1);
    }
}
