//! No crate of the workspace has a cycle between its top-level modules: each module uses only
//! what is below it, so a crate reads top-down.
//!
//! For every workspace member, every top-level module of `src/` (a file `src/x.rs` or a
//! folder `src/x/`) and every `.rs` file inside it are scanned, comments and string literals
//! stripped, for the paths that name another top-level module: `crate::x`, `crate::{x, y}`,
//! and `super::x` where that `super` chain reaches the crate root. A path to an item the crate
//! root re-exports (`pub use x::Item;` in `lib.rs`/`main.rs`) counts as a use of `x`. The test
//! fails naming every cycle (strongly connected set of modules) with one file:line per edge.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One use of a top-level module by another: where it is.
#[derive(Debug, Clone)]
struct Edge {
    to: String,
    at: String,
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate lives in the workspace root")
        .to_path_buf()
}

/// The `members` of the workspace manifest.
fn members(root: &Path) -> Vec<PathBuf> {
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("Cargo.toml");
    let start = manifest.find("members = [").expect("a members list");
    let list = &manifest[start..];
    let end = list.find(']').expect("the end of the members list");
    list[..end]
        .split('"')
        .skip(1)
        .step_by(2)
        .map(|member| root.join(member))
        .collect()
}

/// Source text without comments, string and character literals (replaced by spaces, so the
/// line numbers stay).
fn code_only(text: &str) -> String {
    let bytes: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        let next = bytes.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < bytes.len() && bytes[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < bytes.len() {
                if bytes[i] == '/' && bytes.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if bytes[i] == '*' && bytes.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(if bytes[i] == '\n' { '\n' } else { ' ' });
                    i += 1;
                }
            }
        } else if c == '"' || (c == 'r' && (next == Some('"') || next == Some('#'))) {
            i = skip_string(&bytes, i, &mut out);
        } else if c == '\'' {
            // A character literal ('x', '\n', '\u{..}'); a lifetime ('a) is left as it is.
            let close = (i + 2..(i + 12).min(bytes.len())).find(|&k| bytes[k] == '\'');
            match close {
                Some(k) if bytes[i + 1] == '\\' || k == i + 2 => {
                    out.push(' ');
                    i = k + 1;
                }
                _ => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// Skips a (raw) string literal starting at `start`; returns the index after it.
fn skip_string(bytes: &[char], start: usize, out: &mut String) -> usize {
    let mut i = start;
    let mut hashes = 0;
    let raw = bytes[i] == 'r';
    if raw {
        i += 1;
        while bytes.get(i) == Some(&'#') {
            hashes += 1;
            i += 1;
        }
        if bytes.get(i) != Some(&'"') {
            // An identifier starting with r (not a raw string).
            out.extend(&bytes[start..i]);
            return i;
        }
    }
    i += 1;
    while i < bytes.len() {
        let c = bytes[i];
        if c == '\n' {
            out.push('\n');
        }
        if !raw && c == '\\' {
            i += 2;
            continue;
        }
        if c == '"' && (0..hashes).all(|h| bytes.get(i + 1 + h) == Some(&'#')) {
            out.push(' ');
            return i + 1 + hashes;
        }
        i += 1;
    }
    i
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The identifiers at the top level of the group starting at `text[0] == '{'`.
fn group_heads(text: &str) -> Vec<String> {
    let mut heads = Vec::new();
    let mut depth = 0;
    let mut expecting = false;
    let mut current = String::new();
    for c in text.chars() {
        match c {
            '{' => {
                depth += 1;
                expecting = depth == 1;
            }
            '}' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            ',' if depth == 1 => {
                if !current.is_empty() {
                    heads.push(std::mem::take(&mut current));
                }
                expecting = true;
            }
            c if depth == 1 && expecting && is_ident(c) => current.push(c),
            _ if depth == 1 && expecting && !current.is_empty() => {
                heads.push(std::mem::take(&mut current));
                expecting = false;
            }
            _ => {}
        }
    }
    if !current.is_empty() {
        heads.push(current);
    }
    heads
}

/// The first path segments reached from the crate root in `code` of a file whose module
/// is `depth` levels below the root, with their line numbers.
fn root_paths(code: &str, depth: usize) -> Vec<(String, usize)> {
    let mut found = Vec::new();
    let chars: Vec<(usize, char)> = code.char_indices().collect();
    let line_of = |byte: usize| code[..byte].matches('\n').count() + 1;
    let mut k = 0;
    while k < chars.len() {
        let (byte, _) = chars[k];
        let rest = &code[byte..];
        let before_ok = k == 0 || !is_ident(chars[k - 1].1) && chars[k - 1].1 != ':';
        let (prefix_len, reaches_root) = if before_ok && rest.starts_with("crate::") {
            ("crate::".len(), true)
        } else if before_ok && rest.starts_with("super::") {
            let mut len = 0;
            let mut supers = 0;
            while rest[len..].starts_with("super::") {
                len += "super::".len();
                supers += 1;
            }
            (len, supers == depth)
        } else {
            k += 1;
            continue;
        };
        if reaches_root {
            let tail = &rest[prefix_len..];
            if tail.starts_with('{') {
                for head in group_heads(tail) {
                    found.push((head, line_of(byte)));
                }
            } else {
                let head: String = tail.chars().take_while(|c| is_ident(*c)).collect();
                if !head.is_empty() {
                    found.push((head, line_of(byte)));
                }
            }
        }
        k += code[byte..byte + prefix_len].chars().count();
    }
    found
}

/// Names the crate root re-exports, with the top-level module each comes from.
fn root_reexports(root_file: &str) -> BTreeMap<String, String> {
    let code = code_only(root_file);
    let mut names = BTreeMap::new();
    for statement in code.split(';') {
        let statement = statement.trim();
        let Some(path) = statement
            .strip_prefix("pub use ")
            .or_else(|| statement.strip_prefix("pub(crate) use "))
        else {
            continue;
        };
        let path = path
            .trim_start_matches("crate::")
            .trim_start_matches("self::");
        let module: String = path.chars().take_while(|c| is_ident(*c)).collect();
        let Some(brace) = path.find('{') else {
            let last = path.rsplit("::").next().unwrap_or("");
            let name = last.rsplit(" as ").next().unwrap_or(last).trim();
            names.insert(name.to_string(), module);
            continue;
        };
        for item in path[brace + 1..].trim_end_matches('}').split(',') {
            let last = item.rsplit("::").next().unwrap_or("").trim();
            let name = last.rsplit(" as ").next().unwrap_or(last).trim();
            if !name.is_empty() && name != "self" {
                names.insert(name.to_string(), module.clone());
            }
        }
    }
    names
}

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut paths: Vec<PathBuf> = entries.map(|e| e.expect("dir entry").path()).collect();
    paths.sort();
    for path in paths {
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Depth of a file's module below the crate root (`src/x.rs` and `src/x/mod.rs` are 1).
fn module_depth(src: &Path, file: &Path) -> usize {
    let relative = file.strip_prefix(src).expect("file under src");
    let components = relative.components().count();
    if file.file_name().is_some_and(|n| n == "mod.rs") {
        components - 1
    } else {
        components
    }
}

/// The module graph of one source root (`src/` with `root_name` = `lib.rs` or `main.rs`).
fn module_graph(src: &Path, root_name: &str) -> BTreeMap<String, Vec<Edge>> {
    let root_text = std::fs::read_to_string(src.join(root_name)).unwrap_or_default();
    let reexports = root_reexports(&root_text);
    let mut modules: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
    let mut entries: Vec<PathBuf> = std::fs::read_dir(src)
        .expect("src")
        .map(|e| e.expect("entry").path())
        .collect();
    entries.sort();
    for path in entries {
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_string();
        if path.is_dir() {
            if stem == "bin" {
                continue;
            }
            rust_files(&path, modules.entry(stem).or_default());
        } else if path.extension().is_some_and(|e| e == "rs") && stem != "lib" && stem != "main" {
            modules.entry(stem).or_default().push(path);
        }
    }
    let names: BTreeSet<String> = modules.keys().cloned().collect();
    let mut graph = BTreeMap::new();
    for (module, files) in &modules {
        let mut edges: Vec<Edge> = Vec::new();
        for file in files {
            let code = code_only(&std::fs::read_to_string(file).expect("source file"));
            for (head, line) in root_paths(&code, module_depth(src, file)) {
                let target = if names.contains(&head) {
                    Some(head)
                } else {
                    reexports.get(&head).cloned()
                };
                if let Some(target) = target.filter(|t| t != module && names.contains(t)) {
                    if !edges.iter().any(|e| e.to == target) {
                        edges.push(Edge {
                            to: target,
                            at: format!("{}:{line}", file.display()),
                        });
                    }
                }
            }
        }
        graph.insert(module.clone(), edges);
    }
    graph
}

/// Strongly connected sets of more than one module (Tarjan).
fn cycles(graph: &BTreeMap<String, Vec<Edge>>) -> Vec<Vec<String>> {
    struct State<'a> {
        graph: &'a BTreeMap<String, Vec<Edge>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        next: usize,
        found: Vec<Vec<String>>,
    }
    fn visit<'a>(state: &mut State<'a>, node: &'a str) {
        state.index.insert(node, state.next);
        state.low.insert(node, state.next);
        state.next += 1;
        state.stack.push(node);
        state.on_stack.insert(node);
        for edge in &state.graph[node] {
            let to = edge.to.as_str();
            if !state.index.contains_key(to) {
                visit(state, to);
                let low = state.low[to].min(state.low[node]);
                state.low.insert(node, low);
            } else if state.on_stack.contains(to) {
                let low = state.index[to].min(state.low[node]);
                state.low.insert(node, low);
            }
        }
        if state.low[node] == state.index[node] {
            let mut component = Vec::new();
            while let Some(top) = state.stack.pop() {
                state.on_stack.remove(top);
                component.push(top.to_string());
                if top == node {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                state.found.push(component);
            }
        }
    }
    let mut state = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        next: 0,
        found: Vec::new(),
    };
    for node in graph.keys() {
        if !state.index.contains_key(node.as_str()) {
            visit(&mut state, node);
        }
    }
    state.found
}

#[test]
fn no_crate_has_a_cycle_between_its_top_level_modules() {
    let root = workspace_root();
    let mut problems = Vec::new();
    let mut crates = 0;
    for member in members(&root) {
        for root_name in ["lib.rs", "main.rs"] {
            let src = member.join("src");
            if !src.join(root_name).is_file() {
                continue;
            }
            crates += 1;
            let graph = module_graph(&src, root_name);
            for component in cycles(&graph) {
                let edges: Vec<String> = component
                    .iter()
                    .flat_map(|from| {
                        graph[from]
                            .iter()
                            .filter(|e| component.contains(&e.to))
                            .map(move |e| format!("    {from} → {} ({})", e.to, e.at))
                    })
                    .collect();
                problems.push(format!(
                    "{} ({root_name}): cycle between {}\n{}",
                    member.strip_prefix(&root).unwrap_or(&member).display(),
                    component.join(", "),
                    edges.join("\n")
                ));
            }
        }
    }
    assert!(
        crates >= 10,
        "only {crates} crate roots found under {}",
        root.display()
    );
    assert!(problems.is_empty(), "\n{}", problems.join("\n"));
}

#[test]
fn the_scanner_finds_grouped_super_and_reexported_uses() {
    let code = code_only(
        "use crate::{alpha::{A, B}, beta, Gamma};\n// crate::comment\nlet s = \"crate::text\";\n\
         fn f() { super::delta::g(); super::super::epsilon::h(); }\n",
    );
    let at_depth_1: Vec<String> = root_paths(&code, 1).into_iter().map(|(h, _)| h).collect();
    assert_eq!(at_depth_1, ["alpha", "beta", "Gamma", "delta"]);
    let at_depth_2: Vec<String> = root_paths(&code, 2).into_iter().map(|(h, _)| h).collect();
    assert_eq!(at_depth_2, ["alpha", "beta", "Gamma", "epsilon"]);
    let reexports = root_reexports("pub use gamma::{Gamma, Other as Renamed};\npub use beta::B;");
    assert_eq!(reexports["Gamma"], "gamma");
    assert_eq!(reexports["Renamed"], "gamma");
    assert_eq!(reexports["B"], "beta");
    let graph: BTreeMap<String, Vec<Edge>> = [("a", "b"), ("b", "c"), ("c", "a"), ("d", "a")]
        .into_iter()
        .map(|(from, to)| {
            (
                from.to_string(),
                vec![Edge {
                    to: to.to_string(),
                    at: String::new(),
                }],
            )
        })
        .collect();
    assert_eq!(cycles(&graph), [vec!["a", "b", "c"]]);
}
