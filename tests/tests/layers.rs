//! The shape of the house, checked: no import cycle between the modules of `core-nostd` and
//! `host-sim`, the core's layers import only downwards (the order `core-nostd/src/lib.rs`
//! states), the protocol imports nothing above the episode layer, and no source file is
//! longer than [`MAX_LINES`] lines before its tests.
//!
//! The graph is read from the source text, as `shared/hooks/modgraph.py` reads it: a module
//! is a file (`a/b.rs` or `a/b/mod.rs` is `a::b`), and `a` imports `b` when `a`'s code before
//! its first `#[cfg(test)]` names a path `crate::b…` (in a `use` group or inline) or
//! `super::…` that resolves to `b`. A module never imports its own ancestors or descendants
//! for layering purposes (a folder's `mod.rs` re-exports its children). This is a test and
//! not a lint so that `cargo test` — and so CI — fails on the first cycle someone adds.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// No non-test source file above this many lines (issue 19).
const MAX_LINES: usize = 800;

/// The core's layers, lowest first: a module of layer `i` imports only from layers `< i`
/// (and from its own module). The same table stands in `core-nostd/src/lib.rs`.
const CORE_LAYERS: &[&[&str]] = &[
    &["limits", "checksum"],
    &["world"],
    &["episode"],
    &["localization"],
    &["registration"],
    &["stop"],
    &["policy"],
    &["pipeline"],
    &["protocol"],
    &["device"],
];

/// The host's modules, lowest first, as `host-sim/src/lib.rs` lists them: each imports only
/// from modules before it (one module a layer).
const HOST_LAYERS: &[&str] = &[
    "world",
    "episode",
    "answer",
    "baselines",
    "plot",
    "learn",
    "eval",
    "bench",
    "calibrate",
    "inspect",
    "link",
    "geocom",
    "cli",
];

/// What the protocol may import: the wire sits below the algorithms, as smoltcp's `wire`
/// sits below `iface` and `socket`.
const PROTOCOL_MAY_IMPORT: &[&str] = &["limits", "checksum", "world", "episode"];

/// The one module above the episode layer the protocol may name: the int8 blob parser's
/// error enum, which `PolicyError::Invalid` carries on the wire (a mirror enum would be a
/// second list to keep in step by hand). It must stay a leaf: it imports nothing.
const PROTOCOL_LEAF_EXCEPTION: &[&str] = &["policy", "int8", "error"];

type Module = Vec<String>;

struct Graph {
    files: BTreeMap<Module, PathBuf>,
    edges: BTreeMap<Module, BTreeSet<Module>>,
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// The part of a file the checks read: everything before its first `#[cfg(test)]`.
fn non_test(text: &str) -> &str {
    text.find("#[cfg(test)]").map_or(text, |i| &text[..i])
}

fn strip_comments(text: &str) -> String {
    text.lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn collect(dir: &Path, src: &Path, out: &mut BTreeMap<Module, PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let p = e.path();
        if p.is_dir() {
            collect(&p, src, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            let rel = p.strip_prefix(src).unwrap().with_extension("");
            let mut m: Module = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if matches!(m.last().map(String::as_str), Some("mod" | "lib" | "main")) {
                m.pop();
            }
            out.insert(m, p);
        }
    }
}

/// The longest prefix of `path` that is a module file.
fn resolve(path: &[String], files: &BTreeMap<Module, PathBuf>) -> Option<Module> {
    (1..=path.len())
        .rev()
        .map(|n| path[..n].to_vec())
        .find(|m| files.contains_key(m))
}

/// Every path a `use` tree names, with `{a, b::{c, d}}` groups expanded.
fn expand_use(tree: &str, prefix: &[String], out: &mut Vec<Vec<String>>) {
    let tree = tree.trim();
    if let Some(open) = tree.find('{') {
        let head: Vec<String> = tree[..open]
            .split("::")
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect();
        let mut base = prefix.to_vec();
        base.extend(head);
        let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
        let (mut depth, mut start) = (0, 0);
        for (i, ch) in inner.char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    expand_use(&inner[start..i], &base, out);
                    start = i + 1;
                }
                _ => {}
            }
        }
        expand_use(&inner[start..], &base, out);
    } else {
        let name = tree.split(" as ").next().unwrap_or("").trim();
        if name.is_empty() {
            return;
        }
        let mut p = prefix.to_vec();
        p.extend(
            name.split("::")
                .map(str::trim)
                .filter(|s| !s.is_empty() && *s != "self")
                .map(String::from),
        );
        out.push(p);
    }
}

