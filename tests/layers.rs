//! Layers import one way. Every module of the workspace is a node; a module that names a
//! path into another (`crate::a::b`, `super::x`, outside comments and test modules) is an
//! edge. A group of modules that reach each other is an import circle: none may appear.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Circles not yet taken apart, each as its sorted modules (none now: the last, refuse's
/// config/spec/pipelines, went when the pipelines took a `PipelineBase` instead of the
/// spec).
const STILL_CIRCULAR: &[&[&str]] = &[];

type Module = (String, Vec<String>);

/// Every module of every crate (`src/` and `crates/*/src`) with its file.
fn modules(root: &Path) -> BTreeMap<Module, PathBuf> {
    let mut bases = vec![("".to_owned(), root.join("src"))];
    for c in std::fs::read_dir(root.join("crates")).unwrap() {
        let c = c.unwrap().path();
        let name = format!("crates/{}", c.file_name().unwrap().to_string_lossy());
        bases.push((name, c.join("src")));
    }
    let mut out = BTreeMap::new();
    for (crate_name, src) in bases {
        let mut stack = vec![src.clone()];
        while let Some(dir) = stack.pop() {
            for e in std::fs::read_dir(&dir).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if p.extension().is_some_and(|x| x == "rs") {
                    let rel = p.strip_prefix(&src).unwrap().with_extension("");
                    let mut parts: Vec<String> = rel
                        .components()
                        .map(|c| c.as_os_str().to_string_lossy().into_owned())
                        .collect();
                    if matches!(
                        parts.last().map(String::as_str),
                        Some("mod" | "lib" | "main")
                    ) {
                        parts.pop();
                    }
                    out.insert((crate_name.clone(), parts), p);
                }
            }
        }
    }
    out
}

/// The code of a file without comments and without its test module.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let text = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The paths `crate::…` and `super::…` a file names, as module segments from its crate root.
fn named_paths(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for (start, kind) in [("crate::", "crate"), ("super::", "super")] {
        let mut rest = code;
        while let Some(i) = rest.find(start) {
            let before = rest[..i].chars().last();
            let after = &rest[i + start.len()..];
            rest = after;
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let mut segs: Vec<String> = after
                .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                .next()
                .unwrap_or("")
                .split("::")
                .filter(|s| !s.is_empty())
                .map(str::to_owned)
                .collect();
            let mut base: Vec<String> = match kind {
                "crate" => Vec::new(),
                _ => module[..module.len().saturating_sub(1)].to_vec(),
            };
            while segs.first().is_some_and(|s| s == "super") {
                segs.remove(0);
                base.pop();
            }
            base.extend(segs);
            out.push(base);
        }
    }
    out
}

/// Strongly connected components of more than one module (Tarjan's algorithm).
fn circles(edges: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    struct State<'a> {
        edges: &'a BTreeMap<Module, BTreeSet<Module>>,
        index: BTreeMap<&'a Module, usize>,
        low: BTreeMap<&'a Module, usize>,
        stack: Vec<&'a Module>,
        on: BTreeSet<&'a Module>,
        out: Vec<Vec<Module>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a Module) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on.insert(v);
        for w in &s.edges[v] {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut group = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on.remove(w);
                group.push(w.clone());
                if w == v {
                    break;
                }
            }
            if group.len() > 1 {
                group.sort();
                s.out.push(group);
            }
        }
    }
    let mut s = State {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    s.out
}

#[test]
fn no_import_circle_anywhere_in_the_tree() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let modules = modules(root);
    let mut edges: BTreeMap<Module, BTreeSet<Module>> = BTreeMap::new();
    for ((krate, module), path) in &modules {
        let from = (krate.clone(), module.clone());
        let targets = edges.entry(from.clone()).or_default();
        for named in named_paths(&code(path), module) {
            // The longest module the path names.
            let target = (0..=named.len())
                .rev()
                .map(|n| (krate.clone(), named[..n].to_vec()))
                .find(|m| modules.contains_key(m));
            if let Some(t) = target.filter(|t| *t != from) {
                targets.insert(t);
            }
        }
    }
    let name = |(k, m): &Module| {
        let krate = if k.is_empty() { "src" } else { k.as_str() };
        format!("{krate}::{}", m.join("::"))
    };
    let found: Vec<Vec<String>> = circles(&edges)
        .iter()
        .map(|g| g.iter().map(name).collect())
        .collect();
    let known: Vec<Vec<String>> = STILL_CIRCULAR
        .iter()
        .map(|g| g.iter().map(|s| s.to_string()).collect())
        .collect();
    let new: Vec<&Vec<String>> = found.iter().filter(|g| !known.contains(g)).collect();
    assert!(new.is_empty(), "import circles: {new:#?}");
    // A circle taken apart comes off the list.
    let gone: Vec<&Vec<String>> = known.iter().filter(|g| !found.contains(g)).collect();
    assert!(
        gone.is_empty(),
        "no longer circular, take off STILL_CIRCULAR: {gone:#?}"
    );
}

/// The crates' railfuse dependencies as `cargo metadata` gives them, one line per crate.
fn crate_graph(root: &Path) -> String {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut lines = Vec::new();
    for p in meta["packages"].as_array().unwrap() {
        let mut deps: Vec<&str> = p["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"].is_null())
            .filter_map(|d| d["name"].as_str())
            .filter(|n| n.starts_with("railfuse"))
            .collect();
        deps.sort();
        let deps = match deps.is_empty() {
            true => "(none)".to_owned(),
            false => deps.join(", "),
        };
        lines.push(format!("- `{}` → {deps}", p["name"].as_str().unwrap()));
    }
    lines.sort();
    lines.join("\n")
}

#[test]
fn docs_architecture_shows_the_crate_graph_cargo_gives() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("docs/architecture.md");
    let text = std::fs::read_to_string(&path).unwrap();
    let (start, end) = ("<!-- crate graph -->\n", "<!-- end crate graph -->");
    let (head, rest) = text
        .split_once(start)
        .expect("the crate graph's start marker");
    let (_, tail) = rest.split_once(end).expect("the crate graph's end marker");
    let want = format!("{head}{start}{}\n{end}{tail}", crate_graph(root));
    if std::env::var_os("RAILFUSE_BLESS").is_some() {
        std::fs::write(&path, &want).unwrap();
        return;
    }
    assert_eq!(
        text, want,
        "docs/architecture.md: regenerate with RAILFUSE_BLESS=1 cargo test --test layers"
    );
}
