//! Random mutations of the example scene and pipeline files (numbers replaced by 0, −1, NaN,
//! ±inf, 1e39, 1e-45, 1e300, 2³²; keys dropped, duplicated or renamed; arrays shortened) never
//! panic, crash or hang: each either fails with an error that names something, or gives a
//! finite output. The runner is seeded, so a failure is found again run after run; one found
//! once becomes a named test in `bad_input.rs`.

mod common;

use lumen::pipeline::{self, file as pipeline_file, RunOptions};
use lumen::render;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// Longest a mutated file may take to load and render (or run) before it counts as a hang. A
/// clean run of each takes well under a second.
const DEADLINE: Duration = Duration::from_secs(60);

/// Mutations tried per file.
const CASES: u32 = 150;

/// Numbers a mutation puts in place of one in the file.
const EXTREMES: [&str; 10] =
    ["0", "-1", "nan", "inf", "-inf", "1e39", "1e-45", "1e300", "4294967296", "-0.0"];

/// One change to a TOML file's text.
#[derive(Clone, Debug)]
enum Mutation {
    /// The n-th number (counted over the file, wrapping) becomes `EXTREMES[k]`.
    Number(usize, usize),
    /// The n-th `key = value` line is dropped, duplicated or has its key renamed.
    DropKey(usize),
    DuplicateKey(usize),
    RenameKey(usize),
    /// The n-th array literal loses its last element.
    ShortenArray(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), 0..EXTREMES.len()).prop_map(|(n, k)| Mutation::Number(n, k)),
        1 => any::<usize>().prop_map(Mutation::DropKey),
        1 => any::<usize>().prop_map(Mutation::DuplicateKey),
        1 => any::<usize>().prop_map(Mutation::RenameKey),
        1 => any::<usize>().prop_map(Mutation::ShortenArray),
    ]
}

/// Byte ranges of the numbers in `text` outside comments and strings.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let code = line.split('#').next().unwrap_or("");
        let bytes = code.as_bytes();
        let mut in_string = false;
        let mut i = 0;
        while i < bytes.len() {
            let c = bytes[i];
            if c == b'"' {
                in_string = !in_string;
            }
            let starts = !in_string
                && (c.is_ascii_digit() || (c == b'-' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit)))
                && (i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_'));
            if starts {
                let mut j = i + 1;
                while j < bytes.len() && (bytes[j].is_ascii_alphanumeric() || b".+-_".contains(&bytes[j])) {
                    j += 1;
                }
                out.push((offset + i, offset + j));
                i = j;
            } else {
                i += 1;
            }
        }
        offset += line.len();
    }
    out
}

/// Line indices of `key = value` lines.
fn key_lines(lines: &[&str]) -> Vec<usize> {
    lines
        .iter()
        .enumerate()
        .filter(|(_, l)| {
            let t = l.trim_start();
            !t.starts_with('#') && !t.starts_with('[') && t.contains('=')
        })
        .map(|(i, _)| i)
        .collect()
}

/// `text` with the mutation applied (unchanged where the file has nothing of the kind).
fn apply(text: &str, m: &Mutation) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let keys = key_lines(&lines);
    let edit_line = |n: usize, f: &dyn Fn(&str) -> Vec<String>| -> String {
        if keys.is_empty() {
            return text.to_string();
        }
        let at = keys[n % keys.len()];
        let mut out: Vec<String> = Vec::new();
        for (i, l) in lines.iter().enumerate() {
            if i == at {
                out.extend(f(l));
            } else {
                out.push(l.to_string());
            }
        }
        out.join("\n") + "\n"
    };
    match *m {
        Mutation::Number(n, k) => {
            let found = numbers(text);
            if found.is_empty() {
                return text.to_string();
            }
            let (a, b) = found[n % found.len()];
            format!("{}{}{}", &text[..a], EXTREMES[k], &text[b..])
        }
        Mutation::DropKey(n) => edit_line(n, &|_| vec![]),
        Mutation::DuplicateKey(n) => edit_line(n, &|l| vec![l.to_string(), l.to_string()]),
        Mutation::RenameKey(n) => edit_line(n, &|l| {
            let (key, rest) = l.split_once('=').unwrap_or((l, ""));
            vec![format!("{}_x ={rest}", key.trim_end())]
        }),
        Mutation::ShortenArray(n) => {
            let arrays: Vec<(usize, usize)> = text
                .match_indices('[')
                .filter_map(|(a, _)| {
                    let close = a + text[a..].find(']')?;
                    let inner = &text[a + 1..close];
                    (inner.contains(',') && !inner.contains('[') && !inner.contains('"'))
                        .then_some((a, close))
                })
                .collect();
            if arrays.is_empty() {
                return text.to_string();
            }
            let (a, close) = arrays[n % arrays.len()];
            let cut = a + text[a..close].rfind(',').unwrap_or(0);
            format!("{}{}", &text[..cut], &text[close..])
        }
    }
}

