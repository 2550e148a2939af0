//! The seams of docs/architecture.md, read off `src/`: the modules' dependency direction, no
//! file-level import cycle, no function over 100 lines, the one reader of the state message in
//! the controller, the tick's types below the core and the parts. These are statements about
//! the code a newcomer relies on; a change that breaks one says so here, with the files named.
//!
//! How a file's imports are found: its `use` trees and inline `crate::`/`super::`/`self::` paths,
//! outside comments and its `#[cfg(test)]` module; each path resolves to the file that defines
//! the item (following a `mod.rs`'s `pub use` to the child that defines it). The edges between
//! a `mod.rs` and its own descendants (declarations, re-exports) are not counted.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

/// The library's top-level modules, bottom (0) to top: a module uses only modules of its level
/// or below. Within a level, no cycle (checked with the files).
const LAYERS: &[(&str, u8)] = &[
    ("channels", 0),
    ("config", 0),
    ("dynamics", 0),
    ("logging", 0),
    ("realtime", 0),
    ("record", 0),
    ("recording", 0),
    ("scenario", 0),
    ("shutdown", 0),
    ("robot", 1),
    ("estimation", 2),
    ("plant", 2),
    ("preview", 2),
    ("wbc", 2),
    ("bridge", 3),
    ("bus", 3),
    ("capability", 3),
    ("control", 3),
    ("forecast", 3),
    ("offline", 3),
    ("sim", 3),
    ("report", 4),
];

/// A library file: its module path (`control::core` for src/control/core/mod.rs) and text with
/// comments and its test module removed.
struct SourceFile {
    rel: String,
    module: Vec<String>,
    is_mod: bool,
    code: String,
}

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            walk(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The text before the file's `#[cfg(test)] mod …` (test modules sit at the end of a file).
fn without_tests(text: &str) -> &str {
    let mut from = 0;
    while let Some(i) = text[from..].find("#[cfg(test)]") {
        let at = from + i;
        let rest = text[at + "#[cfg(test)]".len()..].trim_start();
        if rest.starts_with("mod ") || rest.starts_with("pub mod ") {
            return &text[..at];
        }
        from = at + 1;
    }
    text
}

/// The code without `//` and `/* */` comments, string and char literals blanked (so that a
/// brace or a path inside them counts for nothing). Lines are kept.
fn code_only(text: &str) -> String {
    let b: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if b[i] == '\n' {
                        out.push('\n');
                    }
                    i += 1;
                }
            }
        } else if c == 'r' && (next == Some('"') || next == Some('#')) && !ident_char(&b, i) {
            // Raw string: r"…", r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == '"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                if b[j] == '\n' {
                    out.push('\n');
                }
                j += 1;
            }
            out.push_str("\"\"");
            i = j;
        } else if c == '"' {
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    i += 1;
                } else if b[i] == '\n' {
                    out.push('\n');
                }
                i += 1;
            }
            out.push_str("\"\"");
            i += 1;
        } else if c == '\'' && is_char_literal(&b, i) {
            let end = b[i + 1..]
                .iter()
                .position(|&x| x == '\'')
                .map(|p| i + 1 + p);
            let end = if b.get(i + 1) == Some(&'\\') {
                b[i + 3..]
                    .iter()
                    .position(|&x| x == '\'')
                    .map(|p| i + 3 + p)
            } else {
                end
            };
            out.push_str("' '");
            i = end.map_or(b.len(), |e| e + 1);
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn ident_char(b: &[char], i: usize) -> bool {
    i > 0 && (b[i - 1].is_alphanumeric() || b[i - 1] == '_')
}

/// A `'` that opens a char literal ('x', '\n', '\u{…}'), not a lifetime ('a).
fn is_char_literal(b: &[char], i: usize) -> bool {
    matches!(
        (b.get(i + 1), b.get(i + 2)),
        (Some('\\'), _) | (Some(_), Some('\''))
    )
}

fn library_files() -> Vec<SourceFile> {
    let src = src_dir();
    let mut paths = Vec::new();
    walk(&src, &mut paths);
    let mut files = Vec::new();
    for p in paths {
        let rel = p
            .strip_prefix(&src)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        // The binary (main.rs, cli/) imports the library as `upc::`; nothing imports it.
        // Files named tests.rs are test modules.
        if rel == "main.rs" || rel.starts_with("cli/") || rel.ends_with("/tests.rs") {
            continue;
        }
        let mut module: Vec<String> = rel
            .trim_end_matches(".rs")
            .split('/')
            .map(String::from)
            .collect();
        let is_mod = matches!(module.last().map(String::as_str), Some("mod") | Some("lib"));
        if is_mod {
            module.pop();
        }
        let text = std::fs::read_to_string(&p).unwrap();
        let code = code_only(without_tests(&text));
        files.push(SourceFile {
            rel,
            module,
            is_mod,
            code,
        });
    }
    files
}

/// The paths a `use` tree names: `a::{b, c::{d as e}}` → a::b, a::c::d.
fn expand_use(prefix: &[String], tree: &str, out: &mut Vec<(Vec<String>, Option<String>)>) {
    let mut depth = 0;
    let mut item = String::new();
    for ch in tree.chars().chain(std::iter::once(',')) {
        match ch {
            '{' => {
                depth += 1;
                item.push(ch);
            }
            '}' => {
                depth -= 1;
                item.push(ch);
            }
            ',' if depth == 0 => {
                let it = item.trim().to_string();
                item.clear();
                if it.is_empty() {
                    continue;
                }
                if let (Some(open), true) = (it.find('{'), it.ends_with('}')) {
                    let mut p = prefix.to_vec();
                    p.extend(path_segments(it[..open].trim_end_matches("::")));
                    expand_use(&p, &it[open + 1..it.len() - 1], out);
                } else {
                    let (path, alias) = match it.split_once(" as ") {
                        Some((p, a)) => (p.trim(), Some(a.trim().to_string())),
                        None => (it.as_str(), None),
                    };
                    let mut p = prefix.to_vec();
                    p.extend(path_segments(path));
                    out.push((p, alias));
                }
            }
            _ => item.push(ch),
        }
    }
}

fn path_segments(s: &str) -> Vec<String> {
    s.split("::")
        .map(|x| x.trim().to_string())
        .filter(|x| !x.is_empty())
        .collect()
}

/// The `use` statements of a file: (is it `pub`, its tree's text).
fn use_statements(code: &str) -> Vec<(bool, String)> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(i) = code[from..].find("use ") {
        let at = from + i;
        from = at + 4;
        let before = code[..at].trim_end();
        let at_start = before.is_empty() || before.ends_with([';', '{', '}', ']', ')']);
        let is_pub = before.ends_with("pub") || before.ends_with("pub(crate)");
        let word_start =
            at == 0 || !code[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_');
        if !word_start || !(at_start || is_pub) {
            continue;
        }
        if let Some(end) = code[at..].find(';') {
            out.push((
                is_pub,
                code[at + 4..at + end]
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" "),
            ));
        }
    }
    out
}

