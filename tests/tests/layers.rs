//! The shape of the house, checked: no import cycle between the modules of the core or of
//! any host crate, the core's layers import only downwards (the order `core-nostd/src/lib.rs`
//! states), each host crate's top-level modules import only from the ones before them (the
//! order of [`HOST_CRATES`]), the protocol imports nothing above the episode layer, and no
//! production file is longer than [`MAX_LINES`] lines.
//!
//! Everything is read from the source text, as `shared/hooks/modgraph.py` reads it:
//!
//! - **A module is a file**: `a/b.rs` or `a/b/mod.rs` is `a::b`.
//! - **Production code** is the text outside every `#[cfg(test)]` item, wherever the item
//!   stands (a `mod tests { … }` block, a test-only `fn` or `impl` among production code,
//!   a `mod x;` declaration), in every file that is not test-only. A **test-only file** is a
//!   `tests.rs`, a `*_tests.rs`, or one declared `#[cfg(test)] mod x;`. A file's length is
//!   its non-blank production lines.
//! - **Imports**: `a` imports `b` when `a`'s production code, comments removed, names a path
//!   that resolves to `b`: `crate::…` or `super::…` (any number of `super`s), in a `use`
//!   statement (groups expanded) or inline in an expression or a type. A path resolves to
//!   the longest prefix of it that is a module file. A module never imports its own
//!   ancestors or descendants for layering purposes (a folder's `mod.rs` re-exports its
//!   children).
//! - **Cycles** are looked for over every file, test-only ones included; the layering
//!   checks read production modules only.
//!
//! A test and not a lint, so that `cargo test` (and so CI) fails on the first cycle, the
//! first upward import and the first file past the limit someone adds.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// No production file above this many non-blank lines.
const MAX_LINES: usize = 700;

/// The core's source.
const CORE_SRC: &str = "core-nostd/src";

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

/// The host crates: each one's source folder and its top-level modules, lowest first. A
/// module imports only from modules before it (one module a layer), and the crate root
/// (`lib.rs`, else `main.rs`) lists them in the same order in its module table (rows
/// `//! | [`name`] | …`). A folder listed here that does not exist fails the checks.
const HOST_CRATES: &[(&str, &[&str])] = &[
    ("instrument/src", INSTRUMENT_LAYERS),
    ("lab/src", LAB_LAYERS),
    ("cli/src", CLI_LAYERS),
];

/// The instrument crate's modules, lowest first, as `instrument/src/lib.rs` lists them.
const INSTRUMENT_LAYERS: &[&str] = &[
    "world",
    "episode",
    "answer",
    "baselines",
    "plot",
    "learn",
    "agents",
    "link",
    "geocom",
];

/// The lab crate's modules, lowest first, as `lab/src/lib.rs` lists them.
const LAB_LAYERS: &[&str] = &[
    "baselines",
    "coverage",
    "plot",
    "learn",
    "eval",
    "bench",
    "calibrate",
    "inspect",
];

/// The binary crate's one module (the commands), as `cli/src/lib.rs` lists it.
const CLI_LAYERS: &[&str] = &["commands"];

/// What the protocol may import: the wire sits below the algorithms, as smoltcp's `wire`
/// sits below `iface` and `socket`.
const PROTOCOL_MAY_IMPORT: &[&str] = &["limits", "checksum", "world", "episode"];

/// The one module above the episode layer the protocol may name: the int8 blob parser's
/// error enum, which `PolicyError::Invalid` carries on the wire (a mirror enum would be a
/// second list to keep in step by hand). It must stay a leaf: it imports nothing.
const PROTOCOL_LEAF_EXCEPTION: &[&str] = &["policy", "int8", "error"];

type Module = Vec<String>;

/// The module files of one crate and the imports between them.
struct Graph {
    files: BTreeMap<Module, PathBuf>,
    /// Files that are tests as a whole.
    tests: BTreeSet<Module>,
    edges: BTreeMap<Module, BTreeSet<Module>>,
}

