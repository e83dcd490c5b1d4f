//! The render cache: every image a stage synthesises is stored on disk under a key that is a
//! hash of a serialisable description of what was rendered (the recipe: the scene file and
//! every file it names, the stage's changes to the scene, the render settings, the seed, the
//! product kept, lumen's version). A second run, and cases that share renders (a sweep over
//! the number of views or a solver setting), read the images back instead of rendering them.
//!
//! Entries are content-keyed and written to a unique temporary name, then renamed, so a
//! reader never sees half a file and two processes writing the same key do no harm. An entry
//! that cannot be read back whole is rendered again and replaced. The cache never changes a
//! number: an entry holds the exact f32 values the renderer produced.
//!
//! A render share (`Cache::share`, `lumen run --shard K/N --renders-only`) splits the renders
//! of a whole pipeline, not its cases, over N processes: each renders only the entries whose
//! key is K − 1 modulo N, whatever case asks for them, and hands no image back, so the work
//! inside one large case (its views, lights or wavelength bands) is spread and an entry two
//! cases share is made once. The stages then run their cases from a full cache.
//!
//! A second pass of shares (`Pass::Matches`, `lumen run --shard K/N --matches-only`), after
//! the renders, spreads the work that needs every render of a case at hand: structure from
//! motion's blocks of image pairs to match and verify. Its stages read the renders back as a
//! case does and make the derived entries (`bytes`) they own. Derived entries (features,
//! verified pairs) are kept as bytes whose meaning the stage that asks for them knows.
//!
//! The key is FNV-1a over 128 bits of the recipe's JSON, written here rather than taken from a
//! crate because it must stay the same across toolchains and crate versions (std's hasher
//! does not promise that) and is ten lines.

use crate::image::Image;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// What happened to one requested render.
#[derive(Clone, Debug, Serialize)]
pub struct Event {
    pub case: String,
    /// What was rendered, e.g. `view 3` or `light 12`.
    pub what: String,
    /// Read back from the cache (true) or rendered (false).
    pub reused: bool,
    /// Time to render it, or to read it back.
    pub seconds: f64,
}

pub struct Cache {
    /// `None`: nothing is stored (every image is rendered).
    dir: Option<PathBuf>,
    /// A share: (K, N, pass), this process makes only the entries whose key is K − 1 mod N.
    share: Option<(usize, usize, Pass)>,
    shared: Mutex<ShareCount>,
    events: Mutex<Vec<Event>>,
    warnings: Mutex<Vec<String>>,
}

/// What a render share did: entries it owns, of them those it rendered, and the requests it
/// left to other shares.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShareCount {
    pub owned: usize,
    pub rendered: usize,
    pub others: usize,
}

/// FNV-1a, 128 bits.
pub fn fnv128(bytes: &[u8]) -> u128 {
    const OFFSET: u128 = 0x6c62272e07bb014262b821756295c58d;
    const PRIME: u128 = 0x0000000001000000000000000000013B;
    bytes.iter().fold(OFFSET, |h, &b| (h ^ b as u128).wrapping_mul(PRIME))
}

/// A digest of a scene file and of every file it names (meshes, textures, environment maps),
/// so that editing any of them changes the key of every render of the scene.
pub fn scene_digest(path: &Path) -> Result<String, crate::render::Error> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| crate::render::Error::Io { path: path.to_path_buf(), message: e.to_string() })?;
    let value: toml::Value = toml::from_str(&text)
        .map_err(|e| crate::render::Error::Parse { path: path.to_path_buf(), message: e.to_string() })?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut bytes = text.into_bytes();
    let mut strings = Vec::new();
    collect_strings(&value, &mut strings);
    for s in strings {
        let f = dir.join(&s);
        if f.is_file() {
            if let Ok(content) = std::fs::read(&f) {
                bytes.extend_from_slice(s.as_bytes());
                bytes.extend_from_slice(&fnv128(&content).to_le_bytes());
            }
        }
    }
    Ok(format!("{:032x}", fnv128(&bytes)))
}

