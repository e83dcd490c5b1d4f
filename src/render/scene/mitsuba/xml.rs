//! Mitsuba 3's scene XML as a tree of plain elements, as Mitsuba's own parser
//! (`src/core/xml.cpp`) reads it before instantiating plugins: every `include` spliced in where
//! it stands (relative to the including file, then to the `path` folders), every `$name`
//! replaced by its value (`default` elements, in document order, never overriding a value
//! given by the caller), and every `ref` replaced by the element it names. Each element keeps
//! the file and line it came from, so an error can point at it.
//!
//! Read with roxmltree (a small, strict, read-only XML parser that reports positions);
//! unreadable XML, a cycle of includes or refs, an undefined parameter or id, and a scene whose
//! version is not 2.x or 3.x are errors here.

use super::super::super::Error;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// One XML element after includes, parameters and refs are resolved.
#[derive(Clone, Debug)]
pub struct Elem {
    pub tag: String,
    pub attrs: Vec<(String, String)>,
    pub children: Vec<Elem>,
    pub file: Rc<PathBuf>,
    pub line: u32,
}

impl Elem {
    pub fn attr(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// The plugin type (`type="…"`), empty when absent.
    pub fn plugin(&self) -> &str {
        self.attr("type").unwrap_or("")
    }

    /// "<shape type=\"obj\"> at FILE:LINE", for messages.
    pub fn describe(&self) -> String {
        match self.attr("type") {
            Some(t) => format!("<{} type=\"{t}\"> at {}:{}", self.tag, self.file.display(), self.line),
            None => match self.attr("name") {
                Some(n) => format!("<{} name=\"{n}\"> at {}:{}", self.tag, self.file.display(), self.line),
                None => format!("<{}> at {}:{}", self.tag, self.file.display(), self.line),
            },
        }
    }

    /// A bad-input error about this element.
    pub fn error(&self, message: impl std::fmt::Display) -> Error {
        Error::Mitsuba { at: self.describe(), message: message.to_string() }
    }

    /// An error for input lumen does not support, saying what it supports instead.
    pub fn unsupported(&self, message: impl std::fmt::Display) -> Error {
        Error::MitsubaUnsupported { at: self.describe(), message: message.to_string() }
    }

    /// The folder relative paths in this element resolve against first.
    pub fn dir(&self) -> PathBuf {
        self.file.parent().map(Path::to_path_buf).unwrap_or_default()
    }
}

/// Reads a scene file: the `scene` element with everything resolved, and the `path` folders
/// it named (for its file names). `params` are values given by the caller (`-D name=value`),
/// which `default` elements do not override.
pub fn load(path: &Path, params: &[(String, String)]) -> Result<(Elem, Vec<PathBuf>), Error> {
    let mut reader =
        Reader { params: params.iter().cloned().collect(), search: Vec::new(), stack: Vec::new() };
    let mut root = reader.file(path)?;
    let mut ids = BTreeMap::new();
    collect_ids(&root, &mut ids)?;
    let mut resolving = Vec::new();
    let mut budget = MAX_ELEMENTS;
    resolve_refs(&mut root, &ids, &mut resolving, &mut budget)?;
    Ok((root, reader.search))
}

/// Most elements in one file (each becomes a node of the tree): far above any scene written
/// by hand or exported, and a limit on what a hostile file can make lumen allocate.
const MAX_ELEMENTS: usize = 1 << 20;

struct Reader {
    params: HashMap<String, String>,
    search: Vec<PathBuf>,
    /// The files being read, outermost first (an include cycle shows here).
    stack: Vec<PathBuf>,
}

impl Reader {
    fn file(&mut self, path: &Path) -> Result<Elem, Error> {
        let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        if self.stack.contains(&canonical) {
            let chain: Vec<String> =
                self.stack.iter().chain([&canonical]).map(|p| p.display().to_string()).collect();
            return Err(Error::Parse {
                path: path.to_path_buf(),
                message: format!("includes itself: {}", chain.join(" → ")),
            });
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::Io { path: path.to_path_buf(), message: e.to_string() })?;
        let options = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: MAX_ELEMENTS as u32,
            ..Default::default()
        };
        let doc = roxmltree::Document::parse_with_options(&text, options).map_err(|e| Error::Parse {
            path: path.to_path_buf(),
            message: format!("not well-formed XML: {e}"),
        })?;
        let root = doc.root_element();
        let file = Rc::new(path.to_path_buf());
        let line = |n: roxmltree::Node| doc.text_pos_at(n.range().start).row;
        if root.tag_name().name() != "scene" {
            return Err(Error::Mitsuba {
                at: format!("<{}> at {}:{}", root.tag_name().name(), path.display(), line(root)),
                message: "the root element must be <scene version=\"3.0.0\">".into(),
            });
        }
        match root.attribute("version") {
            Some(v) if v.starts_with("3.") || v.starts_with("2.") => {}
            v => {
                return Err(Error::MitsubaUnsupported {
                    at: format!("<scene> at {}:{}", path.display(), line(root)),
                    message: format!(
                        "version {}: lumen reads Mitsuba 3 scenes (version 2.x or 3.x); upgrade older ones with Mitsuba's own tools",
                        v.map_or("(none)".to_string(), |v| format!("\"{v}\""))
                    ),
                })
            }
        }
        self.stack.push(canonical);
        let children = self.children(root, &file, &line)?;
        self.stack.pop();
        Ok(Elem { tag: "scene".into(), attrs: Vec::new(), children, file, line: line(root) })
    }