impl Graph {
    /// The production modules: every module but the test-only files.
    fn production(&self) -> impl Iterator<Item = (&Module, &BTreeSet<Module>)> {
        self.edges.iter().filter(|(m, _)| !self.tests.contains(*m))
    }
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// The source folder `src` (relative to the workspace); a folder that is not there fails
/// with a message saying so, rather than passing over nothing.
fn crate_src(src: &str) -> PathBuf {
    let dir = workspace().join(src);
    assert!(
        dir.is_dir(),
        "{src} does not exist: the crate moved or was split; update CORE_SRC / HOST_CRATES in \
         tests/tests/layers.rs"
    );
    dir
}

/// The production text: every `#[cfg(test)]` item cut out wherever it stands. An item is
/// the attribute up to the first `;` when that comes before the first `{` (a `mod x;`
/// declaration), else up to the `}` that closes that `{`.
fn strip_tests(text: &str) -> String {
    const ATTR: &str = "#[cfg(test)]";
    let mut out = String::new();
    let mut i = 0;
    while let Some(j) = text[i..].find(ATTR).map(|j| i + j) {
        out.push_str(&text[i..j]);
        let k = j + ATTR.len();
        let semi = text[k..].find(';').map(|x| k + x);
        let brace = text[k..].find('{').map(|x| k + x);
        match (semi, brace) {
            (Some(s), b) if b.is_none_or(|b| s < b) => {
                i = s + 1;
                continue;
            }
            (_, None) => return out,
            (_, Some(b)) => {
                let mut depth = 0i32;
                let mut p = b;
                let bytes = text.as_bytes();
                while p < bytes.len() {
                    match bytes[p] {
                        b'{' => depth += 1,
                        b'}' => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    p += 1;
                }
                i = (p + 1).min(text.len());
            }
        }
    }
    out.push_str(&text[i..]);
    out
}

/// Python's `str.isspace`: Unicode white space and the separators U+001C–U+001F.
fn is_space(c: char) -> bool {
    c.is_whitespace() || ('\u{1c}'..='\u{1f}').contains(&c)
}

/// The non-blank lines of production text, split where Python's `str.splitlines` splits.
fn count_lines(text: &str) -> usize {
    const BREAKS: &[char] = &[
        '\n', '\r', '\u{b}', '\u{c}', '\u{1c}', '\u{1d}', '\u{1e}', '\u{85}', '\u{2028}',
        '\u{2029}',
    ];
    text.split(BREAKS)
        .filter(|l| !l.chars().all(is_space))
        .count()
}

/// Line comments removed (`//`, `///`, `//!` to the end of the line).
fn strip_comments(text: &str) -> String {
    text.split('\n')
        .map(|l| l.find("//").map_or(l, |i| &l[..i]))
        .collect::<Vec<_>>()
        .join("\n")
}

fn is_word(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
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

/// The names `text` declares `#[cfg(test)] mod name;` (optionally `pub` or `pub(…)`).
fn test_mod_declarations(text: &str) -> Vec<String> {
    const ATTR: &str = "#[cfg(test)]";
    let mut names = Vec::new();
    let mut at = 0;
    while let Some(i) = text[at..].find(ATTR) {
        at += i + ATTR.len();
        let mut rest = text[at..].trim_start_matches(is_space);
        if let Some(r) = rest.strip_prefix("pub") {
            let r = match r.strip_prefix('(') {
                Some(inner) => match inner.find(')') {
                    Some(close) => &inner[close + 1..],
                    None => continue,
                },
                None => r,
            };
            let trimmed = r.trim_start_matches(is_space);
            if trimmed.len() == r.len() {
                continue;
            }
            rest = trimmed;
        }
        let Some(r) = rest.strip_prefix("mod") else {
            continue;
        };
        let name_part = r.trim_start_matches(is_space);
        if name_part.len() == r.len() {
            continue;
        }
        let name: String = name_part.chars().take_while(|&c| is_word(c)).collect();
        let after = name_part[name.len()..].trim_start_matches(is_space);
        if !name.is_empty() && after.starts_with(';') {
            names.push(name);
        }
    }
    names
}

/// Files that are tests as a whole: `tests.rs`, `*_tests.rs`, or declared
/// `#[cfg(test)] mod x;` by their parent.
fn test_only_files(files: &BTreeMap<Module, PathBuf>) -> BTreeSet<Module> {
    let mut tests = BTreeSet::new();
    for (m, p) in files {
        let name = p.file_name().unwrap().to_string_lossy();
        if name == "tests.rs" || name.ends_with("_tests.rs") {
            tests.insert(m.clone());
        }
        let text = std::fs::read_to_string(p).unwrap();
        for decl in test_mod_declarations(&text) {
            let mut child = m.clone();
            child.push(decl);
            if files.contains_key(&child) {
                tests.insert(child);
            }
        }
    }
    tests
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

/// Strips `super::` prefixes from `path`: the module they lead to from module `m` (a file
/// `a/b.rs` or `a/b/mod.rs` is `a::b`, whose `super` is `a`) and the rest. `None` where
/// the `super`s climb above the crate root.
fn climb<'p>(m: &Module, mut path: &'p str) -> Option<(Module, &'p str)> {
    let mut base = m.clone();
    while let Some(rest) = path.strip_prefix("super::") {
        base.pop()?;
        path = rest.trim_start();
    }
    Some((base, path))
}

/// The path `crate::` or `super::` starts at `code[at..]` (after the keyword's `::`): its
/// segments while they are words joined by `::` (`a::b::C`, `a::b` of `a::b::{…}`).
fn path_tail(code: &str) -> Vec<String> {
    let mut segs = Vec::new();
    let mut rest = code;
    loop {
        let word: String = rest.chars().take_while(|&c| is_word(c)).collect();
        if word.is_empty() {
            break;
        }
        rest = &rest[word.len()..];
        segs.push(word);
        match rest.strip_prefix("::") {
            Some(r) if r.starts_with(is_word) => rest = r,
            _ => break,
        }
    }
    segs
}

/// The module paths (relative to the crate root) that `code`, in module `m`, refers to.
fn references(m: &Module, code: &str) -> Vec<Vec<String>> {
    let mut paths = Vec::new();
    // `use crate::…;` and `use super::…;` statements, groups expanded.
    let mut at = 0;
    while let Some(i) = code[at..].find("use").map(|i| at + i) {
        at = i + 3;
        let before = code[..i].chars().next_back();
        let after = code[at..].chars().next();
        if before.is_some_and(is_word) || !after.is_some_and(char::is_whitespace) {
            continue;
        }
        let Some(end) = code[at..].find(';') else {
            break;
        };
        let stmt: String = code[at..at + end]
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        if let Some(t) = stmt.strip_prefix("crate::") {
            expand_use(t, &[], &mut paths);
        } else if stmt.starts_with("super::") {
            if let Some((base, t)) = climb(m, &stmt) {
                expand_use(t, &base, &mut paths);
            }
        }
    }
    // Inline paths: `crate::a::b` and `super::a::b` (any number of `super`s) anywhere, in
    // expressions, types, attributes and `use` statements alike.
    for keyword in ["crate::", "super::"] {
        let mut at = 0;
        while let Some(s) = code[at..].find(keyword).map(|i| at + i) {
            at = s + keyword.len();
            let before = code[..s].chars().next_back();
            if before.is_some_and(|c| is_word(c) || c == ':') {
                continue; // part of a longer word or path (`a::super::`, `my_crate::`)
            }
            let segs = if keyword == "crate::" {
                path_tail(&code[at..])
            } else {
                let Some((base, rest)) = climb(m, &code[s..]) else {
                    continue;
                };
                let mut p = base;
                p.extend(path_tail(rest));
                p
            };
            paths.push(segs);
        }
    }
    paths
}

/// The import graph of the crate whose source is `src`.
fn graph(src: &Path) -> Graph {
    let mut files = BTreeMap::new();
    collect(src, src, &mut files);
    let tests = test_only_files(&files);
    let mut edges = BTreeMap::new();
    for (m, p) in &files {
        let text = std::fs::read_to_string(p).unwrap();
        let code = strip_comments(&strip_tests(&text));
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
    Graph {
        files,
        tests,
        edges,
    }
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

/// The import cycles of `g`, one line each.
fn cycle_lines(g: &Graph) -> Vec<String> {
    cycles(&g.edges)
        .iter()
        .map(|c| c.iter().map(show).collect::<Vec<_>>().join(" <-> "))
        .collect()
}

/// Every production file of the crate at `src` longer than [`MAX_LINES`], as messages.
fn long_files(src: &Path) -> Vec<String> {
    let mut files = BTreeMap::new();
    collect(src, src, &mut files);
    let tests = test_only_files(&files);
    let mut long = Vec::new();
    for (m, p) in &files {
        if tests.contains(m) {
            continue;
        }
        let n = count_lines(&strip_tests(&std::fs::read_to_string(p).unwrap()));
        if n > MAX_LINES {
            long.push(format!("{} ({n} lines)", p.display()));
        }
    }
    long
}

#[test]
fn core_has_no_import_cycle() {
    let found = cycle_lines(&graph(&crate_src(CORE_SRC)));
    assert!(
        found.is_empty(),
        "import cycles in {CORE_SRC}:\n  {}",
        found.join("\n  ")
    );
}

#[test]
fn host_crates_have_no_import_cycle() {
    let mut found = Vec::new();
    for (src, _) in HOST_CRATES {
        for c in cycle_lines(&graph(&crate_src(src))) {
            found.push(format!("{src}: {c}"));
        }
    }
    assert!(found.is_empty(), "import cycles:\n  {}", found.join("\n  "));
}

fn layer_of(m: &Module) -> Option<usize> {
    let top = m.first()?;
    CORE_LAYERS.iter().position(|l| l.contains(&top.as_str()))
}

#[test]
fn core_layers_import_only_downwards() {
    let g = graph(&crate_src(CORE_SRC));
    let mut wrong = Vec::new();
    for (m, to) in g.production() {
        let Some(lm) = layer_of(m) else {
            assert!(
                m.is_empty(),
                "core module {} is in no layer of CORE_LAYERS (add it to lib.rs's table and here)",
                show(m)
            );
            continue;
        };
        for t in to.iter().filter(|t| !g.tests.contains(*t)) {
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

/// The modules a crate root's module table lists, in order: rows `//! | [`name`] | …`.
fn listed_modules(root: &str) -> Vec<&str> {
    root.lines()
        .filter_map(|l| l.strip_prefix("//! | [`"))
        .map(|l| l.split('`').next().unwrap_or(""))
        .collect()
}

#[test]
fn host_modules_import_only_from_earlier_ones() {
    let mut wrong = Vec::new();
    for &(src, layers) in HOST_CRATES {
        let dir = crate_src(src);
        let g = graph(&dir);
        let layer = |m: &Module| m.first().and_then(|t| layers.iter().position(|l| l == t));
        for (m, to) in g.production() {
            let Some(lm) = layer(m) else {
                assert!(
                    m.is_empty(),
                    "{src}: module {} is not in its HOST_CRATES entry (nor the root's table)",
                    show(m)
                );
                continue;
            };
            for t in to.iter().filter(|t| !g.tests.contains(*t)) {
                if layer(t).is_none_or(|lt| lt > lm) {
                    wrong.push(format!("{src}: {} imports {}", show(m), show(t)));
                }
            }
        }
        let root = ["lib.rs", "main.rs"]
            .iter()
            .map(|f| dir.join(f))
            .find(|p| p.is_file())
            .unwrap_or_else(|| panic!("{src} has neither lib.rs nor main.rs"));
        let text = std::fs::read_to_string(&root).unwrap();
        assert_eq!(
            listed_modules(&text),
            layers,
            "{}'s module table and its HOST_CRATES entry differ",
            root.display()
        );
    }
    assert!(
        wrong.is_empty(),
        "host imports against the layer order:\n  {}",
        wrong.join("\n  ")
    );
}

#[test]
fn protocol_imports_nothing_above_the_episode_layer() {
    let g = graph(&crate_src(CORE_SRC));
    let mut wrong = Vec::new();
    for (m, to) in g.production() {
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
        "{CORE_SRC} has no protocol module"
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
    let lib = std::fs::read_to_string(crate_src(CORE_SRC).join("lib.rs")).unwrap();
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
fn no_production_file_is_longer_than_the_limit() {
    let mut long = Vec::new();
    for src in std::iter::once(CORE_SRC).chain(HOST_CRATES.iter().map(|c| c.0)) {
        long.extend(long_files(&crate_src(src)));
    }
    assert!(
        long.is_empty(),
        "files over {MAX_LINES} production lines:\n  {}",
        long.join("\n  ")
    );
}

// The checker itself, on small synthetic crates: a check that cannot fail is no check.

/// A crate of `files` (path, text) in a fresh temporary folder, handed to `check`.
fn synthetic<T>(files: &[(&str, &str)], check: impl FnOnce(&Path) -> T) -> T {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "activesense-layers-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    for (name, text) in files {
        let p = dir.join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    let out = check(&dir);
    let _ = std::fs::remove_dir_all(&dir);
    out
}

fn module(path: &str) -> Module {
    path.split('/').map(String::from).collect()
}

#[test]
fn the_checker_finds_a_cycle_through_a_use_group_and_an_inline_path() {
    let g = synthetic(
        &[
            ("lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
            ("a.rs", "use crate::{b::Thing, c::inner::Q};\n"),
            ("b.rs", "fn f() -> u8 { crate::c::inner::X }\n"),
            ("c/mod.rs", "pub mod inner;\n"),
            ("c/inner.rs", "use super::super::a::Y;\n"),
        ],
        graph,
    );
    let found = cycles(&g.edges);
    assert_eq!(found.len(), 1, "{:?}", g.edges);
    let names: Vec<String> = found[0].iter().map(show).collect();
    assert_eq!(names, ["a", "b", "c/inner"]);
}

#[test]
fn the_checker_finds_a_cycle_through_inline_super_paths() {
    // Two siblings naming each other through their parent, once in a `use` and once in a
    // type alias: the shape of a backend trait whose module also picks the backend.
    let g = synthetic(
        &[
            ("lib.rs", "pub mod p;\n"),
            ("p/mod.rs", "pub mod dot;\npub mod dsp;\n"),
            (
                "p/dot.rs",
                "pub trait Dot {}\npub type Fast = super::dsp::Dsp;\n",
            ),
            ("p/dsp.rs", "use super::dot::Dot;\npub struct Dsp;\n"),
        ],
        graph,
    );
    assert_eq!(cycle_lines(&g), ["p/dot <-> p/dsp"], "{:?}", g.edges);
    // The alias moved up to the parent, which may name its children: no cycle.
    let g = synthetic(
        &[
            ("lib.rs", "pub mod p;\n"),
            (
                "p/mod.rs",
                "pub mod dot;\npub mod dsp;\npub type Fast = dsp::Dsp;\n",
            ),
            ("p/dot.rs", "pub trait Dot {}\n"),
            (
                "p/dsp.rs",
                "use super::dot::Dot;\npub struct Dsp;\nfn f() { super::super::p::dot::g() }\n",
            ),
        ],
        graph,
    );
    assert!(cycle_lines(&g).is_empty(), "{:?}", g.edges);
    assert!(g.edges[&module("p/dsp")].contains(&module("p/dot")));
}

#[test]
fn the_checker_ignores_tests_comments_and_parents() {
    let g = synthetic(
        &[
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
        ],
        graph,
    );
    assert!(cycles(&g.edges).is_empty(), "{:?}", g.edges);
    assert!(g.edges[&module("b")].contains(&module("a/x")));
}

#[test]
fn the_checker_cuts_every_test_item_and_counts_production_lines() {
    // A test-only method in the middle of production code, a test module, a test-only
    // `mod x;` and a `*_tests.rs` file: only the production lines count, and the test-only
    // files are no production files at all.
    let text = "use crate::b;\n\nfn one() {}\n#[cfg(test)]\nfn reference() {\n    crate::c::x();\n}\n\
                fn two() {\n    b::y();\n}\n#[cfg(test)]\nmod helper;\n#[cfg(test)]\nmod tests {\n    \
                use crate::c;\n}\nfn three() {}\n";
    assert_eq!(count_lines(&strip_tests(text)), 6);
    let (g, long) = synthetic(
        &[
            ("lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
            ("a/mod.rs", text),
            ("a/helper.rs", &"fn f() {}\n".repeat(MAX_LINES + 1)),
            ("a/x_tests.rs", &"fn f() {}\n".repeat(MAX_LINES + 1)),
            ("b.rs", &"fn f() {}\n\n".repeat(MAX_LINES)),
            ("c.rs", &"fn f() {}\n".repeat(MAX_LINES + 1)),
        ],
        |dir| (graph(dir), long_files(dir)),
    );
    assert_eq!(g.edges[&module("a")], BTreeSet::from([module("b")]));
    assert_eq!(
        g.tests,
        BTreeSet::from([module("a/helper"), module("a/x_tests")])
    );
    assert_eq!(long.len(), 1, "{long:?}");
    assert!(long[0].ends_with(&format!("c.rs ({} lines)", MAX_LINES + 1)));
}

#[test]
#[should_panic(expected = "does not exist")]
fn a_listed_crate_that_is_not_there_fails() {
    crate_src("no-such-crate/src");
}

#[test]
fn the_docs_name_only_source_paths_that_exist() {
    // A moved file leaves stale paths behind in prose; every `core-nostd/…`, `instrument/…`,
    // `lab/…`, `cli/…`, `firmware/…`, `xtask/…` and `tests/…` path the README and docs/
    // name must exist.
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
        for prefix in [
            "core-nostd/",
            "instrument/",
            "lab/",
            "cli/",
            "firmware/",
            "xtask/",
            "tests/",
        ] {
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
