//! The run report: `report.json` (machine-readable), `report.md` (tables for a person) and,
//! for every sweep, a plot of error against time with its Pareto front (`plots/*.svg`).
//! The report is the only place that sees estimates and truth side by side.

use super::cache::Event;
use super::metric::{fmt_value, Metric};
use super::names::file_stem;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What a case declared it would end with, and what it did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Outcome {
    /// `result` (metrics within their bounds) or `error: KIND`.
    pub declared: String,
    /// `result` or `error: KIND`.
    pub actual: String,
}

/// A stage's error as the report shows it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StageFailure {
    pub kind: String,
    pub message: String,
}

/// Renders a case asked for: how many were rendered and how many read back from the cache.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Renders {
    pub rendered: usize,
    pub reused: usize,
    /// Seconds spent rendering (reading back is counted in `reused_s`).
    pub rendered_s: f64,
    pub reused_s: f64,
}

impl Renders {
    pub fn from_events(events: &[Event]) -> Renders {
        let mut r = Renders::default();
        for e in events {
            if e.reused {
                r.reused += 1;
                r.reused_s += e.seconds;
            } else {
                r.rendered += 1;
                r.rendered_s += e.seconds;
            }
        }
        r
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StageReport {
    pub stage: String,
    pub case: String,
    /// The entry's case name; the cases of one sweep share it.
    pub group: String,
    /// The swept fields' values (empty outside a sweep).
    pub sweep: BTreeMap<String, String>,
    /// `alone` (upstream quantities from truth) or `chained` (from the previous stage).
    pub mode: String,
    pub seed: u64,
    pub outcome: Outcome,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<StageFailure>,
    pub metrics: Vec<Metric>,
    /// `render` (synthesis), `solve`, `validate` and `total`, in seconds.
    pub timings_s: BTreeMap<String, f64>,
    pub renders: Renders,
    /// The metric this case's sweep plots against time.
    pub plot_metric: String,
    pub notes: Vec<String>,
    /// Why the case did not run (its real data are absent): no metric, no verdict, no miss.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

impl StageReport {
    /// The outcome as the report's tables show it: skipped (and why), the outcome when it is
    /// the declared one, or the outcome in bold beside the declared one.
    pub fn outcome_text(&self) -> String {
        match &self.skipped {
            Some(why) => format!("skipped ({why})"),
            None if self.outcome.declared == self.outcome.actual => self.outcome.actual.clone(),
            None => format!("**{}** (declared {})", self.outcome.actual, self.outcome.declared),
        }
    }

    /// Whether the case failed: an outcome other than declared, or a metric that missed its
    /// bound without a declared miss. (A declared miss now met is judged over its entry's
    /// cases: `Report::misses_now_met`.)
    pub fn failed(&self) -> bool {
        self.skipped.is_none() && self.outcome.declared != self.outcome.actual
            || self.metrics.iter().any(Metric::failed)
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Report {
    pub pipeline: String,
    pub seed: u64,
    pub lumen_version: String,
    /// The git commit lumen was built from (`+changes` when the checkout had uncommitted
    /// changes), or `unknown`.
    pub git_commit: String,
    /// When the run started (UTC, RFC 3339).
    pub started: String,
    /// The machine: processor model (family, model), widest vectors and logical cores.
    pub machine: String,
    pub threads: usize,
    /// Wall time of the whole run, in seconds.
    pub total_s: f64,
    pub stages: Vec<StageReport>,
    /// Every case ended as declared, every metric met its bound or has a declared miss, and
    /// no declared miss met its bound.
    pub passed: bool,
    /// Problems that did not stop the run (e.g. the render cache could not be written).
    pub warnings: Vec<String>,
    /// Set in a shard's fragment (`lumen run --shard K/N`): which part of the pipeline it holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fragment: Option<Fragment>,
    /// Files cases asked to keep, written with the report.
    #[serde(skip)]
    pub files: Vec<(PathBuf, super::stages::Kept)>,
}

impl Report {
    pub fn new(pipeline: String, seed: u64, stages: Vec<StageReport>, total_s: f64) -> Report {
        let mut report = Report {
            pipeline,
            seed,
            lumen_version: env!("CARGO_PKG_VERSION").into(),
            git_commit: env!("LUMEN_GIT_COMMIT").into(),
            started: String::new(),
            machine: machine(),
            threads: rayon::current_num_threads(),
            total_s,
            stages,
            passed: false,
            warnings: Vec::new(),
            fragment: None,
            files: Vec::new(),
        };
        report.judge();
        report
    }

    /// One line per failed metric or case: `stage/case/metric = value unit, bound …`.
    pub fn failures(&self) -> Vec<String> {
        let mut v = Vec::new();
        for s in &self.stages {
            if s.skipped.is_none() && s.outcome.declared != s.outcome.actual {
                let why = s.error.as_ref().map(|e| format!(": {}", e.message)).unwrap_or_default();
                v.push(format!(
                    "{}/{} declared {}, ended with {}{why}",
                    s.stage, s.case, s.outcome.declared, s.outcome.actual
                ));
            }
            for m in s.metrics.iter().filter(|m| m.failed()) {
                let bound = m.bound.map_or("—".into(), |b| b.text());
                v.push(format!(
                    "{}/{}/{} = {} {}, bound {bound}",
                    s.stage,
                    s.case,
                    m.name,
                    value_text(m),
                    m.unit
                ));
            }
        }
        for (stage, group, name) in self.misses_now_met() {
            let values: Vec<String> = self
                .stages
                .iter()
                .filter(|s| s.stage == stage && s.group == group)
                .flat_map(|s| s.metrics.iter().filter(|m| m.name == name).map(move |m| (s, m)))
                .map(|(s, m)| format!("{} {}", s.case, value_text(m)))
                .collect();
            v.push(format!(
                "{stage}/{group}/{name}: declared a miss, now met ({}): remove expected_miss.{name} from the entry, or tighten its bound",
                values.join(", ")
            ));
        }
        v
    }

    /// Declared misses that every case of their entry now meets, as (stage, entry, metric).
    /// A declaration belongs to its entry, so in a sweep it stands while one case still
    /// misses. A fragment holds part of an entry's sweep at most, and judges none.
    pub fn misses_now_met(&self) -> Vec<(String, String, String)> {
        if self.fragment.is_some() {
            return Vec::new();
        }
        let mut verdicts: Vec<((&str, &str, &str), bool)> = Vec::new();
        for s in self.stages.iter().filter(|s| s.skipped.is_none()) {
            for m in s.metrics.iter().filter(|m| m.expected_miss.is_some() && m.unjudged().is_none()) {
                let key = (s.stage.as_str(), s.group.as_str(), m.name.as_str());
                let met = m.pass == Some(true);
                match verdicts.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, all)) => *all &= met,
                    None => verdicts.push((key, met)),
                }
            }
        }
        verdicts
            .into_iter()
            .filter(|(_, all)| *all)
            .map(|((a, b, c), _)| (a.to_string(), b.to_string(), c.to_string()))
            .collect()
    }

    /// Sets `passed`: no case failed and no declared miss is met by its whole entry.
    pub fn judge(&mut self) {
        self.passed = !self.stages.iter().any(StageReport::failed) && self.misses_now_met().is_empty();
    }

    /// The sweeps: groups of more than one case, in file order.
    pub fn sweeps(&self) -> Vec<(&str, Vec<&StageReport>)> {
        let mut groups: Vec<(&str, Vec<&StageReport>)> = Vec::new();
        for s in self.stages.iter().filter(|s| !s.sweep.is_empty()) {
            match groups.iter_mut().find(|(g, _)| *g == s.group) {
                Some((_, v)) => v.push(s),
                None => groups.push((&s.group, vec![s])),
            }
        }
        groups
    }

    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# lumen report: {}\n", self.pipeline);
        let _ = writeln!(
            s,
            "Started {}; lumen {} (commit {}); {}; {} threads; seed {}; {:.1} s in all. Result: **{}**\n",
            self.started,
            self.lumen_version,
            self.git_commit,
            self.machine,
            self.threads,
            self.seed,
            self.total_s,
            if self.passed {
                "every case ended as declared, every metric met its bound or missed as declared"
            } else {
                "a case missed"
            }
        );
        let _ = writeln!(
            s,
            "Columns: *render* is the time to synthesise the case's input (renders and truth; renders \
             read back from the cache cost almost nothing), *solve* the solver's own time; *renders* \
             counts images rendered / reused from the cache (the render stage renders its image afresh, outside the cache, and times it as its solve); *metrics met* counts bounded metrics that \
             met their bound, with declared misses and skipped metrics shown apart.\n"
        );
        let _ = writeln!(
            s,
            "| stage | case | outcome | render (s) | solve (s) | renders | metrics met |\n|---|---|---|---:|---:|---|---|"
        );
        let now_met_all = self.misses_now_met();
        let whole_entry_met = |st: &StageReport, name: &str| entry_meets(&now_met_all, st, name);
        for st in &self.stages {
            let bounded = st.metrics.iter().filter(|m| m.bound.is_some() && m.unjudged().is_none()).count();
            let met = st.metrics.iter().filter(|m| m.pass == Some(true)).count();
            let declared =
                st.metrics.iter().filter(|m| m.pass == Some(false) && m.expected_miss.is_some()).count();
            let now_met = st.metrics.iter().filter(|m| whole_entry_met(st, &m.name)).count();
            let skipped = st.metrics.iter().filter(|m| m.skipped.is_some() && m.bound.is_some()).count();
            let mut met_text = format!("{met}/{bounded}");
            if declared > 0 {
                met_text += &format!(" ({declared} declared miss)");
            }
            if now_met > 0 {
                met_text += &format!(" (**{now_met} declared miss now met**)");
            }
            if skipped > 0 {
                met_text += &format!(", {skipped} skipped");
            }
            if st.skipped.is_some() {
                met_text = "—".into();
            }
            let outcome = st.outcome_text();
            let t = |k: &str| st.timings_s.get(k).copied().unwrap_or(0.0);
            let _ = writeln!(
                s,
                "| {} | {} | {outcome} | {:.2} | {:.3} | {} / {} | {met_text} |",
                st.stage,
                st.case,
                t("render"),
                t("solve"),
                st.renders.rendered,
                st.renders.reused
            );
        }
        let sweeps = self.sweeps();
        if !sweeps.is_empty() {
            let _ = writeln!(s, "\n## Error against time\n");
            for (group, cases) in &sweeps {
                let _ = writeln!(s, "### {group}: {}\n", cases[0].plot_metric);
                let _ = writeln!(s, "![{group}](plots/{}.svg)\n", file_stem(group));
                sweep_table(&mut s, cases);
            }
        }
        for st in &self.stages {
            let _ = writeln!(s, "\n## {} — {}\n", st.stage, st.case);
            case_section(&mut s, st, &now_met_all);
        }
        for w in &self.warnings {
            let _ = writeln!(s, "\nWarning: {w}");
        }
        s
    }

    /// Writes `report.json`, `report.md`, the sweeps' plots and the files cases asked to keep
    /// into `dir`, each atomically.
    /// Writes the report, its plots and the files cases kept, all together (`io::write_together`):
    /// a failure leaves none of them in `dir`.
    pub fn write(&self, dir: &Path) -> Result<(), super::Error> {
        crate::image::io::write_together(dir, |staged| self.write_files(staged))
    }

    fn write_files(&self, dir: &Path) -> Result<(), super::Error> {
        let werr = |path: &Path, message: String| super::Error::Write { path: path.into(), message };
        for (name, kept) in &self.files {
            let path = dir.join(name);
            match kept {
                super::stages::Kept::Image(img) => crate::image::io::write(&path, img).map(|_| ()),
                super::stages::Kept::Bytes(b) => {
                    crate::image::io::write_atomically(&path, |tmp| std::fs::write(tmp, b))
                }
            }
            .map_err(|e| werr(&path, e.to_string()))?;
        }
        for (group, cases) in self.sweeps() {
            let path = dir.join("plots").join(format!("{}.svg", file_stem(group)));
            let svg = plot_svg(group, &cases);
            crate::image::io::write_atomically(&path, |tmp| std::fs::write(tmp, &svg))
                .map_err(|e| werr(&path, e.to_string()))?;
        }
        let json =
            serde_json::to_string_pretty(self).map_err(|e| werr(&dir.join("report.json"), e.to_string()))?;
        for (name, text) in [("report.json", json), ("report.md", self.to_markdown())] {
            let path = dir.join(name);
            crate::image::io::write_atomically(&path, |tmp| std::fs::write(tmp, &text))
                .map_err(|e| werr(&path, e.to_string()))?;
        }
        Ok(())
    }
}

/// What a fragment holds besides its cases' reports: enough to check, when merging, that the
/// fragments come from one pipeline file run by one lumen, and where each case goes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Fragment {
    pub shard: usize,
    pub shards: usize,
    /// FNV-1a 128 of the pipeline file's bytes.
    pub pipeline_digest: String,
    /// Cases in the whole pipeline.
    pub cases: usize,
    /// Each of this fragment's stages' position in the pipeline (0-based), in order.
    pub indices: Vec<usize>,
    /// Files the cases kept, relative to the fragment's folder.
    pub kept: Vec<PathBuf>,
}

