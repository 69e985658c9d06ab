//! A variant of a firmware tree: a copy of the files a build reads, with one named numeric
//! constant changed — the kind of small change a firmware team commits, made on purpose to check
//! that a regression gate catches it (`docs/sitl.md#a-firmware-regression-gate`).
//!
//! The change is named, never written as firmware code: a file of the tree, a name, and the new
//! number. The name is either a macro (`#define NAME 0.2` at the start of a line) or a field
//! given a number in an assignment (`x->NAME = 0.1;` or `x.NAME = 0.1;`, as a configuration's
//! defaults are written). It must occur exactly once, so a change never lands in a place it was
//! not meant for. The tree itself is only read.
//!
//! ```no_run
//! # fn run() -> Result<(), sitl::variant::VariantError> {
//! use std::path::Path;
//! let copy = Path::new("/tmp/candidate");
//! sitl::variant::copy_tree(Path::new("/src/rise_sdvp/Embedded/RC_Controller"), copy)?;
//! let old = sitl::variant::set_constant(copy, "conf_general.c", "uwb_max_corr", "1.0")?;
//! println!("uwb_max_corr: {old} -> 1.0");
//! # Ok(()) }
//! ```

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::builder::TREE_INCLUDE_DIRS;

/// Why a variant could not be made.
#[derive(Debug, Error)]
pub enum VariantError {
    /// A file or folder could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The name is not given a number in the file.
    #[error("{}: no `#define {name} NUMBER` and no assignment `{name} = NUMBER;`", file.display())]
    NotFound {
        /// The file.
        file: PathBuf,
        /// The name.
        name: String,
    },
    /// The name is given a number more than once in the file.
    #[error("{}: `{name}` is given a number {count} times (it must be once)", file.display())]
    Ambiguous {
        /// The file.
        file: PathBuf,
        /// The name.
        name: String,
        /// How many times.
        count: usize,
    },
    /// The new value is not a number.
    #[error("`{value}` is not a number (for `{name}`)")]
    NotANumber {
        /// The name.
        name: String,
        /// The value given.
        value: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> VariantError + '_ {
    move |source| VariantError::Io {
        path: path.to_owned(),
        source,
    }
}

/// Copies the files of `tree` that a build reads (the top folder and the folders of the include
/// path, not the tree's ChibiOS) into `dest`, which is created.
pub fn copy_tree(tree: &Path, dest: &Path) -> Result<(), VariantError> {
    for sub in TREE_INCLUDE_DIRS {
        let (from, to) = (tree.join(sub), dest.join(sub));
        let entries = match std::fs::read_dir(&from) {
            Ok(entries) => entries,
            Err(_) if !sub.is_empty() => continue,
            Err(e) => return Err(io(&from)(e)),
        };
        std::fs::create_dir_all(&to).map_err(io(&to))?;
        for entry in entries {
            let entry = entry.map_err(io(&from))?;
            let path = entry.path();
            if path.is_file() {
                let target = to.join(entry.file_name());
                std::fs::copy(&path, &target).map_err(io(&target))?;
            }
        }
    }
    Ok(())
}

/// Gives `name` the number `value` in `file` (relative to `tree`), where it was given one
/// exactly once; returns the old number, as written.
pub fn set_constant(
    tree: &Path,
    file: &str,
    name: &str,
    value: &str,
) -> Result<String, VariantError> {
    if value.parse::<f64>().is_err() {
        return Err(VariantError::NotANumber {
            name: name.to_owned(),
            value: value.to_owned(),
        });
    }
    let path = tree.join(file);
    let text = std::fs::read_to_string(&path).map_err(io(&path))?;
    let found = find(&text, name);
    match found.as_slice() {
        [] => Err(VariantError::NotFound {
            file: path,
            name: name.to_owned(),
        }),
        [(start, end)] => {
            let old = text[*start..*end].to_owned();
            let changed = format!("{}{value}{}", &text[..*start], &text[*end..]);
            std::fs::write(&path, changed).map_err(io(&path))?;
            Ok(old)
        }
        more => Err(VariantError::Ambiguous {
            file: path,
            name: name.to_owned(),
            count: more.len(),
        }),
    }
}

/// The byte ranges of the numbers `name` is given in `text`.
fn find(text: &str, name: &str) -> Vec<(usize, usize)> {
    let mut found = Vec::new();
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        if let Some(at) = number_of(line, name) {
            found.push((offset + at.0, offset + at.1));
        }
        offset += line.len();
    }
    found
}

/// Where in `line` the number given to `name` is: `#define NAME NUMBER` or `… NAME = NUMBER;`.
fn number_of(line: &str, name: &str) -> Option<(usize, usize)> {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let trimmed = line.trim_start();
    let indent = line.len() - trimmed.len();
    if let Some(rest) = trimmed.strip_prefix('#') {
        let after_hash = rest.trim_start();
        let rest = after_hash.strip_prefix("define")?;
        let after_define = rest.trim_start();
        if after_define.len() == rest.len() {
            return None; // `#defineX`
        }
        let rest = after_define.strip_prefix(name)?;
        if rest.starts_with(ident) || rest.starts_with('(') {
            return None; // another name, or a function-like macro
        }
        let value = rest.trim_start();
        let start = line.len() - value.len();
        let len = number_len(value)?;
        let tail = value[len..].trim();
        (tail.is_empty() || tail.starts_with("//") || tail.starts_with("/*"))
            .then_some((start, start + len))
    } else {
        // an assignment: the name after `->`, `.` or the line's start, then `=` and a number and `;`
        let mut search = indent;
        while let Some(i) = line[search..].find(name) {
            let at = search + i;
            search = at + name.len();
            let before = &line[..at];
            let after = &line[at + name.len()..];
            let preceded =
                before.ends_with("->") || before.ends_with('.') || before.trim().is_empty();
            if !preceded || after.starts_with(ident) {
                continue;
            }
            let Some(rest) = after.trim_start().strip_prefix('=') else {
                continue;
            };
            if rest.starts_with('=') {
                continue; // `==`
            }
            let value = rest.trim_start();
            let start = line.len() - value.len();
            let Some(len) = number_len(value) else {
                continue;
            };
            if value[len..].trim_start().starts_with(';') {
                return Some((start, start + len));
            }
        }
        None
    }
}