/// Runs `f` on a thread of its own; a panic or a run past `DEADLINE` fails the test with
/// `what` named.
fn within_deadline<T: Send + 'static>(what: String, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)));
    });
    match rx.recv_timeout(DEADLINE) {
        Ok(Ok(v)) => v,
        Ok(Err(_)) => panic!("panicked on {what}"),
        Err(_) => panic!("still running after {DEADLINE:?} on {what}"),
    }
}

/// A seeded runner that keeps no files of failures (a failure is printed and made a named
/// test instead).
fn runner(cases: u32) -> TestRunner {
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    TestRunner::new_with_rng(config, TestRng::deterministic_rng(RngAlgorithm::ChaCha))
}

/// Loads a mutated scene; when it loads, renders a 16×16 window at the image's centre (one
/// sample, four segments) and, with a sensor, exposes it: every value finite.
fn check_scene(text: String) -> Result<bool, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let scene = match common::scene(&text, dir.path()) {
        Ok(s) => s,
        Err(e) => {
            let message = e.to_string();
            return if message.trim().is_empty() { Err("an empty error".into()) } else { Ok(false) };
        }
    };
    let (w, h) = (scene.camera.width, scene.camera.height);
    let (x0, y0) = ((w / 2).saturating_sub(8), (h / 2).saturating_sub(8));
    let mut settings = common::settings(&scene, 1, 4);
    settings.crop = Some([x0, y0, (x0 + 16).min(w), (y0 + 16).min(h)]);
    let film = render::render(&scene, &settings);
    if let Some(v) = film.mean.data.iter().find(|v| !v.is_finite()) {
        return Err(format!("a pixel of {v}"));
    }
    if let Some(sensor) = &scene.sensor {
        let codes = sensor.expose(&film.mean, 1);
        if codes.iter().any(|&c| c > sensor.max_code()) {
            return Err("a code above the sensor's largest".into());
        }
    }
    Ok(true)
}

/// The example scenes: a mesh under an area light, a chessboard through a distorting lens and a
/// sensor, glossy spheres, a generated torus and the furnace. The Cornell box's mesh is named
/// by its absolute path, so the mutated copy can live in a temporary folder.
fn example_scenes() -> Vec<(String, String)> {
    let root = common::root();
    let scenes = root.join("pipelines/scenes");
    ["cornell-box", "calib-board", "glossy-spheres", "ps-torus", "furnace"]
        .iter()
        .map(|name| {
            let text = std::fs::read_to_string(scenes.join(format!("{name}.toml"))).unwrap();
            let data = root.join("data");
            (name.to_string(), text.replace("\"../../data/", &format!("\"{}/", data.display())))
        })
        .collect()
}

/// Checks `text` as it is (it must be accepted), then `CASES` mutations of it; returns how
/// many mutations were accepted (rendered or run) rather than refused.
fn mutate_and_check(name: &str, text: &str, check: fn(String) -> Result<bool, String>) -> usize {
    let original = text.to_string();
    match within_deadline(format!("{name} as it is"), move || check(original)) {
        Ok(accepted) => assert!(accepted, "{name} as it is was refused"),
        Err(e) => panic!("{name} as it is: {e}"),
    }
    let accepted = AtomicUsize::new(0);
    let result = runner(CASES).run(&mutation(), |m| {
        let mutated = apply(text, &m);
        let outcome = within_deadline(format!("{name} with {m:?}"), move || check(mutated));
        prop_assert!(outcome.is_ok(), "{name} with {m:?}: {}", outcome.unwrap_err());
        accepted.fetch_add(outcome.is_ok_and(|a| a) as usize, Ordering::Relaxed);
        Ok(())
    });
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
    let accepted = accepted.into_inner();
    eprintln!("{name}: {CASES} mutations, {accepted} accepted, the others refused with a reason");
    accepted
}