fn collect_strings(v: &toml::Value, out: &mut Vec<String>) {
    match v {
        toml::Value::String(s) => out.push(s.clone()),
        toml::Value::Array(a) => a.iter().for_each(|x| collect_strings(x, out)),
        toml::Value::Table(t) => t.values().for_each(|x| collect_strings(x, out)),
        _ => {}
    }
}

const MAGIC: &[u8; 8] = b"LUMENC01";
const MAGIC_BYTES: &[u8; 8] = b"LUMENB01";

/// The two passes of shares (module docs): renders first, then the work that needs them all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pass {
    Renders,
    Matches,
}

/// An entry's key: FNV-1a 128 of lumen's version and the recipe's JSON.
fn key(recipe: &impl Serialize) -> Option<u128> {
    serde_json::to_string(&(env!("CARGO_PKG_VERSION"), recipe)).ok().map(|j| fnv128(j.as_bytes()))
}

impl Cache {
    pub fn new(dir: Option<PathBuf>) -> Cache {
        Cache {
            dir,
            share: None,
            shared: Mutex::new(ShareCount::default()),
            events: Mutex::new(Vec::new()),
            warnings: Mutex::new(Vec::new()),
        }
    }

    /// Share K of N (1 ≤ K ≤ N) of `pass` over the cache in `dir` (module docs).
    pub fn share(dir: PathBuf, k: usize, n: usize, pass: Pass) -> Cache {
        Cache { share: Some((k, n, pass)), ..Cache::new(Some(dir)) }
    }

    /// A share runs no case: the stages stop after asking for their renders (and, in the
    /// matches pass, after making the derived entries they own).
    pub fn renders_only(&self) -> bool {
        self.share.is_some()
    }

    /// The pass of a share, `None` in a run of cases.
    pub fn pass(&self) -> Option<Pass> {
        self.share.map(|s| s.2)
    }

    /// Whether this process makes the entry `recipe` names: in a share, when its key is
    /// K − 1 mod N; otherwise always.
    pub fn owns(&self, recipe: &impl Serialize) -> bool {
        match self.share {
            Some((k, n, _)) => key(recipe).is_some_and(|key| key % n as u128 == (k - 1) as u128),
            None => true,
        }
    }

    fn path_of(&self, recipe: &impl Serialize) -> Option<PathBuf> {
        self.dir.as_ref().zip(key(recipe)).map(|(dir, key)| dir.join(format!("{key:032x}.bin")))
    }

    /// The images of `recipe` when the cache holds them whole (no event is logged: a share
    /// reading back what it rendered).
    pub fn stored_images(&self, recipe: &impl Serialize) -> Option<Vec<Image>> {
        self.path_of(recipe).as_deref().and_then(read_entry)
    }

    /// The derived entry `recipe` names (module docs), when the cache holds it whole.
    pub fn bytes(&self, recipe: &impl Serialize) -> Option<Vec<u8>> {
        let bytes = std::fs::read(self.path_of(recipe)?).ok()?;
        bytes.strip_prefix(MAGIC_BYTES).map(<[u8]>::to_vec)
    }

    /// Stores a derived entry (without a cache folder, nothing); a failure is a warning.
    pub fn store_bytes(&self, recipe: &impl Serialize, bytes: &[u8]) {
        if let Some(path) = self.path_of(recipe) {
            if let Err(e) = write_atomically(&path, &[MAGIC_BYTES.as_slice(), bytes].concat()) {
                self.warn(format!("render cache: cannot write {}: {e}", path.display()));
            }
        }
    }

    fn warn(&self, w: String) {
        if let Ok(mut ws) = self.warnings.lock() {
            ws.push(w);
        }
    }