/// The length of the C number literal (with an optional sign and `f`/`F` suffix) at the start of
/// `s`.
fn number_len(s: &str) -> Option<usize> {
    let bytes = s.as_bytes();
    let mut i = usize::from(bytes.first().is_some_and(|&b| b == b'-' || b == b'+'));
    let digits_from = i;
    while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
        i += 1;
    }
    if i == digits_from || !s[digits_from..i].bytes().any(|b| b.is_ascii_digit()) {
        return None;
    }
    if i < bytes.len() && (bytes[i] == b'e' || bytes[i] == b'E') {
        let mut j = i + 1;
        if j < bytes.len() && (bytes[j] == b'-' || bytes[j] == b'+') {
            j += 1;
        }
        let exp_from = j;
        while j < bytes.len() && bytes[j].is_ascii_digit() {
            j += 1;
        }
        if j > exp_from {
            i = j;
        }
    }
    if i < bytes.len() && (bytes[i] == b'f' || bytes[i] == b'F') {
        i += 1;
    }
    if i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
        return None;
    }
    Some(i)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn changed(text: &str, name: &str, value: &str) -> Result<(String, String), VariantError> {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(t.path().join("f.c"), text).unwrap();
        let old = set_constant(t.path(), "f.c", name, value)?;
        Ok((old, std::fs::read_to_string(t.path().join("f.c")).unwrap()))
    }

    #[test]
    fn a_macro_gets_the_new_number() {
        let (old, text) = changed(
            "#define GAIN_X\t\t0.5\n#define GAIN\t\t\t0.2 // m\nint x;\n",
            "GAIN",
            "0.5",
        )
        .unwrap();
        assert_eq!(old, "0.2");
        assert_eq!(
            text,
            "#define GAIN_X\t\t0.5\n#define GAIN\t\t\t0.5 // m\nint x;\n"
        );
    }

    #[test]
    fn an_assignment_gets_the_new_number() {
        let text = "void f(c *conf) {\n\tconf->limit = 0.1;\n\tconf->limit_x = 3;\n\tif (a.limit == 2) {}\n}\n";
        let (old, new) = changed(text, "limit", "1.0").unwrap();
        assert_eq!(old, "0.1");
        assert_eq!(new, text.replacen("= 0.1;", "= 1.0;", 1));
        let (old, _) = changed("\ts.gain = -2.5e-1f;\n", "gain", "4").unwrap();
        assert_eq!(old, "-2.5e-1f");
    }

    #[test]
    fn a_name_not_given_a_number_once_is_refused_naming_the_file() {
        let e = changed("#define GAIN foo(2)\nx = GAIN;\n", "GAIN", "1").unwrap_err();
        assert!(matches!(e, VariantError::NotFound { .. }), "{e}");
        assert!(e.to_string().contains("f.c"), "{e}");
        let e = changed("a.g = 1;\nb.g = 2;\n", "g", "1").unwrap_err();
        assert!(matches!(e, VariantError::Ambiguous { count: 2, .. }), "{e}");
        let e = changed("#define G(x) 2\n", "G", "1").unwrap_err();
        assert!(matches!(e, VariantError::NotFound { .. }), "{e}");
        let e = changed("#define G 2\n", "G", "two").unwrap_err();
        assert!(matches!(e, VariantError::NotANumber { .. }), "{e}");
    }

    #[test]
    fn the_copy_leaves_the_tree_as_it_was() {
        let t = tempfile::tempdir().unwrap();
        let tree = t.path().join("tree");
        std::fs::create_dir_all(tree.join("imu")).unwrap();
        std::fs::create_dir_all(tree.join("ChibiOS")).unwrap();
        std::fs::write(tree.join("a.c"), "#define K 1\n").unwrap();
        std::fs::write(tree.join("imu/b.h"), "int b;\n").unwrap();
        std::fs::write(tree.join("ChibiOS/c.h"), "int c;\n").unwrap();
        let copy = t.path().join("copy");
        copy_tree(&tree, &copy).unwrap();
        assert_eq!(set_constant(&copy, "a.c", "K", "2").unwrap(), "1");
        assert_eq!(
            std::fs::read_to_string(tree.join("a.c")).unwrap(),
            "#define K 1\n"
        );
        assert_eq!(
            std::fs::read_to_string(copy.join("a.c")).unwrap(),
            "#define K 2\n"
        );
        assert!(copy.join("imu/b.h").is_file());
        assert!(!copy.join("ChibiOS").exists());
        let e = copy_tree(&t.path().join("nope"), &t.path().join("c2")).unwrap_err();
        assert!(e.to_string().contains("nope"), "{e}");
    }
}