#[test]
fn mutated_scenes_give_an_error_or_a_finite_image() {
    for (name, text) in example_scenes() {
        // Mutations that leave every number in range must still render.
        assert!(mutate_and_check(&name, &text, check_scene) > 0, "{name}: no mutation rendered");
    }
}

/// A small pipeline of two cheap cases: a furnace render and a photometric sphere under six
/// lights.
fn small_pipeline() -> String {
    let scenes = common::root().join("pipelines/scenes");
    format!(
        "name = \"small\"\nseed = 5\n\
         [[stages]]\nstage = \"render\"\ncase = \"furnace\"\nscene = \"{0}/furnace.toml\"\nspp = 4\nexpect_uniform = [1.0, 1.0, 1.0]\nbounds = {{ nonfinite_samples = 0 }}\n\
         [[stages]]\nstage = \"photometric\"\ncase = \"sphere\"\nscene = \"{0}/ps-sphere.toml\"\nspp = 1\nlights = 6\nbounds = {{ masked_pixels = 0 }}\n",
        scenes.display()
    )
}

/// Parses a mutated pipeline file and, when it parses, runs it: the run either ends with an
/// error that names something, or with a report whose every number is finite.
fn check_pipeline(text: String) -> Result<bool, String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let path = dir.path().join("small.toml");
    std::fs::write(&path, &text).map_err(|e| e.to_string())?;
    let named = |e: String| if e.trim().is_empty() { Err("an empty error".to_string()) } else { Ok(false) };
    let file = match pipeline_file::parse(&text, &path) {
        Ok(f) => f,
        Err(e) => return named(e.to_string()),
    };
    let opts = RunOptions { threads: Some(1), progress: false, cache_dir: None, shard: None };
    let report = match pipeline::run(&path, &file, &opts) {
        Ok(r) => r,
        Err(e) => return named(e.to_string()),
    };
    let json = serde_json::to_value(&report).map_err(|e| e.to_string())?;
    for case in json["stages"].as_array().into_iter().flatten() {
        for metric in case["metrics"].as_array().into_iter().flatten() {
            if !metric["value"].is_number() {
                return Err(format!("{}: {} is {}", case["case"], metric["name"], metric["value"]));
            }
        }
    }
    Ok(true)
}

#[test]
fn mutated_pipelines_give_an_error_or_a_finite_report() {
    assert!(mutate_and_check("pipeline", &small_pipeline(), check_pipeline) > 0, "no mutation ran");
}

/// The mutations do what they say.
#[test]
fn mutations_change_what_they_name() {
    let text = "a = 1.5 # 7\nb = [1, 2, 3]\nc = \"x9\"\n";
    assert_eq!(numbers(text).len(), 4);
    assert_eq!(apply(text, &Mutation::Number(0, 2)), "a = nan # 7\nb = [1, 2, 3]\nc = \"x9\"\n");
    assert_eq!(apply(text, &Mutation::DropKey(1)), "a = 1.5 # 7\nc = \"x9\"\n");
    assert_eq!(
        apply(text, &Mutation::DuplicateKey(0)),
        "a = 1.5 # 7\na = 1.5 # 7\nb = [1, 2, 3]\nc = \"x9\"\n"
    );
    assert_eq!(apply(text, &Mutation::RenameKey(2)), "a = 1.5 # 7\nb = [1, 2, 3]\nc_x = \"x9\"\n");
    assert_eq!(apply(text, &Mutation::ShortenArray(0)), "a = 1.5 # 7\nb = [1, 2]\nc = \"x9\"\n");
}