    /// The images `recipe` describes: read back when the cache holds them, otherwise made by
    /// `make` and stored. `case` and `what` only label the event in the report. In a share of
    /// the renders pass, `None`: the entry is made if this share owns it and the cache lacks
    /// it. (In the matches pass, as in a run of cases.)
    pub fn images<E>(
        &self,
        case: &str,
        what: &str,
        recipe: &impl Serialize,
        make: impl FnOnce() -> Result<Vec<Image>, E>,
    ) -> Result<Option<Vec<Image>>, E> {
        let t = std::time::Instant::now();
        let path = self.path_of(recipe);
        if let Some((_, _, Pass::Renders)) = self.share {
            let owned = self.owns(recipe);
            // Present entries were renamed into place whole; a damaged one is remade when a
            // case reads it.
            let present = path.as_deref().is_some_and(Path::is_file);
            let make_it = owned && !present;
            if make_it {
                let images = make()?;
                self.store(path.as_deref(), &images);
            }
            self.count(owned, make_it);
            return Ok(None);
        }
        if let Some(images) = path.as_deref().and_then(read_entry) {
            self.log(case, what, true, t.elapsed().as_secs_f64());
            return Ok(Some(images));
        }
        let images = make()?;
        self.log(case, what, false, t.elapsed().as_secs_f64());
        self.store(path.as_deref(), &images);
        Ok(Some(images))
    }

    fn store(&self, path: Option<&Path>, images: &[Image]) {
        if let Some(path) = path {
            if let Err(e) = write_entry(path, images) {
                self.warn(format!("render cache: cannot write {}: {e}", path.display()));
            }
        }
    }

    /// Counts an entry a share asked for: its own or another's, made now or already there.
    pub fn count(&self, owned: bool, made: bool) {
        if let Ok(mut c) = self.shared.lock() {
            c.owned += usize::from(owned);
            c.rendered += usize::from(made);
            c.others += usize::from(!owned);
        }
    }

    /// What this share did so far (zero outside a share).
    pub fn share_count(&self) -> ShareCount {
        self.shared.lock().map(|c| *c).unwrap_or_default()
    }

    fn log(&self, case: &str, what: &str, reused: bool, seconds: f64) {
        if let Ok(mut ev) = self.events.lock() {
            ev.push(Event { case: case.into(), what: what.into(), reused, seconds });
        }
    }

    /// The events of one case, in request order.
    pub fn events_of(&self, case: &str) -> Vec<Event> {
        self.events
            .lock()
            .map(|ev| ev.iter().filter(|e| e.case == case).cloned().collect())
            .unwrap_or_default()
    }

    /// Problems writing the cache (the run goes on without the entry).
    pub fn warnings(&self) -> Vec<String> {
        self.warnings.lock().map(|w| w.clone()).unwrap_or_default()
    }
}

fn read_entry(path: &Path) -> Option<Vec<Image>> {
    let bytes = std::fs::read(path).ok()?;
    let rest = bytes.strip_prefix(MAGIC)?;
    let u32_at = |b: &[u8], i: usize| b.get(i..i + 4).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]));
    let count = u32_at(rest, 0)? as usize;
    let mut at = 4;
    let mut images = Vec::with_capacity(count.min(16));
    for _ in 0..count {
        let (w, h, c) = (u32_at(rest, at)?, u32_at(rest, at + 4)?, u32_at(rest, at + 8)?);
        at += 12;
        let n = (w as usize).checked_mul(h as usize)?.checked_mul(c as usize)?;
        let body = rest.get(at..at.checked_add(n.checked_mul(4)?)?)?;
        let data = body.chunks_exact(4).map(|s| f32::from_le_bytes([s[0], s[1], s[2], s[3]])).collect();
        images.push(Image { width: w, height: h, channels: c, data });
        at += 4 * n;
    }
    (at == rest.len()).then_some(images)
}

