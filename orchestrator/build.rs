//! Records the git revision the binary is built from, for `drivecheck --version` (a bug report
//! names the commit): `DRIVECHECK_REVISION`, the short hash, or `unknown revision` outside a git
//! checkout (a source tarball, a vendored copy).

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let output = Command::new("git").args(args).output().ok()?;
    output
        .status
        .success()
        .then(|| String::from_utf8(output.stdout).ok())
        .flatten()
        .map(|s| s.trim().to_owned())
        .filter(|s| !s.is_empty())
}

fn main() {
    let revision = git(&["rev-parse", "--short=12", "HEAD"]).map_or_else(
        || "unknown revision".to_owned(),
        |r| format!("revision {r}"),
    );
    println!("cargo:rustc-env=DRIVECHECK_REVISION={revision}");
    // Built again when HEAD moves (a commit, a checkout), not on every build. HEAD is the work
    // tree's own (`git worktree` gives each one), the branches are shared; a path that does not
    // exist would make cargo run this script on every build, so only those that do are named.
    let own = git(&["rev-parse", "--absolute-git-dir"]);
    let common = git(&["rev-parse", "--path-format=absolute", "--git-common-dir"]);
    let paths = [
        (&own, "HEAD"),
        (&common, "refs/heads"),
        (&common, "packed-refs"),
    ];
    for (dir, path) in paths {
        if let Some(dir) = dir {
            let path = std::path::Path::new(dir).join(path);
            if path.exists() {
                println!("cargo:rerun-if-changed={}", path.display());
            }
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
