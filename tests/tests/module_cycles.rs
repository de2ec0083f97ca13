//! No crate of the workspace has a cycle between its top-level modules: each module uses only
//! what is below it, so a crate reads top-down.
//!
//! For every workspace member, every top-level module of `src/` (a file `src/x.rs` or a folder
//! `src/x/`) and every `.rs` file inside it are parsed with `syn`, and every path that names
//! another top-level module is collected: `crate::x`, `use crate::{x, y}` (at any depth of a use
//! group), and `super::x` where that `super` chain reaches the crate root, in items, expressions,
//! types and the token streams of macro calls. A path to an item the crate root re-exports
//! (`pub use x::Item;` in `lib.rs`/`main.rs`) counts as a use of `x`. The modules and those uses
//! form a graph; the test fails naming every strongly connected set of more than one module
//! (`petgraph`'s Tarjan), with one file:line per edge.

use petgraph::algo::tarjan_scc;
use petgraph::graph::DiGraph;
use proc_macro2::{TokenStream, TokenTree};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

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
    let manifest: toml::Table = std::fs::read_to_string(root.join("Cargo.toml"))
        .expect("Cargo.toml")
        .parse()
        .expect("Cargo.toml is TOML");
    manifest["workspace"]["members"]
        .as_array()
        .expect("a members list")
        .iter()
        .map(|member| root.join(member.as_str().expect("a member path")))
        .collect()
}

fn parse(file: &Path) -> syn::File {
    let text = std::fs::read_to_string(file).expect("source file");
    syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()))
}

/// Collects the first path segment after the crate root of every path in a file whose module
/// is `depth` levels below the root, with its line.
struct RootUses {
    depth: usize,
    found: Vec<(String, usize)>,
}

impl RootUses {
    /// The segment after the root in `segments`, if they start at the root.
    fn note<'a>(&mut self, mut segments: impl Iterator<Item = &'a syn::Ident>) {
        let Some(first) = segments.next() else {
            return;
        };
        let head = if first == "crate" {
            segments.next()
        } else if first == "super" {
            let mut supers = 1;
            let mut next = segments.next();
            while next.is_some_and(|s| s == "super") {
                supers += 1;
                next = segments.next();
            }
            next.filter(|_| supers == self.depth)
        } else {
            None
        };
        if let Some(head) = head {
            self.found
                .push((head.to_string(), head.span().start().line));
        }
    }

    /// Every use-path in a use tree, as the idents from its start down to each leaf.
    fn use_tree(&mut self, prefix: &mut Vec<syn::Ident>, tree: &syn::UseTree) {
        match tree {
            syn::UseTree::Path(path) => {
                prefix.push(path.ident.clone());
                self.use_tree(prefix, &path.tree);
                prefix.pop();
            }
            syn::UseTree::Name(name) => self.leaf(prefix, &name.ident),
            syn::UseTree::Rename(rename) => self.leaf(prefix, &rename.ident),
            syn::UseTree::Glob(_) => self.note(prefix.iter()),
            syn::UseTree::Group(group) => {
                for item in &group.items {
                    self.use_tree(prefix, item);
                }
            }
        }
    }

    fn leaf(&mut self, prefix: &[syn::Ident], ident: &syn::Ident) {
        self.note(prefix.iter().chain(std::iter::once(ident)));
    }

    /// Paths written inside a macro call: runs of `ident :: ident :: ...` in its tokens.
    fn tokens(&mut self, tokens: TokenStream) {
        let mut run: Vec<syn::Ident> = Vec::new();
        let mut colons = 0;
        for token in tokens {
            match token {
                TokenTree::Ident(ident) if run.is_empty() || colons == 2 => {
                    run.push(ident);
                    colons = 0;
                }
                TokenTree::Punct(p) if p.as_char() == ':' && !run.is_empty() && colons < 2 => {
                    colons += 1;
                }
                other => {
                    self.note(run.iter());
                    run.clear();
                    colons = 0;
                    match other {
                        TokenTree::Group(group) => self.tokens(group.stream()),
                        TokenTree::Ident(ident) => run.push(ident),
                        _ => {}
                    }
                }
            }
        }
        self.note(run.iter());
    }
}

impl<'ast> Visit<'ast> for RootUses {
    fn visit_item_use(&mut self, item: &'ast syn::ItemUse) {
        self.use_tree(&mut Vec::new(), &item.tree);
    }

    fn visit_path(&mut self, path: &'ast syn::Path) {
        self.note(path.segments.iter().map(|s| &s.ident));
        syn::visit::visit_path(self, path);
    }