/// Inline paths outside `use`: `crate::a::b`, `super::x`, `self::y`.
fn inline_paths(code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for root in ["crate::", "super::", "self::"] {
        let mut from = 0;
        while let Some(i) = code[from..].find(root) {
            let at = from + i;
            from = at + root.len();
            if at > 0 && code[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_' || c == ':')
            {
                continue;
            }
            let tail: String = code[at..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                .collect();
            out.push(path_segments(&tail));
        }
    }
    out
}

/// A path relative to `module` made absolute (without `crate`).
fn absolute(module: &[String], path: &[String]) -> Vec<String> {
    match path.first().map(String::as_str) {
        Some("crate") => path[1..].to_vec(),
        Some("super") | Some("self") => {
            let mut base = module.to_vec();
            let mut i = 0;
            while i < path.len() && (path[i] == "super" || path[i] == "self") {
                if path[i] == "super" {
                    base.pop();
                }
                i += 1;
            }
            base.extend_from_slice(&path[i..]);
            base
        }
        // A child module named without `self::` (2018 paths in a mod.rs's `pub use`).
        _ => {
            let mut base = module.to_vec();
            base.extend_from_slice(path);
            base
        }
    }
}

struct Graph {
    files: Vec<SourceFile>,
    by_module: HashMap<Vec<String>, usize>,
    reexports: HashMap<(Vec<String>, String), Vec<String>>,
    edges: Vec<BTreeSet<usize>>,
}

impl Graph {
    fn build() -> Graph {
        let files = library_files();
        let by_module: HashMap<_, _> = files
            .iter()
            .enumerate()
            .map(|(i, f)| (f.module.clone(), i))
            .collect();
        let mut reexports = HashMap::new();
        for f in files.iter().filter(|f| f.is_mod) {
            for (is_pub, tree) in use_statements(&f.code) {
                let mut paths = Vec::new();
                expand_use(&[], &tree, &mut paths);
                for (p, alias) in paths {
                    let first = p.first().map(String::as_str);
                    if !is_pub
                        || matches!(first, Some("crate") | Some("super"))
                        || p.last().is_some_and(|l| l == "*")
                    {
                        continue;
                    }
                    let name = alias.unwrap_or_else(|| p.last().unwrap().clone());
                    reexports.insert((f.module.clone(), name), absolute(&f.module, &p));
                }
            }
        }
        let mut g = Graph {
            edges: vec![BTreeSet::new(); files.len()],
            files,
            by_module,
            reexports,
        };
        for i in 0..g.files.len() {
            let f = &g.files[i];
            let mut paths: Vec<Vec<String>> = Vec::new();
            for (_, tree) in use_statements(&f.code) {
                let mut ps = Vec::new();
                expand_use(&[], &tree, &mut ps);
                paths.extend(ps.into_iter().map(|(p, _)| p).filter(|p| {
                    matches!(
                        p.first().map(String::as_str),
                        Some("crate") | Some("super") | Some("self")
                    )
                }));
            }
            paths.extend(inline_paths(&f.code));
            let targets: BTreeSet<usize> = paths
                .iter()
                .filter_map(|p| {
                    let mut abs = absolute(&f.module, p);
                    if abs.last().is_some_and(|l| l == "self" || l == "*") {
                        abs.pop();
                    }
                    g.resolve(abs)
                })
                .filter(|&t| t != i && !g.files[t].module.is_empty())
                .collect();
            g.edges[i] = targets;
        }
        g
    }

    /// The file defining `path`: the longest module prefix that is a file, through re-exports.
    fn resolve(&self, mut path: Vec<String>) -> Option<usize> {
        for _ in 0..8 {
            let k = (0..=path.len())
                .rev()
                .find(|&k| self.by_module.contains_key(&path[..k]))?;
            let module = path[..k].to_vec();
            if k < path.len()
                && let Some(target) = self.reexports.get(&(module.clone(), path[k].clone()))
            {
                let mut next = target.clone();
                next.extend_from_slice(&path[k + 1..]);
                if next != path {
                    path = next;
                    continue;
                }
            }
            return self.by_module.get(&module).copied();
        }
        None
    }

    /// An edge between a `mod.rs` and its own descendant: a declaration or a re-export.
    fn is_family(&self, a: usize, b: usize) -> bool {
        let (fa, fb) = (&self.files[a], &self.files[b]);
        (fa.is_mod && fb.module.starts_with(&fa.module))
            || (fb.is_mod && fa.module.starts_with(&fb.module))
    }

    fn top(&self, i: usize) -> &str {
        &self.files[i].module[0]
    }

    fn edges_named(&self, from: usize) -> impl Iterator<Item = &str> + '_ {
        self.edges[from].iter().map(|&t| self.files[t].rel.as_str())
    }

    fn file(&self, rel: &str) -> usize {
        self.files
            .iter()
            .position(|f| f.rel == rel)
            .unwrap_or_else(|| panic!("src/{rel} not found"))
    }
}

/// Strongly connected components of more than one file (Tarjan), family edges skipped.
fn cycles(g: &Graph) -> Vec<Vec<String>> {
    struct T<'a> {
        g: &'a Graph,
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        stack: Vec<usize>,
        on: Vec<bool>,
        next: usize,
        found: Vec<Vec<String>>,
    }
    fn visit(t: &mut T, v: usize) {
        t.index[v] = Some(t.next);
        t.low[v] = t.next;
        t.next += 1;
        t.stack.push(v);
        t.on[v] = true;
        let targets: Vec<usize> = t.g.edges[v]
            .iter()
            .copied()
            .filter(|&w| !t.g.is_family(v, w))
            .collect();
        for w in targets {
            match t.index[w] {
                None => {
                    visit(t, w);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(iw) if t.on[w] => t.low[v] = t.low[v].min(iw),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.index[v] {
            let mut comp = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on[w] = false;
                comp.push(t.g.files[w].rel.clone());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.found.push(comp);
            }
        }
    }
    let n = g.files.len();
    let mut t = T {
        g,
        index: vec![None; n],
        low: vec![0; n],
        stack: vec![],
        on: vec![false; n],
        next: 0,
        found: vec![],
    };
    for v in 0..n {
        if t.index[v].is_none() {
            visit(&mut t, v);
        }
    }
    t.found
}

#[test]
fn the_import_graph_is_read_and_resolves_through_re_exports() {
    // The reader itself, on edges known to exist: a plain `use crate::…`, a `super::` path, and
    // a name re-exported by a mod.rs resolved to the child that defines it.
    let g = Graph::build();
    assert!(
        g.files.len() > 150,
        "only {} library files read",
        g.files.len()
    );
    let server = g.file("control/server.rs");
    let named: Vec<_> = g.edges_named(server).collect();
    assert!(
        named.contains(&"control/contract.rs"),
        "control/server.rs → {named:?}"
    );
    let part = g.file("control/part.rs");
    let named: Vec<_> = g.edges_named(part).collect();
    assert!(
        named.contains(&"control/frame.rs") && named.contains(&"control/tick.rs"),
        "control/part.rs → {named:?}"
    );
    let edges: usize = g.edges.iter().map(BTreeSet::len).sum();
    assert!(edges > 500, "only {edges} import edges found");
}

#[test]
fn no_file_imports_a_file_that_imports_it_back() {
    let g = Graph::build();
    let found = cycles(&g);
    assert!(
        found.is_empty(),
        "file-level import cycles in src/: {found:#?}"
    );
}

#[test]
fn modules_depend_downwards_only() {
    let g = Graph::build();
    let layer: HashMap<&str, u8> = LAYERS.iter().copied().collect();
    let mut tops = BTreeSet::new();
    let mut wrong = BTreeMap::new();
    for (i, f) in g.files.iter().enumerate() {
        let Some(from) = f.module.first() else {
            continue;
        };
        tops.insert(from.clone());
        let lf = *layer.get(from.as_str()).unwrap_or_else(|| {
            panic!(
                "src/{from}: a top-level module without a layer in LAYERS (docs/architecture.md)"
            )
        });
        for &t in &g.edges[i] {
            let to = g.top(t);
            if to != from && layer.get(to).is_some_and(|&lt| lt > lf) {
                wrong
                    .entry(format!("{from} → {to}"))
                    .or_insert_with(Vec::new)
                    .push(format!("{} → {}", f.rel, g.files[t].rel));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "upward dependencies (docs/architecture.md): {wrong:#?}"
    );
    // The table names every module there is (a removed module leaves no stale line).
    let listed: BTreeSet<String> = LAYERS.iter().map(|(m, _)| m.to_string()).collect();
    assert_eq!(listed, tops, "LAYERS vs the modules of src/");
}

#[test]
fn no_module_uses_a_module_that_uses_it_back() {
    let g = Graph::build();
    let mut uses: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (i, f) in g.files.iter().enumerate() {
        let Some(from) = f.module.first().map(String::as_str) else {
            continue;
        };
        let set = uses.entry(from).or_default();
        set.extend(
            g.edges[i]
                .iter()
                .map(|&t| g.top(t))
                .filter(|&to| to != from),
        );
    }
    // Peel off modules that use nothing left; what remains is on a cycle.
    let mut left = uses.clone();
    loop {
        let sinks: Vec<&str> = left
            .iter()
            .filter(|(_, to)| to.iter().all(|t| !left.contains_key(t)))
            .map(|(m, _)| *m)
            .collect();
        if sinks.is_empty() {
            break;
        }
        for m in sinks {
            left.remove(m);
        }
    }
    assert!(left.is_empty(), "modules on a cycle: {left:#?}");
}

#[test]
fn the_bus_imports_nothing_of_the_plants_and_one_plant_speaks_the_bus() {
    let g = Graph::build();
    for (i, f) in g.files.iter().enumerate() {
        let into = |m: &str| g.edges[i].iter().any(|&t| g.top(t) == m);
        let top = f.module.first().map_or("", String::as_str);
        if top == "bus" {
            assert!(!into("sim"), "src/{} imports sim", f.rel);
        }
        if top == "sim" && f.rel != "sim/bus_robot.rs" {
            assert!(
                !into("bus"),
                "src/{} imports bus (only sim/bus_robot.rs speaks the bus)",
                f.rel
            );
        }
    }
}

#[test]
fn neither_engine_imports_the_other() {
    let g = Graph::build();
    for (i, f) in g.files.iter().enumerate() {
        let mujoco = f.rel.starts_with("sim/mujoco/");
        let own = f.rel == "sim/world.rs" || f.rel == "sim/contact.rs";
        for t in g.edges_named(i) {
            assert!(
                !(mujoco && (t == "sim/world.rs" || t == "sim/contact.rs")),
                "src/{} imports src/{t}",
                f.rel
            );
            assert!(
                !(own && t.starts_with("sim/mujoco/")),
                "src/{} imports src/{t}",
                f.rel
            );
        }
    }
}

#[test]
fn the_tick_types_import_neither_the_core_nor_the_parts() {
    let g = Graph::build();
    for rel in [
        "tick.rs",
        "frame.rs",
        "part.rs",
        "tick_record.rs",
        "held_object.rs",
        "summary.rs",
    ] {
        let i = g.file(&format!("control/{rel}"));
        let up: Vec<_> = g
            .edges_named(i)
            .filter(|t| t.starts_with("control/core/") || t.starts_with("control/parts/"))
            .collect();
        assert!(up.is_empty(), "src/control/{rel} imports {up:?}");
    }
}

#[test]
fn only_the_loop_edge_of_the_controller_sees_the_state_message() {
    let allowed = [
        "control/contract.rs",
        "control/plant_link.rs",
        "control/server.rs",
    ];
    let g = Graph::build();
    let mut seen = Vec::new();
    for f in g.files.iter().filter(|f| f.rel.starts_with("control/")) {
        let word = f.code.match_indices("StateMsg").any(|(i, _)| {
            let before = f.code[..i].chars().last();
            let after = f.code[i + "StateMsg".len()..].chars().next();
            !before.is_some_and(|c| c.is_alphanumeric() || c == '_')
                && !after.is_some_and(|c| c.is_alphanumeric() || c == '_')
        });
        if word {
            seen.push(f.rel.as_str());
        }
    }
    assert!(
        seen.iter().all(|r| allowed.contains(r)),
        "StateMsg in {seen:?}; the controller reads it in {allowed:?} only"
    );
    assert!(
        seen.contains(&"control/contract.rs"),
        "the contract's reader no longer reads StateMsg: {seen:?}"
    );
}

/// Functions of `code` longer than `limit` lines (signature to closing brace), as (name, line,
/// length).
fn long_functions(code: &str, limit: usize) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = code.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let Some(name) = fn_name(lines[i]) else {
            i += 1;
            continue;
        };
        let (mut depth, mut opened, mut j) = (0i32, false, i);
        while j < lines.len() {
            for c in lines[j].chars() {
                match c {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    ';' if !opened && depth == 0 => break,
                    _ => {}
                }
            }
            if (opened && depth == 0) || (!opened && lines[j].trim_end().ends_with(';')) {
                break;
            }
            j += 1;
        }
        let length = j - i + 1;
        if opened && length > limit {
            out.push((name, i + 1, length));
        }
        // Nested functions count within their parent.
        i = j + 1;
    }
    out
}

/// The name of a function whose signature starts on `line`.
fn fn_name(line: &str) -> Option<String> {
    let mut words = line.split_whitespace().peekable();
    while let Some(w) = words.next() {
        if w.starts_with("pub")
            || matches!(
                w,
                "const" | "unsafe" | "async" | "extern" | "\"C\"" | "default"
            )
        {
            continue;
        }
        if w == "fn" {
            return words
                .next()
                .map(|n| n.split(['(', '<']).next().unwrap_or(n).to_string());
        }
        return None;
    }
    None
}

#[test]
fn the_length_reader_finds_a_long_function() {
    let body: String = (0..120).map(|k| format!("    let x{k} = {k};\n")).collect();
    let code = format!("pub fn short() {{\n}}\n\nfn long_one(a: u8) -> u8 {{\n{body}    a\n}}\n");
    assert_eq!(
        long_functions(&code, 100),
        vec![("long_one".to_string(), 4, 123)]
    );
    assert!(long_functions(&code, 200).is_empty());
}

#[test]
fn no_function_is_over_100_lines() {
    let src = src_dir();
    let mut paths = Vec::new();
    walk(&src, &mut paths);
    let mut long = Vec::new();
    for p in paths {
        let rel = p.strip_prefix(&src).unwrap().to_string_lossy().into_owned();
        if rel.ends_with("tests.rs") {
            continue;
        }
        let code = code_only(without_tests(&std::fs::read_to_string(&p).unwrap()));
        for (name, line, n) in long_functions(&code, 100) {
            long.push(format!("src/{rel}:{line} {name} ({n} lines)"));
        }
    }
    assert!(long.is_empty(), "functions over 100 lines: {long:#?}");
}
