//! `lumen run` as a process, and reading its report: shared by the pipeline and shard tests.

use std::process::Command;

/// Runs `lumen run` on the pipeline text (written to DIR/p.toml) with `--out DIR/OUT` and the
/// extra arguments: the exit code, stderr and the report (Null when none was written).
pub fn run_with(
    pipeline: &str,
    dir: &std::path::Path,
    out: &str,
    args: &[&str],
) -> (i32, String, serde_json::Value) {
    let p = dir.join("p.toml");
    std::fs::write(&p, pipeline).unwrap();
    let out = dir.join(out);
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let report = std::fs::read_to_string(out.join("report.json"))
        .map(|t| serde_json::from_str(&t).unwrap())
        .unwrap_or(serde_json::Value::Null);
    (o.status.code().unwrap_or(-1), err, report)
}

/// Runs `lumen run` on the pipeline text (written beside OUT as p.toml) with `--out OUT` and
/// the render cache beside it: the exit code and stderr.
pub fn run(pipeline: &str, out: &std::path::Path) -> (i32, String) {
    let dir = out.parent().unwrap();
    let p = dir.join("p.toml");
    std::fs::write(&p, pipeline).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args([
            "run",
            p.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--cache",
            dir.join("cache").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// The JSON file at PATH (a report, a shard's fragment, a summary), parsed.
pub fn read_json(path: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every case's metrics that do not depend on the machine's speed, by case and name.
pub fn numbers(report: &serde_json::Value) -> Vec<(String, String, serde_json::Value)> {
    let mut v = Vec::new();
    for st in report["stages"].as_array().unwrap() {
        for m in st["metrics"].as_array().unwrap() {
            if !["s", "1/s", "M/s"].contains(&m["unit"].as_str().unwrap()) {
                v.push((st["case"].to_string(), m["name"].to_string(), m["value"].clone()));
            }
        }
    }
    v
}

pub fn case<'a>(report: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    report["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["case"] == name)
        .unwrap_or_else(|| panic!("no case {name}"))
}

/// A small pipeline of every kind of case: two sweeps (the second sharing renders) and one
/// case alone.
pub fn small_pipeline() -> String {
    let root = super::root().join("pipelines/scenes");
    format!(
        "name = \"small\"\nseed = 5\n\
         [[stages]]\nstage = \"render\"\ncase = \"furnace\"\nscene = \"{0}/furnace.toml\"\nexpect_uniform = [1.0, 1.0, 1.0]\nsweep = {{ spp = [4, 16] }}\n\
         [[stages]]\nstage = \"calibrate\"\ncase = \"board\"\nscene = \"{0}/calib-board.toml\"\nspp = 4\nsweep = {{ views = [4, 5] }}\nbounds = {{ views_missed = 0 }}\n\
         [[stages]]\nstage = \"photometric\"\ncase = \"sphere\"\nscene = \"{0}/ps-sphere.toml\"\nspp = 4\nlights = 8\nbounds = {{ masked_pixels = 0 }}\n",
        root.display()
    )
}