/// A case's error or skip, its metrics with bounds and verdicts, timings and notes.
/// `now_met` is `Report::misses_now_met`, computed once for the whole report.
pub fn case_section(s: &mut String, st: &StageReport, now_met: &[(String, String, String)]) {
    let whole_entry_met = |st: &StageReport, name: &str| entry_meets(now_met, st, name);
    if let Some(e) = &st.error {
        let _ = writeln!(s, "Ended with a {} error: {}\n", e.kind, e.message);
    }
    if let Some(why) = &st.skipped {
        let _ = writeln!(s, "Skipped: {why}.\n");
    }
    if !st.metrics.is_empty() {
        let _ = writeln!(s, "| metric | value | unit | bound | verdict |\n|---|---:|---|---:|---|");
    }
    for m in &st.metrics {
        let bound = m.bound.map_or("—".into(), |b| b.text());
        let whole = whole_entry_met(st, &m.name);
        let verdict = match (m.pass, &m.expected_miss, &m.skipped) {
            (_, _, Some(why)) => format!("skipped: {why}"),
            _ if m.not_applicable.is_some() => {
                format!("n/a: {}", m.not_applicable.as_deref().unwrap_or_default())
            }
            (Some(true), Some(why), _) if whole => {
                format!("**DECLARED MISS NOW MET** (declared: {why})")
            }
            (Some(true), Some(why), _) => {
                format!("pass (the entry declares a miss some case still has: {why})")
            }
            (Some(true), None, _) => "pass".to_string(),
            (Some(false), Some(why), _) => format!("expected miss: {why}"),
            (Some(false), None, _) => "**MISS**".to_string(),
            (None, _, _) => "—".to_string(),
        };
        let _ = writeln!(s, "| {} | {} | {} | {bound} | {verdict} |", m.name, value_text(m), m.unit);
    }
    let times: Vec<String> = st.timings_s.iter().map(|(k, v)| format!("{k} {v:.3} s")).collect();
    let _ = writeln!(
        s,
        "\nTimings: {}. Renders: {} rendered ({:.2} s), {} reused from the cache ({:.2} s).",
        times.join(", "),
        st.renders.rendered,
        st.renders.rendered_s,
        st.renders.reused,
        st.renders.reused_s
    );
    for n in &st.notes {
        let _ = writeln!(s, "\n- {n}");
    }
}