    fn visit_macro(&mut self, mac: &'ast syn::Macro) {
        self.tokens(mac.tokens.clone());
        syn::visit::visit_macro(self, mac);
    }
}

/// The first path segments reached from the crate root in a file whose module is `depth`
/// levels below the root, with their lines.
fn root_uses(file: &syn::File, depth: usize) -> Vec<(String, usize)> {
    let mut uses = RootUses {
        depth,
        found: Vec::new(),
    };
    uses.visit_file(file);
    uses.found
}

/// Names the crate root re-exports (`pub use x::...;`), with the top-level module each comes
/// from.
fn root_reexports(root: &syn::File) -> BTreeMap<String, String> {
    fn leaves(module: &str, tree: &syn::UseTree, out: &mut BTreeMap<String, String>) {
        match tree {
            syn::UseTree::Path(path) => leaves(module, &path.tree, out),
            syn::UseTree::Name(name) if name.ident != "self" => {
                out.insert(name.ident.to_string(), module.to_owned());
            }
            syn::UseTree::Rename(rename) => {
                out.insert(rename.rename.to_string(), module.to_owned());
            }
            syn::UseTree::Group(group) => {
                for item in &group.items {
                    leaves(module, item, out);
                }
            }
            _ => {}
        }
    }
    let mut names = BTreeMap::new();
    for item in &root.items {
        let syn::Item::Use(item) = item else { continue };
        if !matches!(item.vis, syn::Visibility::Public(_)) {
            continue;
        }
        let mut tree = &item.tree;
        if let syn::UseTree::Path(path) = tree {
            if path.ident == "crate" || path.ident == "self" {
                tree = &path.tree;
            }
        }
        match tree {
            syn::UseTree::Path(path) => leaves(&path.ident.to_string(), &path.tree, &mut names),
            syn::UseTree::Group(group) => {
                for item in &group.items {
                    if let syn::UseTree::Path(path) = item {
                        leaves(&path.ident.to_string(), &path.tree, &mut names);
                    }
                }
            }
            _ => {}
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
    let reexports = root_reexports(&parse(&src.join(root_name)));
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
            for (head, line) in root_uses(&parse(file), module_depth(src, file)) {
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

/// Strongly connected sets of more than one module, each sorted.
fn cycles(graph: &BTreeMap<String, Vec<Edge>>) -> Vec<Vec<String>> {
    let mut digraph = DiGraph::<&str, ()>::new();
    let index: BTreeMap<&str, _> = graph
        .keys()
        .map(|name| (name.as_str(), digraph.add_node(name.as_str())))
        .collect();
    for (from, edges) in graph {
        for edge in edges {
            if let Some(&to) = index.get(edge.to.as_str()) {
                digraph.add_edge(index[from.as_str()], to, ());
            }
        }
    }
    let mut found: Vec<Vec<String>> = tarjan_scc(&digraph)
        .into_iter()
        .filter(|component| component.len() > 1)
        .map(|component| {
            let mut names: Vec<String> = component.iter().map(|&n| digraph[n].to_owned()).collect();
            names.sort();
            names
        })
        .collect();
    found.sort();
    found
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
fn the_scanner_finds_grouped_super_macro_and_reexported_uses() {
    let file = syn::parse_file(
        "use crate::{alpha::{A, B}, beta, Gamma};\n// crate::comment\n\
         fn f() { let s = \"crate::text\"; super::delta::g(); super::super::epsilon::h(); }\n\
         fn m() { println!(\"{}\", crate::zeta::Z); }\n",
    )
    .unwrap();
    let heads = |depth| -> Vec<String> {
        root_uses(&file, depth)
            .into_iter()
            .map(|(head, _)| head)
            .collect()
    };
    assert_eq!(
        heads(1),
        ["alpha", "alpha", "beta", "Gamma", "delta", "zeta"]
    );
    assert_eq!(
        heads(2),
        ["alpha", "alpha", "beta", "Gamma", "epsilon", "zeta"]
    );
    let lines: Vec<usize> = root_uses(&file, 1).into_iter().map(|(_, l)| l).collect();
    assert_eq!(lines, [1, 1, 1, 1, 3, 4]);
    let root = syn::parse_file(
        "mod gamma;\npub use gamma::{Gamma, Other as Renamed};\npub use beta::B;\nuse hidden::H;",
    )
    .unwrap();
    let reexports = root_reexports(&root);
    assert_eq!(reexports["Gamma"], "gamma");
    assert_eq!(reexports["Renamed"], "gamma");
    assert_eq!(reexports["B"], "beta");
    assert!(
        !reexports.contains_key("H"),
        "a private use is no re-export"
    );
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
