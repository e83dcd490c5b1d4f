//! `lumen run --shard`, `lumen merge` and `lumen slurm`: a pipeline split into shards, render
//! shares and match shares gives the numbers of the one-process run.

mod common;

use common::run::{case, numbers, read_json, run_with, small_pipeline};
use std::process::Command;

/// The small pipeline run as one process, and as 3 shards (each writing its fragment) joined by
/// `lumen merge`, gives the same numbers; a missing fragment, or one from another pipeline file,
/// is an error naming it; a shard run again replaces its fragment.
#[test]
fn shards_merge_into_the_one_process_report() {
    let dir = tempfile::tempdir().unwrap();
    let text = small_pipeline();
    let (code, err, one) = run_with(&text, dir.path(), "one", &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let out = dir.path().join("sharded");
    let cache = dir.path().join("cache");
    let shard = |k: usize, text: &str| {
        let (code, err, _) = run_with(
            text,
            dir.path(),
            "sharded",
            &["--shard", &format!("{k}/3"), "--cache", cache.to_str().unwrap()],
        );
        assert_eq!(code, 0, "{err}");
        serde_json::from_str::<serde_json::Value>(
            &std::fs::read_to_string(out.join(format!("shards/{k}-of-3/report.json"))).unwrap(),
        )
        .unwrap()
    };
    let merge = || {
        let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
            .args(["merge", out.to_str().unwrap()])
            .output()
            .unwrap();
        (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // Cases 0 and 3 (furnace[spp=4], board[views=5]) are shard 1's.
    let first = shard(1, &text);
    let cases: Vec<&str> =
        first["stages"].as_array().unwrap().iter().map(|s| s["case"].as_str().unwrap()).collect();
    assert_eq!(cases, ["furnace[spp=4]", "board[views=5]"]);
    assert!(!out.join("report.json").exists(), "a shard writes only its fragment");
    assert_eq!(first["fragment"]["indices"], serde_json::json!([0, 3]));
    shard(2, &text);
    let (code, err) = merge();
    assert_eq!(code, 1);
    assert!(err.contains("missing fragment(s) 3-of-3"), "{err}");
    shard(3, &text);
    let (code, err) = merge();
    assert_eq!(code, 0, "{err}");
    let merged: serde_json::Value = read_json(&out.join("report.json"));
    assert_eq!(numbers(&one), numbers(&merged));
    let order = |r: &serde_json::Value| -> Vec<serde_json::Value> {
        r["stages"].as_array().unwrap().iter().map(|s| s["case"].clone()).collect()
    };
    assert_eq!(order(&one), order(&merged));
    assert_eq!(merged["passed"], true);
    assert!(merged.get("fragment").is_none());
    assert!(out.join("plots/board.svg").exists() && out.join("report.md").exists());
    // Shard 2 run from another pipeline file replaces its fragment, and the merge refuses it.
    shard(2, &text.replace("lights = 8", "lights = 9"));
    let (code, err) = merge();
    assert_eq!(code, 1);
    assert!(err.contains("2-of-3") && err.contains("pipeline file"), "{err}");
    // Run again from the right file, it replaces that fragment and the merge holds again.
    shard(2, &text);
    let (code, err) = merge();
    assert_eq!(code, 0, "{err}");
    // A fragment edited by hand: a case count beyond what the fragments hold is refused
    // before anything is allocated for it; a kept file outside the fragment's folder is refused
    // before anything is read or written.
    let fragment = out.join("shards/1-of-3/report.json");
    let good = std::fs::read_to_string(&fragment).unwrap();
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut j: serde_json::Value = serde_json::from_str(&good).unwrap();
        f(&mut j);
        std::fs::write(&fragment, j.to_string()).unwrap();
    };
    let paths: Vec<_> = (1..=3).map(|k| out.join(format!("shards/{k}-of-3/report.json"))).collect();
    let texts: Vec<String> = paths.iter().map(|p| std::fs::read_to_string(p).unwrap()).collect();
    for (p, t) in paths.iter().zip(&texts) {
        let mut j: serde_json::Value = serde_json::from_str(t).unwrap();
        j["fragment"]["cases"] = serde_json::json!(1_000_000_000_000u64);
        std::fs::write(p, j.to_string()).unwrap();
    }
    let (code, err) = merge();
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("claims 1000000000000 cases in the pipeline, but the 3 fragments hold 5"), "{err}");
    for (p, t) in paths.iter().zip(&texts) {
        std::fs::write(p, t).unwrap();
    }
    edit(&|j| j["fragment"]["kept"] = serde_json::json!(["../../x.txt"]));
    std::fs::write(dir.path().join("x.txt"), "outside").unwrap();
    let (code, err) = merge();
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("kept file `../../x.txt` is not a relative path inside the fragment's folder"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(dir.path().join("x.txt")).unwrap(), "outside");
}

/// `lumen slurm` writes a job array's script and a merge script; run as Slurm would run them
/// (one task per SLURM_ARRAY_TASK_ID, then the merge), they give the one-process numbers.
#[test]
fn slurm_scripts_run_the_shards_and_the_merge() {
    let dir = tempfile::tempdir().unwrap();
    let text = small_pipeline();
    let (code, err, one) = run_with(&text, dir.path(), "one", &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let p = dir.path().join("p.toml");
    let out = dir.path().join("cluster");
    let slurm = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_lumen"))
            .args(["slurm", p.to_str().unwrap(), "--shards", "3", "--out", out.to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap()
    };
    let o = slurm(&["--time", "0:10:00 --mem=1T"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--time"), "{o:?}");
    let o = slurm(&["--time", "0:10:00", "--cpus-per-task", "1"]);
    assert!(o.status.success(), "{o:?}");
    let script = std::fs::read_to_string(out.join("slurm/run.sbatch")).unwrap();
    assert!(script.contains("#SBATCH --array=0-2") && script.contains("#SBATCH --time=0:10:00"), "{script}");
    // The render array, the matches array, then the run array (which then finds every render
    // in the cache).
    for array in ["render", "match", "run"] {
        for task in 0..3 {
            let o = Command::new("bash")
                .arg(out.join(format!("slurm/{array}.sbatch")))
                .env("SLURM_ARRAY_TASK_ID", task.to_string())
                .env("SLURM_CPUS_PER_TASK", "1")
                .output()
                .unwrap();
            assert!(o.status.success(), "{array} task {task}: {}", String::from_utf8_lossy(&o.stderr));
        }
    }
    let o = Command::new("bash").arg(out.join("slurm/merge.sbatch")).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let merged: serde_json::Value = read_json(&out.join("report.json"));
    assert_eq!(numbers(&one), numbers(&merged));
    assert_eq!(merged["threads"], 1);
    assert_eq!(rendered(&merged), 0, "the render array made every render");
}

/// Renders the cases of a report made, summed.
fn rendered(report: &serde_json::Value) -> u64 {
    report["stages"].as_array().unwrap().iter().map(|s| s["renders"]["rendered"].as_u64().unwrap()).sum()
}

/// Render shares split the renders, not the cases: 3 shares each make a disjoint part of the
/// small pipeline's renders (entries two cases share made once, the 8 lights of the one
/// photometric case spread), together every render the one-process run makes, after which
/// the shards run every case from the cache; a share run again makes nothing.
#[test]
fn render_shares_split_the_renders_inside_cases() {
    let dir = tempfile::tempdir().unwrap();
    let text = small_pipeline();
    let (code, err, one) =
        run_with(&text, dir.path(), "one", &["--cache", dir.path().join("c1").to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let cache = dir.path().join("c3");
    let p = dir.path().join("p.toml");
    let share = |k: usize| {
        let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
            .args(["run", p.to_str().unwrap(), "--shard", &format!("{k}/3"), "--renders-only"])
            .args(["--cache", cache.to_str().unwrap(), "--threads", "1"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        // "... requests are this share's, R made in ..."
        let made = err.split(" made in").next().and_then(|s| s.rsplit(' ').next()).unwrap();
        (made.parse::<u64>().unwrap(), err)
    };
    let (made, lights): (Vec<u64>, Vec<usize>) = (1..=3)
        .map(|k| {
            let (m, err) = share(k);
            let line = err.lines().find(|l| l.contains("photometric sphere")).unwrap().to_string();
            let own = line.split(": ").nth(1).and_then(|s| s.split(' ').next()).unwrap();
            (m, own.parse::<usize>().unwrap())
        })
        .unzip();
    let entries = std::fs::read_dir(&cache).unwrap().count() as u64;
    assert_eq!(made.iter().sum::<u64>(), entries);
    assert_eq!(entries, rendered(&one), "{made:?}");
    assert_eq!(lights.iter().sum::<usize>(), 8);
    assert!(lights.iter().filter(|&&l| l > 0).count() >= 2, "one case's lights on one share: {lights:?}");
    assert_eq!(share(2).0, 0, "a share run again makes nothing");
    for k in 1..=3 {
        let (code, err, frag) = run_with(
            &text,
            dir.path(),
            "sharded",
            &["--shard", &format!("{k}/3"), "--cache", cache.to_str().unwrap()],
        );
        assert_eq!(code, 0, "{err}");
        assert!(frag.is_null(), "a shard writes only its fragment");
        let frag = dir.path().join(format!("sharded/shards/{k}-of-3/report.json"));
        let frag: serde_json::Value = read_json(&frag);
        assert_eq!(rendered(&frag), 0, "shard {k}");
    }
    // --renders-only needs a shard and a cache.
    let (code, err) = common::lumen(&["run", p.to_str().unwrap(), "--renders-only"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--shard"), "{err}");
    let (code, err) =
        common::lumen(&["run", p.to_str().unwrap(), "--shard", "1/2", "--renders-only", "--no-cache"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--no-cache"), "{err}");
}

/// Shares split structure from motion inside one case: the renders pass extracts the
/// features of the views each share renders, the matches pass verifies the blocks of pairs
/// each owns (10 views: blocks of views 0–7 × 0–7, 0–7 × 8–9 and 8–9 × 8–9), and the case,
/// run as a shard from that cache, reads them all and gives the one-process numbers.
#[test]
fn shares_split_structure_from_motion_inside_a_case() {
    let dir = tempfile::tempdir().unwrap();
    // The courtyard at half the resolution, to keep the test short.
    let scene = std::fs::read_to_string(common::root().join("pipelines/scenes/sfm-courtyard.toml")).unwrap();
    let small = scene
        .replace("width = 1024", "width = 512")
        .replace("height = 768", "height = 384")
        .replace("fx = 960.0", "fx = 480.0")
        .replace("fy = 960.0", "fy = 480.0")
        .replace("cx = 511.5", "cx = 255.5")
        .replace("cy = 383.5", "cy = 191.5");
    assert_ne!(small, scene);
    std::fs::write(dir.path().join("courtyard.toml"), small).unwrap();
    let text = "name = \"sfm\"\nseed = 3\n[[stages]]\nstage = \"sfm\"\ncase = \"courtyard\"\nscene = \"courtyard.toml\"\n\
                target = [0.0, 0.5, 0.6]\nradius = 3.5\nheight = 1.3\narc_deg = 40\nviews = 10\nspp = 4\n\
                bounds = { unregistered_images = 0 }\n";
    let (code, err, one) =
        run_with(text, dir.path(), "one", &["--cache", dir.path().join("c1").to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let cache = dir.path().join("c2");
    let p = dir.path().join("p.toml");
    let share = |k: usize, pass: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
            .args(["run", p.to_str().unwrap(), "--shard", &format!("{k}/2"), pass])
            .args(["--cache", cache.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        // "... are this share's, M made in ..."
        let made = err.split(" made in").next().and_then(|s| s.rsplit(' ').next()).unwrap();
        made.parse::<usize>().unwrap()
    };
    let renders: usize = (1..=2).map(|k| share(k, "--renders-only")).sum();
    assert_eq!(renders, 10);
    // Every view's render and its features.
    assert_eq!(std::fs::read_dir(&cache).unwrap().count(), 20);
    let blocks: Vec<usize> = (1..=2).map(|k| share(k, "--matches-only")).collect();
    assert_eq!(blocks.iter().sum::<usize>(), 3, "{blocks:?}");
    assert_eq!(std::fs::read_dir(&cache).unwrap().count(), 23);
    assert_eq!(share(1, "--matches-only"), 0, "a share run again makes nothing");
    for k in 1..=2 {
        let (code, err, _) = run_with(
            text,
            dir.path(),
            "sharded",
            &["--shard", &format!("{k}/2"), "--cache", cache.to_str().unwrap()],
        );
        assert_eq!(code, 0, "{err}");
    }
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["merge", dir.path().join("sharded").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let merged: serde_json::Value = read_json(&dir.path().join("sharded/report.json"));
    assert_eq!(numbers(&one), numbers(&merged));
    assert_eq!(case(&merged, "courtyard")["metrics"][0]["value"], 10.0);
    let notes = case(&merged, "courtyard")["notes"].to_string();
    assert!(
        notes
            .contains("the features of 10 of 10 images, the matches and two-view geometry of 45 of 45 pairs"),
        "{notes}"
    );
    // --matches-only needs a shard and a cache, and is not --renders-only.
    for bad in [vec!["--matches-only"], vec!["--shard", "1/2", "--matches-only", "--renders-only"]] {
        let (code, err) = common::lumen(&[&["run", p.to_str().unwrap()], bad.as_slice()].concat());
        assert_eq!(code, 2, "{err}");
    }
}

/// The photographs' sfm case splits the same way: each renders share extracts the features of
/// the photographs it owns (keyed by the file's content), a matches share verifies the block,
/// and the case read as a shard takes both from the cache, with the one-process numbers.
/// Four of Herz-Jesu's photographs, to keep the test short.
#[test]
fn shares_split_the_photographs_features_and_pairs() {
    let Some(data) = common::shared_data() else { return };
    let hj = data.join("sfm/herz-jesu-p8");
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    std::fs::create_dir(&images).unwrap();
    for name in ["0000.jpg", "0001.jpg", "0002.jpg", "0003.jpg"] {
        std::os::unix::fs::symlink(hj.join("images").join(name), images.join(name)).unwrap();
    }
    let text = format!(
        "seed = 2\n[[stages]]\nstage = \"sfm\"\ncase = \"herz-jesu-4\"\nimages = \"images\"\ncamera = \"{}\"\ntruth = \"{}\"\n",
        hj.join("images/K.txt").display(),
        hj.join("gt_dense_cameras").display()
    );
    let (code, err, one) = run_with(&text, dir.path(), "one", &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(case(&one, "herz-jesu-4")["metrics"][0]["value"], 4.0, "{one}");
    let cache = dir.path().join("cache");
    let p = dir.path().join("p.toml");
    let mut passes = Vec::new();
    for pass in ["--renders-only", "--matches-only"] {
        let shares: Vec<_> = (1..=2)
            .map(|k| {
                Command::new(env!("CARGO_BIN_EXE_lumen"))
                    .args(["run", p.to_str().unwrap(), "--shard", &format!("{k}/2"), pass])
                    .args(["--cache", cache.to_str().unwrap(), "--threads", "1"])
                    .spawn()
                    .unwrap()
            })
            .collect();
        for mut c in shares {
            assert!(c.wait().unwrap().success(), "{pass}");
        }
        passes.push(std::fs::read_dir(&cache).unwrap().count());
    }
    // Four photographs' features, then one block of pairs.
    assert_eq!(passes, [4, 5]);
    for k in 1..=2 {
        let args = ["--shard", &format!("{k}/2"), "--cache", cache.to_str().unwrap()];
        let (code, err, _) = run_with(&text, dir.path(), "sharded", &args);
        assert_eq!(code, 0, "{err}");
    }
    let (code, err) = common::lumen(&["merge", dir.path().join("sharded").to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let merged: serde_json::Value = read_json(&dir.path().join("sharded/report.json"));
    assert_eq!(numbers(&one), numbers(&merged));
    let notes = case(&merged, "herz-jesu-4")["notes"].to_string();
    assert!(
        notes.contains("the features of 4 of 4 images, the matches and two-view geometry of 6 of 6 pairs"),
        "{notes}"
    );
}

/// The same small pipeline through a live Slurm: `lumen slurm --submit --wait` submits the
/// 3-task array and the merge job that depends on it, waits for the merge, and its report
/// equals the one-process run's; a shard that fails makes Slurm cancel the merge, which
/// `lumen slurm` reports instead of exiting 0. It runs where `LUMEN_SLURM_TEST` is set, as
/// `.ci/run` sets it once `.ci/slurm-up` has started a one-node Slurm (with `SLURM_CONF`);
/// elsewhere it is skipped, and the skip is listed.
#[test]
fn live_slurm_runs_the_array_and_the_merge() {
    if std::env::var_os("LUMEN_SLURM_TEST").is_none() {
        common::skip_needing("Slurm", "LUMEN_SLURM_TEST is not set (.ci/slurm-up starts a one-node Slurm)");
        return;
    }
    let sinfo = Command::new("sinfo").args(["-h", "-o", "%a %t"]).output().expect("sinfo runs");
    assert!(sinfo.status.success(), "LUMEN_SLURM_TEST is set but sinfo fails: {sinfo:?}");
    let dir = tempfile::tempdir().unwrap();
    let text = small_pipeline();
    let (code, err, one) = run_with(&text, dir.path(), "one", &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let submit = |pipeline: &str, out: &str| {
        let p = dir.path().join(pipeline);
        let out = dir.path().join(out);
        let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
            .args(["slurm", p.to_str().unwrap(), "--shards", "3", "--out", out.to_str().unwrap()])
            .args(["--cpus-per-task", "1", "--time", "0:20:00", "--submit", "--wait"])
            .output()
            .unwrap();
        (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned(), out)
    };
    let (code, err, out) = submit("p.toml", "cluster");
    assert_eq!(code, Some(0), "{err}");
    for task in 0..3 {
        for log in ["render", "match", "shard"] {
            assert!(out.join(format!("slurm/{log}-{task}.log")).is_file(), "no {log} log of task {task}");
        }
    }
    let merged: serde_json::Value = read_json(&out.join("report.json"));
    assert_eq!(numbers(&one), numbers(&merged));
    assert_eq!(merged["threads"], 1);
    assert_eq!(rendered(&merged), 0, "the render array made every render");
    // A scene no shard can read: the two tasks holding its cases fail, so the merge never runs.
    let bad = text.replace("furnace.toml", "missing.toml");
    std::fs::write(dir.path().join("bad.toml"), bad).unwrap();
    let (code, err, out) = submit("bad.toml", "bad");
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("cancelled the merge") && !out.join("report.json").exists(), "{err}");
}