/// Whether the declared miss of `name` in `st`'s entry is met by every case of the entry
/// (`now_met` as `Report::misses_now_met` gives it).
fn entry_meets(now_met: &[(String, String, String)], st: &StageReport, name: &str) -> bool {
    now_met.iter().any(|(a, b, c)| *a == st.stage && *b == st.group && c == name)
}

/// A sweep's table: each case's solve and render time, its plotted error, and whether it is
/// on the Pareto front.
pub fn sweep_table(s: &mut String, cases: &[&StageReport]) {
    let _ = writeln!(
        s,
        "| case | solve (s) | render (s) | {} | Pareto |\n|---|---:|---:|---:|---|",
        cases[0].plot_metric
    );
    let points = sweep_points(cases);
    let front = pareto(&points);
    for (k, (st, p)) in cases.iter().zip(&points).enumerate() {
        let value = p.map_or("—".into(), |(_, e)| fmt_value(e));
        let _ = writeln!(
            s,
            "| {} | {:.3} | {:.2} | {value} | {} |",
            st.case,
            st.timings_s.get("solve").copied().unwrap_or(0.0),
            st.timings_s.get("render").copied().unwrap_or(0.0),
            if front.contains(&k) { "yes" } else { "" }
        );
    }
    let _ = writeln!(s);
}