/// The module paths (relative to the crate root) that `code`, in module `m`, refers to.
fn references(m: &Module, code: &str) -> Vec<Vec<String>> {
    let mut paths = Vec::new();
    // `use crate::…;` and `use super::…;` statements, groups included.
    let mut rest = code;
    while let Some(i) = rest.find("use ") {
        let before = rest[..i].chars().last();
        rest = &rest[i + 4..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let Some(end) = rest.find(';') else { break };
        let stmt: String = rest[..end].split_whitespace().collect::<Vec<_>>().join(" ");
        if let Some(t) = stmt.strip_prefix("crate::") {
            expand_use(t, &[], &mut paths);
        } else if stmt.starts_with("super::") {
            let mut base = m.clone();
            let mut t = stmt.as_str();
            // A file `a/b.rs` is module a::b; `super` is a.
            while let Some(r) = t.strip_prefix("super::") {
                base.pop();
                t = r;
            }
            expand_use(t, &base, &mut paths);
        }
    }
    // Inline `crate::a::b` paths.
    let bytes = code.as_bytes();
    let mut at = 0;
    while let Some(i) = code[at..].find("crate::") {
        let s = at + i;
        at = s + 7;
        if s > 0 && (bytes[s - 1].is_ascii_alphanumeric() || bytes[s - 1] == b'_') {
            continue;
        }
        let tail: String = code[at..]
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect();
        paths.push(
            tail.split("::")
                .filter(|s| !s.is_empty())
                .map(String::from)
                .collect(),
        );
    }
    paths
}

fn graph(src: &Path) -> Graph {
    let mut files = BTreeMap::new();
    collect(src, src, &mut files);
    let mut edges = BTreeMap::new();
    for (m, p) in &files {
        let text = std::fs::read_to_string(p).unwrap();
        let code = strip_comments(non_test(&text));
        let mut to = BTreeSet::new();
        for path in references(m, &code) {
            if let Some(t) = resolve(&path, &files) {
                let related = t.starts_with(m) || m.starts_with(&t);
                if !related {
                    to.insert(t);
                }
            }
        }
        edges.insert(m.clone(), to);
    }
    Graph { files, edges }
}

/// Strongly connected components with more than one module (Tarjan).
fn cycles(edges: &BTreeMap<Module, BTreeSet<Module>>) -> Vec<Vec<Module>> {
    struct T<'a> {
        edges: &'a BTreeMap<Module, BTreeSet<Module>>,
        index: BTreeMap<&'a Module, usize>,
        low: BTreeMap<&'a Module, usize>,
        stack: Vec<&'a Module>,
        on: BTreeSet<&'a Module>,
        out: Vec<Vec<Module>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a Module) {
        let n = t.index.len();
        t.index.insert(v, n);
        t.low.insert(v, n);
        t.stack.push(v);
        t.on.insert(v);
        for w in &t.edges[v] {
            if !t.index.contains_key(w) {
                visit(t, w);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on.remove(w);
                comp.push(w.clone());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.push(comp);
            }
        }
    }
    let mut t = T {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !t.index.contains_key(v) {
            visit(&mut t, v);
        }
    }
    t.out
}

fn show(m: &Module) -> String {
    if m.is_empty() {
        "lib".into()
    } else {
        m.join("/")
    }
}

fn assert_acyclic(crate_src: &str) {
    let g = graph(&workspace().join(crate_src));
    let found = cycles(&g.edges);
    let text: Vec<String> = found
        .iter()
        .map(|c| c.iter().map(show).collect::<Vec<_>>().join(" <-> "))
        .collect();
    assert!(
        found.is_empty(),
        "import cycles in {crate_src}:\n  {}",
        text.join("\n  ")
    );
}

#[test]
fn core_has_no_import_cycle() {
    assert_acyclic("core-nostd/src");
}

#[test]
fn host_has_no_import_cycle() {
    assert_acyclic("host-sim/src");
}

fn layer_of(m: &Module) -> Option<usize> {
    let top = m.first()?;
    CORE_LAYERS.iter().position(|l| l.contains(&top.as_str()))
}

