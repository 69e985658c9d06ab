//! Citations stay true: every `docs/<page>.md#<anchor>` cited in the workspace's Rust sources and
//! Markdown files names a page of `docs/` and a heading of that page (its anchor as GitHub renders
//! it), and every relative link between the pages of `docs/` resolves the same way. The code
//! explains itself through these pages, so a renamed heading must not leave a citation behind.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The workspace root (this crate lives in `tests/`).
fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate is inside the workspace")
        .to_path_buf()
}

/// Every file under `dir` whose name ends with one of `extensions`, skipping build output and
/// hidden directories.
fn files(dir: &Path, extensions: &[&str], found: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .map(|entry| entry.expect("a directory entry").path())
        .collect();
    entries.sort();
    for path in entries {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if path.is_dir() {
            if name != "target" && !name.starts_with('.') {
                files(&path, extensions, found);
            }
        } else if extensions.iter().any(|ext| name.ends_with(ext)) {
            found.push(path);
        }
    }
}

/// A heading's anchor as GitHub renders it: the text without inline markup, lower case, every
/// character but letters, digits, `_`, `-` and spaces dropped, spaces turned into hyphens.
fn slug(heading: &str) -> String {
    let mut text = String::new();
    let mut rest = heading;
    // A link `[text](target)` renders as its text.
    while let Some(open) = rest.find('[') {
        let close = rest[open..].find("](").map(|i| open + i);
        let end = close.and_then(|c| rest[c..].find(')').map(|i| c + i));
        match (close, end) {
            (Some(close), Some(end)) => {
                text.push_str(&rest[..open]);
                text.push_str(&rest[open + 1..close]);
                rest = &rest[end + 1..];
            }
            _ => break,
        }
    }
    text.push_str(rest);
    text.trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a Markdown page: one per heading outside code blocks; a repeated heading gets
/// `-1`, `-2`, … as on GitHub.
fn anchors(markdown: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut in_code = false;
    for line in markdown.lines() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if in_code || hashes == 0 || hashes > 6 || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = slug(line[hashes..].trim().trim_end_matches('#'));
        let n = seen.entry(base.clone()).or_insert(0);
        found.insert(if *n == 0 { base } else { format!("{base}-{n}") });
        *n += 1;
    }
    found
}

/// The pages of `docs/` and their anchors.
fn pages(root: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut found = Vec::new();
    files(&root.join("docs"), &[".md"], &mut found);
    found
        .iter()
        .map(|path| {
            let name = path.file_name().expect("a file name").to_string_lossy();
            let text = fs::read_to_string(path).expect("a readable page");
            (name.into_owned(), anchors(&text))
        })
        .collect()
}

/// A page and optional anchor named by a citation.
#[derive(Debug, PartialEq, Eq)]
struct Citation {
    page: String,
    anchor: Option<String>,
}

fn is_name_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')
}

/// The `docs/<page>.md[#<anchor>]` citations in `text`.
fn citations(text: &str) -> Vec<Citation> {
    let mut found = Vec::new();
    for (start, _) in text.match_indices("docs/") {
        let rest = &text[start + "docs/".len()..];
        let name_len = rest.find(|c: char| !is_name_char(c)).unwrap_or(rest.len());
        // A sentence may end right after the page: `docs/case-format.md.`
        let page = rest[..name_len].trim_end_matches('.');
        if !page.ends_with(".md") || page.len() == ".md".len() {
            continue;
        }
        let after = &rest[page.len()..];
        let page = page.to_string();
        let anchor = after.strip_prefix('#').map(|a| {
            a.chars()
                .take_while(|&c| c.is_alphanumeric() || matches!(c, '_' | '-'))
                .collect::<String>()
        });
        found.push(Citation { page, anchor });
    }
    found
}

/// The relative links `](page.md#anchor)`, `](page.md)` and `](#anchor)` of a page of `docs/`.
fn relative_links(text: &str, this_page: &str) -> Vec<Citation> {
    let mut found = Vec::new();
    for (start, _) in text.match_indices("](") {
        let rest = &text[start + 2..];
        let Some(end) = rest.find(')') else { continue };
        let target = &rest[..end];
        if target.contains(':') || target.contains('/') || target.is_empty() {
            continue;
        }
        let (page, anchor) = match target.split_once('#') {
            Some((page, anchor)) => (page, Some(anchor.to_string())),
            None => (target, None),
        };
        let page = if page.is_empty() { this_page } else { page };
        if page.ends_with(".md") {
            found.push(Citation {
                page: page.to_string(),
                anchor,
            });
        }
    }
    found
}

/// What is wrong with `citation`, if anything.
fn problem(citation: &Citation, pages: &BTreeMap<String, BTreeSet<String>>) -> Option<String> {
    let Some(anchors) = pages.get(&citation.page) else {
        return Some(format!("docs/{} does not exist", citation.page));
    };
    match &citation.anchor {
        Some(anchor) if !anchors.contains(anchor) => Some(format!(
            "docs/{} has no heading with the anchor #{anchor}",
            citation.page
        )),
        _ => None,
    }
}