fn write_entry(path: &Path, images: &[Image]) -> std::io::Result<()> {
    let mut bytes = MAGIC.to_vec();
    bytes.extend_from_slice(&(images.len() as u32).to_le_bytes());
    for img in images {
        for v in [img.width, img.height, img.channels] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        for v in &img.data {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    write_atomically(path, &bytes)
}

fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    // A name no other process uses, renamed into place: readers see all of the entry or none.
    let nanos =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let tmp = path.with_extension(format!("tmp.{}.{nanos}", std::process::id()));
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_reuse() {
        let dir = tempfile::tempdir().unwrap();
        let cache = Cache::new(Some(dir.path().to_path_buf()));
        let img = Image {
            width: 2,
            height: 1,
            channels: 3,
            data: vec![1.0, -2.5, 3.0, f32::MIN_POSITIVE, 0.0, 7.0],
        };
        let recipe = ("film", 42u64);
        let a = cache.images("c", "x", &recipe, || Ok::<_, ()>(vec![img.clone(), img.clone()])).unwrap();
        let b =
            cache.images("c", "x", &recipe, || -> Result<Vec<Image>, ()> { panic!("not reused") }).unwrap();
        assert!(a.is_some());
        assert_eq!(a, b);
        let ev = cache.events_of("c");
        assert_eq!((ev[0].reused, ev[1].reused), (false, true));
        // Another recipe is another entry.
        let c = cache.images("c", "y", &("film", 43u64), || Ok::<_, ()>(vec![])).unwrap();
        assert_eq!(c, Some(vec![]));
        // A truncated entry is rendered again.
        for e in std::fs::read_dir(dir.path()).unwrap() {
            let p = e.unwrap().path();
            let bytes = std::fs::read(&p).unwrap();
            std::fs::write(&p, &bytes[..bytes.len().saturating_sub(3)]).unwrap();
        }
        let d = cache.images("c", "x", &recipe, || Ok::<_, ()>(vec![img.clone()])).unwrap();
        assert_eq!(d.map(|d| d.len()), Some(1));
        assert!(!cache.events_of("c")[3].reused);
    }

    /// N shares make disjoint parts of the entries, together all of them, each entry once,
    /// and hand no image back; a cache then reads every entry without rendering.
    #[test]
    fn shares_make_disjoint_parts_of_the_entries() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image { width: 1, height: 1, channels: 1, data: vec![0.5] };
        let made = std::sync::atomic::AtomicUsize::new(0);
        let mut owned = Vec::new();
        for k in 1..=3 {
            let share = Cache::share(dir.path().to_path_buf(), k, 3, Pass::Renders);
            for recipe in 0..30u64 {
                let got = share
                    .images("c", "x", &("film", recipe), || {
                        made.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        Ok::<_, ()>(vec![img.clone()])
                    })
                    .unwrap();
                assert!(got.is_none());
            }
            let c = share.share_count();
            assert_eq!((c.owned + c.others, c.rendered), (30, c.owned));
            owned.push(c.owned);
        }
        assert_eq!(made.into_inner(), 30);
        assert!(owned.iter().all(|&n| n > 0), "{owned:?}");
        // Run again, a share makes nothing.
        let again = Cache::share(dir.path().to_path_buf(), 2, 3, Pass::Renders);
        for recipe in 0..30u64 {
            again
                .images("c", "x", &("film", recipe), || -> Result<Vec<Image>, ()> { panic!("made twice") })
                .unwrap();
        }
        assert_eq!(again.share_count().rendered, 0);
        let cache = Cache::new(Some(dir.path().to_path_buf()));
        for recipe in 0..30u64 {
            let got = cache
                .images("c", "x", &("film", recipe), || -> Result<Vec<Image>, ()> { panic!("not there") });
            assert_eq!(got.unwrap(), Some(vec![img.clone()]));
        }
    }

    #[test]
    fn fnv_reference_values() {
        // FNV-1a 128 of "" and "a" (the published test vectors).
        assert_eq!(fnv128(b""), 0x6c62272e07bb014262b821756295c58d);
        assert_eq!(fnv128(b"a"), 0xd228cb696f1a8caf78912b704e4a8964);
    }
}