#[test]
fn core_layers_import_only_downwards() {
    let g = graph(&workspace().join("core-nostd/src"));
    let mut wrong = Vec::new();
    for (m, to) in &g.edges {
        let Some(lm) = layer_of(m) else {
            assert!(
                m.is_empty(),
                "core module {} is in no layer of CORE_LAYERS (add it to lib.rs's table and here)",
                show(m)
            );
            continue;
        };
        for t in to {
            // The crate root (`lib.rs`) is no layer: importing it counts as upward. Two
            // modules of one layer may not import each other (layer 0 holds leaves only).
            let lt = layer_of(t).unwrap_or(usize::MAX);
            if lt > lm || (lt == lm && m[0] != t[0]) {
                wrong.push(format!(
                    "{} (layer {lm}) imports {} (layer {lt})",
                    show(m),
                    show(t)
                ));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "upward imports:\n  {}",
        wrong.join("\n  ")
    );
}

#[test]
fn host_modules_import_only_from_earlier_ones() {
    let g = graph(&workspace().join("host-sim/src"));
    let layer = |m: &Module| {
        m.first()
            .and_then(|t| HOST_LAYERS.iter().position(|l| l == t))
    };
    let mut wrong = Vec::new();
    for (m, to) in &g.edges {
        let Some(lm) = layer(m) else {
            assert!(
                m.is_empty(),
                "host module {} is not in HOST_LAYERS (nor lib.rs's table)",
                show(m)
            );
            continue;
        };
        for t in to {
            if layer(t).is_none_or(|lt| lt > lm) {
                wrong.push(format!("{} imports {}", show(m), show(t)));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "host imports against the lib.rs order:\n  {}",
        wrong.join("\n  ")
    );
    let lib = std::fs::read_to_string(workspace().join("host-sim/src/lib.rs")).unwrap();
    let listed: Vec<&str> = lib
        .lines()
        .filter_map(|l| l.strip_prefix("//! | [`"))
        .map(|l| l.split('`').next().unwrap_or(""))
        .collect();
    assert_eq!(
        listed, HOST_LAYERS,
        "host-sim/src/lib.rs's table and HOST_LAYERS differ"
    );
}

#[test]
fn protocol_imports_nothing_above_the_episode_layer() {
    let g = graph(&workspace().join("core-nostd/src"));
    let mut wrong = Vec::new();
    for (m, to) in &g.edges {
        if m.first().map(String::as_str) != Some("protocol") {
            continue;
        }
        for t in to {
            let top = t.first().map(String::as_str).unwrap_or("lib");
            let leaf = t
                .iter()
                .map(String::as_str)
                .eq(PROTOCOL_LEAF_EXCEPTION.iter().copied());
            if top != "protocol" && !PROTOCOL_MAY_IMPORT.contains(&top) && !leaf {
                wrong.push(format!("{} imports {}", show(m), show(t)));
            }
        }
    }
    let leaf: Module = PROTOCOL_LEAF_EXCEPTION
        .iter()
        .map(|s| s.to_string())
        .collect();
    if let Some(to) = g.edges.get(&leaf) {
        assert!(
            to.is_empty(),
            "{} must import nothing, imports {:?}",
            show(&leaf),
            to
        );
    }
    assert!(
        g.files
            .keys()
            .any(|m| m.first().map(String::as_str) == Some("protocol")),
        "core-nostd/src has no protocol module"
    );
    assert!(
        wrong.is_empty(),
        "the protocol reaches up:\n  {}",
        wrong.join("\n  ")
    );
}

#[test]
fn lib_rs_states_the_same_layers() {
    // `//! | 0 | [`limits`], [`checksum`] | …` rows of lib.rs's "Layers" table.
    let lib = std::fs::read_to_string(workspace().join("core-nostd/src/lib.rs")).unwrap();
    let table: Vec<Vec<String>> = lib
        .lines()
        .filter_map(|l| l.strip_prefix("//! | "))
        .filter(|l| l.chars().next().is_some_and(|c| c.is_ascii_digit()))
        .map(|l| {
            let modules = l.split('|').nth(1).unwrap_or("");
            modules
                .split(',')
                .map(|m| {
                    m.trim()
                        .trim_start_matches("[`")
                        .trim_end_matches("`]")
                        .to_string()
                })
                .collect()
        })
        .collect();
    let expected: Vec<Vec<String>> = CORE_LAYERS
        .iter()
        .map(|l| l.iter().map(|m| m.to_string()).collect())
        .collect();
    assert_eq!(
        table, expected,
        "core-nostd/src/lib.rs's layer table and CORE_LAYERS differ"
    );
    let declared: BTreeSet<&str> = lib
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|l| l.trim_end_matches(';').trim())
        .collect();
    let layered: BTreeSet<&str> = CORE_LAYERS.iter().flat_map(|l| l.iter().copied()).collect();
    assert_eq!(declared, layered, "every core module has a layer");
}

#[test]
fn no_source_file_is_longer_than_the_limit() {
    let mut long = Vec::new();
    for src in ["core-nostd/src", "host-sim/src"] {
        let mut files = BTreeMap::new();
        let root = workspace().join(src);
        collect(&root, &root, &mut files);
        for p in files.values() {
            let text = std::fs::read_to_string(p).unwrap();
            let n = non_test(&text).lines().count();
            if n > MAX_LINES {
                long.push(format!("{} ({n} lines)", p.display()));
            }
        }
    }
    assert!(
        long.is_empty(),
        "files over {MAX_LINES} non-test lines:\n  {}",
        long.join("\n  ")
    );
}

// The checker itself, on small synthetic crates: a check that cannot fail is no check.

fn synthetic(files: &[(&str, &str)]) -> Graph {
    let dir = std::env::temp_dir().join(format!(
        "activesense-layers-{}-{}",
        std::process::id(),
        files.len() * 31 + files.iter().map(|f| f.1.len()).sum::<usize>()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    for (name, text) in files {
        let p = dir.join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    let g = graph(&dir);
    let _ = std::fs::remove_dir_all(&dir);
    g
}

#[test]
fn the_checker_finds_a_cycle_through_a_use_group_and_an_inline_path() {
    let g = synthetic(&[
        ("lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
        ("a.rs", "use crate::{b::Thing, c::inner::Q};\n"),
        ("b.rs", "fn f() -> u8 { crate::c::inner::X }\n"),
        ("c/mod.rs", "pub mod inner;\n"),
        ("c/inner.rs", "use super::super::a::Y;\n"),
    ]);
    let found = cycles(&g.edges);
    assert_eq!(found.len(), 1, "{:?}", g.edges);
    let names: Vec<String> = found[0].iter().map(show).collect();
    assert_eq!(names, ["a", "b", "c/inner"]);
}

#[test]
fn the_checker_ignores_tests_comments_and_parents() {
    let g = synthetic(&[
        ("lib.rs", "pub mod a;\npub mod b;\n"),
        (
            "a/mod.rs",
            "pub mod x;\npub use x::X; // crate::b is only named here\n",
        ),
        (
            "a/x.rs",
            "use crate::a::Z;\n#[cfg(test)]\nmod tests { use crate::b::B; }\n",
        ),
        ("b.rs", "use crate::a::x::X;\n"),
    ]);
    assert!(cycles(&g.edges).is_empty(), "{:?}", g.edges);
    assert!(g.edges[&vec!["b".to_string()]].contains(&vec!["a".to_string(), "x".to_string()]));
}

#[test]
fn the_docs_name_only_source_paths_that_exist() {
    // A moved file leaves stale paths behind in prose; every `core-nostd/…`, `host-sim/…`,
    // `firmware/…`, `xtask/…` and `tests/…` path the README and docs/ name must exist.
    let root = workspace();
    let mut docs = vec![root.join("README.md")];
    for e in std::fs::read_dir(root.join("docs")).unwrap().flatten() {
        if e.path().extension().is_some_and(|x| x == "md") {
            docs.push(e.path());
        }
    }
    let mut missing = Vec::new();
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap();
        for prefix in ["core-nostd/", "host-sim/", "firmware/", "xtask/", "tests/"] {
            let mut at = 0;
            while let Some(i) = text[at..].find(prefix) {
                let s = at + i;
                at = s + prefix.len();
                let before = text[..s].chars().last();
                if before.is_some_and(|c| c.is_alphanumeric() || c == '/' || c == '-' || c == '_') {
                    continue;
                }
                let path: String = text[s..]
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || "_./-{},".contains(*c))
                    .collect();
                let path = path.trim_end_matches(['.', ',']);
                if path.contains('{') || path.ends_with('/') && path.len() == prefix.len() {
                    continue;
                }
                if !root.join(path).exists() {
                    missing.push(format!(
                        "{}: {path}",
                        doc.strip_prefix(&root).unwrap().display()
                    ));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "the docs name paths that do not exist:\n  {}",
        missing.join("\n  ")
    );
}