#[test]
fn headings_become_anchors_as_github_renders_them() {
    assert_eq!(slug("UWB estimator, 10.x"), "uwb-estimator-10x");
    assert_eq!(slug("A test, step by step"), "a-test-step-by-step");
    assert_eq!(slug("`/car/state`"), "carstate");
    assert_eq!(
        slug("What car-link does not speak"),
        "what-car-link-does-not-speak"
    );
    assert_eq!(slug("The [oracle](x.md) here"), "the-oracle-here");
    let page = "# Title\n\n## Part\n\n```\n## not a heading\n```\n\n### Part\n";
    let expected: BTreeSet<String> = ["title", "part", "part-1"].map(String::from).into();
    assert_eq!(anchors(page), expected);
}

#[test]
fn citations_are_found_with_their_anchors() {
    let text = "see `docs/firmware.md#fault-injection`, docs/*.md and docs/case-format.md.";
    assert_eq!(
        citations(text),
        vec![
            Citation {
                page: "firmware.md".into(),
                anchor: Some("fault-injection".into()),
            },
            Citation {
                page: "case-format.md".into(),
                anchor: None,
            },
        ]
    );
    let links = relative_links(
        "[a](method.md#the-oracle), [b](#here), [c](https://x.md)",
        "p.md",
    );
    assert_eq!(links.len(), 2);
    assert_eq!(links[1].page, "p.md");
}

#[test]
fn every_cited_docs_page_and_anchor_exists() {
    let root = workspace();
    let pages = pages(&root);
    assert!(
        pages.contains_key("firmware.md") && pages.contains_key("protocol.md"),
        "docs/ lacks the firmware and protocol pages: {:?}",
        pages.keys()
    );
    let mut sources = Vec::new();
    files(&root, &[".rs", ".md", ".toml"], &mut sources);
    let mut problems = Vec::new();
    let mut anchored = 0;
    for path in &sources {
        let text = fs::read_to_string(path).expect("a readable source file");
        let shown = path
            .strip_prefix(&root)
            .unwrap_or(path)
            .display()
            .to_string();
        let in_docs = path.parent() == Some(root.join("docs").as_path());
        let this_page = path.file_name().map(|n| n.to_string_lossy().into_owned());
        for (number, line) in text.lines().enumerate() {
            let mut found = citations(line);
            if in_docs && let Some(this_page) = &this_page {
                found.extend(relative_links(line, this_page));
            }
            for citation in found {
                anchored += usize::from(citation.anchor.is_some());
                if let Some(p) = problem(&citation, &pages) {
                    problems.push(format!("{shown}:{}: {p}", number + 1));
                }
            }
        }
    }
    assert!(
        anchored > 0,
        "no citation with an anchor found: is the scan broken?"
    );
    assert!(
        problems.is_empty(),
        "citations that do not resolve:\n{}",
        problems.join("\n")
    );
}

/// Our crates by the name code uses, with their directories.
const CRATES: [(&str, &str); 11] = [
    ("trajgen", "trajgen"),
    ("recovery", "recovery"),
    ("scenarios", "scenarios"),
    ("car_link", "car-link"),
    ("car_sim", "car-sim"),
    ("campaign", "campaign"),
    ("sitl", "sitl"),
    ("recording", "recording"),
    ("runner", "runner"),
    ("report", "report"),
    ("orchestrator", "orchestrator"),
];

/// Crates of others that ARCHITECTURE.md may name in a path.
const OTHERS: [&str; 3] = ["std", "rand_pcg", "tokio"];

/// The module file of `name` inside the module directory `dir` (`name.rs` or `name/mod.rs`).
fn module_file(dir: &Path, name: &str) -> Option<PathBuf> {
    [
        dir.join(format!("{name}.rs")),
        dir.join(name).join("mod.rs"),
    ]
    .into_iter()
    .find(|p| p.is_file())
}

/// Where the submodules of the module whose file is `file` live: beside a `lib.rs` or `mod.rs`,
/// in the directory named after any other module file.
fn submodule_dir(file: &Path) -> Option<PathBuf> {
    if file.ends_with("lib.rs") || file.ends_with("mod.rs") {
        file.parent().map(Path::to_path_buf)
    } else {
        file.parent()
            .zip(file.file_stem())
            .map(|(parent, stem)| parent.join(stem))
    }
}

/// The text of every Rust file of the module whose file is `file` (its directory included).
fn module_text(file: &Path) -> String {
    let mut text = fs::read_to_string(file).unwrap_or_default();
    if let Some(dir) = submodule_dir(file).filter(|d| d.is_dir()) {
        let mut found = Vec::new();
        files(&dir, &[".rs"], &mut found);
        for path in found {
            text.push_str(&fs::read_to_string(path).unwrap_or_default());
        }
    }
    text
}