/// The processor model with its family and model numbers (from /proc/cpuinfo where there is
/// one: a name such as "AMD EPYC" covers several generations), its widest vectors, and the
/// logical cores.
fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |name: &str| {
        info.lines()
            .find(|l| l.split(':').next().is_some_and(|k| k.trim() == name))
            .and_then(|l| l.split(':').nth(1))
            .map(|v| v.trim().to_string())
            .filter(|v| !v.is_empty())
    };
    let model = field("model name").unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let generation = match (field("cpu family"), field("model")) {
        (Some(f), Some(m)) => format!(" (family {f}, model {m})"),
        _ => String::new(),
    };
    format!("{model}{generation}, {}, {cores} logical cores", vectors())
}

/// The widest vector instructions the processor has, as lumen's run-time dispatch sees them.
fn vectors() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx512f") {
            return "AVX-512";
        }
        if std::is_x86_feature_detected!("avx2") {
            return "AVX2";
        }
        "SSE2"
    }
    #[cfg(not(target_arch = "x86_64"))]
    "no x86 vectors"
}

/// Each case's (time, error): solve time for solver stages, the render's time for the
/// render stage (there the renderer is what is measured); `None` where the error is missing.
fn sweep_points(cases: &[&StageReport]) -> Vec<Option<(f64, f64)>> {
    cases
        .iter()
        .map(|st| {
            let t = st.timings_s.get("solve").copied()?;
            let e = st.metrics.iter().find(|m| m.name == st.plot_metric)?.value?;
            Some((t.max(1e-6), e))
        })
        .collect()
}