    fn children(
        &mut self,
        node: roxmltree::Node,
        file: &Rc<PathBuf>,
        line: &dyn Fn(roxmltree::Node) -> u32,
    ) -> Result<Vec<Elem>, Error> {
        let mut out = Vec::new();
        for c in node.children().filter(|c| c.is_element()) {
            let mut e = Elem {
                tag: c.tag_name().name().to_string(),
                attrs: Vec::new(),
                children: Vec::new(),
                file: file.clone(),
                line: line(c),
            };
            for a in c.attributes() {
                let v = self.substitute(a.value(), &e)?;
                e.attrs.push((a.name().to_string(), v));
            }
            let top = node.tag_name().name() == "scene" && node.parent().is_some_and(|p| p.is_root());
            match e.tag.as_str() {
                "default" => {
                    if !top {
                        return Err(e.error("a <default> belongs directly in <scene>"));
                    }
                    let (Some(name), Some(value)) = (e.attr("name"), e.attr("value")) else {
                        return Err(e.error("needs `name` and `value`"));
                    };
                    // The raw value: a default may not itself name a parameter.
                    self.params.entry(name.to_string()).or_insert_with(|| value.to_string());
                }
                "path" => {
                    let Some(v) = e.attr("value") else { return Err(e.error("needs `value`")) };
                    self.search.push(e.dir().join(v));
                }
                "include" => {
                    let Some(f) = e.attr("filename") else { return Err(e.error("needs `filename`")) };
                    let found = std::iter::once(e.dir())
                        .chain(self.search.iter().cloned())
                        .map(|d| d.join(f))
                        .find(|p| p.is_file())
                        .ok_or_else(|| {
                            e.error(format!("cannot find \"{f}\" beside the file or in a <path>"))
                        })?;
                    let included = self.file(&found)?;
                    out.extend(included.children);
                }
                _ => {
                    e.children = self.children(c, file, line)?;
                    out.push(e);
                }
            }
        }
        Ok(out)
    }

    /// `$name` replaced by its parameter's value; `$` followed by no name is kept.
    fn substitute(&self, v: &str, at: &Elem) -> Result<String, Error> {
        if !v.contains('$') {
            return Ok(v.to_string());
        }
        let mut out = String::new();
        let mut rest = v;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let n = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
            if n == 0 {
                out.push('$');
            } else {
                let name = &after[..n];
                let value = self.params.get(name).ok_or_else(|| {
                    at.error(format!(
                        "uses ${name}, which no <default name=\"{name}\"> or -D {name}=… defines"
                    ))
                })?;
                out.push_str(value);
            }
            rest = &after[n..];
        }
        out.push_str(rest);
        Ok(out)
    }
}

fn collect_ids(e: &Elem, ids: &mut BTreeMap<String, Elem>) -> Result<(), Error> {
    for c in &e.children {
        if c.tag != "ref" {
            if let Some(id) = c.attr("id") {
                if let Some(first) = ids.get(id) {
                    return Err(c.error(format!("id \"{id}\" is already used by {}", first.describe())));
                }
                ids.insert(id.to_string(), c.clone());
            }
        }
        collect_ids(c, ids)?;
    }
    Ok(())
}

fn size(e: &Elem) -> usize {
    1 + e.children.iter().map(size).sum::<usize>()
}

/// Replaces every `ref` below `e` by a copy of what it names. `budget` bounds the elements the
/// copies add: refs nested in what they name multiply (a few lines can ask for 2⁴⁰ copies).
fn resolve_refs(
    e: &mut Elem,
    ids: &BTreeMap<String, Elem>,
    resolving: &mut Vec<String>,
    budget: &mut usize,
) -> Result<(), Error> {
    for c in &mut e.children {
        if c.tag == "ref" {
            let Some(id) = c.attr("id").map(str::to_string) else { return Err(c.error("needs `id`")) };
            let Some(target) = ids.get(&id) else {
                return Err(c.error(format!("names id \"{id}\", which no element has")));
            };
            if resolving.contains(&id) {
                return Err(c.error(format!("refs form a cycle: {} → {id}", resolving.join(" → "))));
            }
            let name = c.attr("name").map(str::to_string);
            *budget = budget
                .checked_sub(size(target))
                .ok_or_else(|| c.error(format!("refs expand the scene past {MAX_ELEMENTS} elements")))?;
            let mut t = target.clone();
            if let Some(n) = name {
                t.attrs.retain(|(k, _)| k != "name");
                t.attrs.push(("name".into(), n));
            }
            resolving.push(id);
            resolve_refs(&mut t, ids, resolving, budget)?;
            resolving.pop();
            *c = t;
        } else {
            if let Some(id) = c.attr("id") {
                resolving.push(id.to_string());
            }
            resolve_refs(c, ids, resolving, budget)?;
            if c.attr("id").is_some() {
                resolving.pop();
            }
        }
    }
    Ok(())
}