/// Why the code path `path` (`crate::module::Item`, or `module::…` of one of our crates) does not
/// resolve in the workspace `root`, if it does not.
fn unresolved(root: &Path, path: &str) -> Option<String> {
    let segments: Vec<&str> = path.split("::").collect();
    let first = segments[0];
    let (mut file, rest) = if let Some((_, dir)) = CRATES.iter().find(|(name, _)| *name == first) {
        (root.join(dir).join("src").join("lib.rs"), &segments[1..])
    } else if OTHERS.contains(&first) {
        return None;
    } else {
        // A module of one of our crates, named without its crate.
        let found = CRATES
            .iter()
            .find_map(|(_, dir)| module_file(&root.join(dir).join("src"), first));
        match found {
            Some(file) => (file, &segments[1..]),
            None => return Some(format!("no crate or module `{first}`")),
        }
    };
    for (i, segment) in rest.iter().enumerate() {
        if let Some(next) = submodule_dir(&file).and_then(|d| module_file(&d, segment)) {
            file = next;
            continue;
        }
        // An item: it and what follows it are named in the module.
        let text = module_text(&file);
        return rest[i..]
            .iter()
            .find(|name| !text.contains(*name))
            .map(|name| format!("`{name}` is not in {}", file.display()));
    }
    None
}

/// ARCHITECTURE.md is the map of the code: every file or directory it names in backticks exists,
/// and every module path of ours it names (`campaign::seed`, `runner::reset`,
/// `car_link::firmware::steering`, an item in one) resolves to a module that holds it.
#[test]
fn the_architecture_names_only_what_exists() {
    let root = workspace();
    let text = fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut problems = Vec::new();
    let mut checked = (0, 0);
    for span in text.split('`').skip(1).step_by(2) {
        let plain = !span.contains([' ', '<', '>', '#', '*', '{', '|', '(']);
        if !plain {
            continue;
        }
        let is_path = span.contains('/')
            && !span.contains(':')
            && (span.ends_with('/') || span.rsplit('/').next().is_some_and(|f| f.contains('.')));
        if is_path {
            checked.0 += 1;
            if !root.join(span).exists() {
                problems.push(format!("{span}: no such file or directory"));
            }
            continue;
        }
        let starts_lower = span.chars().next().is_some_and(|c| c.is_ascii_lowercase());
        if span.contains("::") && starts_lower && !span.contains(['.', '/']) {
            checked.1 += 1;
            if let Some(problem) = unresolved(&root, span) {
                problems.push(format!("{span}: {problem}"));
            }
        }
    }
    assert!(
        checked.0 >= 20 && checked.1 >= 20,
        "too few names checked: {checked:?}"
    );
    assert!(
        problems.is_empty(),
        "ARCHITECTURE.md names what does not exist:\n{}",
        problems.join("\n")
    );
}

#[test]
fn a_misnamed_module_or_item_is_found() {
    let root = workspace();
    assert_eq!(unresolved(&root, "campaign::seed"), None);
    assert_eq!(unresolved(&root, "runner::reset"), None);
    assert_eq!(unresolved(&root, "car_link::firmware::steering"), None);
    assert_eq!(unresolved(&root, "campaign::drive::TestDrive"), None);
    assert!(unresolved(&root, "campaign::no_such_module").is_some());
    assert!(unresolved(&root, "runner::reset::NoSuchItem").is_some());
    assert!(unresolved(&root, "nosuchcrate::x").is_some());
}

/// The README's table of bundled scenarios is `scenario list`'s: every bundled scenario has a row
/// with its drivable area (to the square metre), its cutouts and its anchors, and no other row.
#[test]
fn the_readme_lists_the_bundled_scenarios_as_scenario_list_does() {
    let readme = fs::read_to_string(workspace().join("README.md")).expect("README.md");
    let table = readme
        .split("## Bundled scenarios")
        .nth(1)
        .and_then(|rest| rest.split("\n## ").next())
        .expect("a Bundled scenarios section");
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("| `")).collect();
    let names = scenarios::bundled::names();
    assert_eq!(
        rows.len(),
        names.len(),
        "one row per bundled scenario: {rows:#?}"
    );
    for name in names {
        let s = scenarios::bundled::load(name).expect("bundled").scenario;
        let anchors = match s.anchors.len() {
            0 => "none".to_owned(),
            _ => {
                let mut ids: Vec<u8> = s.anchors.iter().map(|a| a.id).collect();
                ids.sort_unstable();
                let ids: Vec<String> = ids.iter().map(ToString::to_string).collect();
                ids.join(" and ")
            }
        };
        let row = format!(
            "| `{name}` | {:.0} m² | {} | {anchors} |",
            s.area.drivable_area(),
            s.area.cutouts().len()
        );
        assert!(
            rows.iter().any(|r| r.starts_with(&row)),
            "README.md has no row starting {row}"
        );
    }
}
