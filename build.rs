//! Records the git commit the binary is built from, for the run report (`unknown` outside a
//! git checkout or without git).

fn main() {
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    let dirty = std::process::Command::new("git")
        .args(["status", "--porcelain", "--untracked-files=no"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .is_some_and(|o| !o.stdout.is_empty());
    println!("cargo:rustc-env=LUMEN_GIT_COMMIT={commit}{}", if dirty { "+changes" } else { "" });
    println!("cargo:rerun-if-changed=.git/HEAD");
    println!("cargo:rerun-if-changed=.git/index");
    // A commit moves the branch HEAD names, not HEAD itself; and an edit not yet staged leaves
    // the index alone but makes the build `+changes`. So the branch's ref, the packed refs and
    // what the binary is built from are watched too (only paths that exist: a missing one
    // would rerun this script on every build).
    let mut watched: Vec<String> = ["src", "data", "Cargo.toml", "Cargo.lock", ".git/packed-refs"]
        .iter()
        .map(|p| p.to_string())
        .collect();
    if let Some(branch) = std::fs::read_to_string(".git/HEAD")
        .ok()
        .and_then(|h| h.strip_prefix("ref: ").map(|r| r.trim().to_string()))
    {
        watched.push(format!(".git/{branch}"));
    }
    for p in watched.iter().filter(|p| std::path::Path::new(p).exists()) {
        println!("cargo:rerun-if-changed={p}");
    }
}