/// Indices of the points no other point beats in both time and error.
pub fn pareto(points: &[Option<(f64, f64)>]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let Some((ti, ei)) = points[i] else { return false };
            !points.iter().enumerate().any(|(j, p)| {
                p.is_some_and(|(tj, ej)| j != i && tj <= ti && ej <= ei && (tj < ti || ej < ei))
            })
        })
        .collect()
}

/// Error against time on log-log axes, every case a point labelled with its swept values,
/// the Pareto front as a line.
pub fn plot_svg(group: &str, cases: &[&StageReport]) -> String {
    use plotters::prelude::*;
    let points = sweep_points(cases);
    let metric = &cases[0].plot_metric;
    let front = pareto(&points);
    let valid: Vec<(f64, f64)> = points.iter().flatten().copied().filter(|(_, e)| *e > 0.0).collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 480)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let span = |v: &mut dyn Iterator<Item = f64>| {
            let (lo, hi) = v.fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
            if lo.is_finite() && hi > 0.0 {
                (lo / 1.5, hi * 1.5)
            } else {
                (1e-3, 1.0)
            }
        };
        let (t0, t1) = span(&mut valid.iter().map(|p| p.0));
        let (e0, e1) = span(&mut valid.iter().map(|p| p.1));
        let time_label = if cases[0].stage == "render" { "render time (s)" } else { "solve time (s)" };
        let chart = ChartBuilder::on(&root)
            .caption(format!("{group}: {metric} against time"), ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d((t0..t1).log_scale(), (e0..e1).log_scale());
        if let Ok(mut chart) = chart {
            let _ = chart.configure_mesh().x_desc(time_label).y_desc(metric.as_str()).draw();
            let mut line: Vec<(f64, f64)> =
                front.iter().filter_map(|&i| points[i]).filter(|p| p.1 > 0.0).collect();
            line.sort_by(|a, b| a.0.total_cmp(&b.0));
            let _ = chart.draw_series(LineSeries::new(line, &RED)).map(|s| s.label("Pareto front"));
            for (st, p) in cases.iter().zip(&points) {
                if let Some((t, e)) = p.filter(|p| p.1 > 0.0) {
                    let label: Vec<String> = st.sweep.iter().map(|(k, v)| format!("{k}={v}")).collect();
                    let _ = chart.draw_series(std::iter::once(Circle::new((t, e), 4, BLUE.filled())));
                    let _ = chart.draw_series(std::iter::once(Text::new(
                        label.join(","),
                        (t, e),
                        ("sans-serif", 12).into_font(),
                    )));
                }
            }
        }
        let _ = root.present();
    }
    svg
}

pub fn value_text(m: &Metric) -> String {
    match (m.value, &m.missing) {
        (Some(v), _) => fmt_value(v),
        (None, Some(why)) if m.unjudged().is_none() => format!("— ({why})"),
        _ => "—".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::pareto;

    #[test]
    fn pareto_front_keeps_the_undominated() {
        let p =
            [Some((1.0, 5.0)), Some((2.0, 3.0)), Some((3.0, 4.0)), None, Some((4.0, 1.0)), Some((2.0, 3.0))];
        // (3, 4) is beaten by (2, 3); the two equal points do not beat each other.
        assert_eq!(pareto(&p), vec![0, 1, 4, 5]);
    }
}
