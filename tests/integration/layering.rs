//! The layering of `src/` (issue #33): no import circle between the top-level modules.
//! A `crate::b` path written anywhere in module `a` (code, comments and doc links alike)
//! counts as `a` uses `b`, as does a `super::` chain that climbs out of `a` to `b`; no
//! chain of these may come back to where it started. The bottom layer (`base`, `error`,
//! `files`, `simd`) names nothing above it. Reads every file under `src/` with std only.

use std::collections::{BTreeMap, BTreeSet};

/// Module `a` -> module `b` -> the files of `a` that name `b`.
type Graph = BTreeMap<String, BTreeMap<String, BTreeSet<String>>>;

/// The modules below everything else: they may name only each other.
const BOTTOM: [&str; 4] = ["base", "error", "files", "simd"];

/// The module path of a file relative to `src/`: `geometry/grid/mod.rs` -> `[geometry,
/// grid]`, `files.rs` -> `[files]`; empty for the crate roots `lib.rs` and `main.rs`.
fn module_path(rel: &str) -> Vec<&str> {
    let mut parts: Vec<&str> = rel.split('/').collect();
    let last = parts.pop().unwrap().trim_end_matches(".rs");
    let crate_root = parts.is_empty() && matches!(last, "lib" | "main");
    if last != "mod" && !crate_root {
        parts.push(last);
    }
    parts
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The identifier at the start of `s` (after white space).
fn ident(s: &str) -> &str {
    let s = s.trim_start();
    &s[..s.find(|c: char| !is_ident(c)).unwrap_or(s.len())]
}

/// The first names of the paths in a `{...}` group at the start of `s`
/// (`{a::X, b, c::{D, E}}` -> `a`, `b`, `c`).
fn group_heads(s: &str) -> Vec<&str> {
    let mut heads = Vec::new();
    let mut depth = 0;
    let mut expect_head = false;
    for (i, c) in s.char_indices() {
        match c {
            '{' => {
                depth += 1;
                expect_head = depth == 1;
            }
            '}' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            ',' if depth == 1 => expect_head = true,
            c if expect_head && !c.is_whitespace() => {
                expect_head = false;
                let head = ident(&s[i..]);
                if !head.is_empty() {
                    heads.push(head);
                }
            }
            _ => {}
        }
    }
    heads
}

/// The crate-root names that the text of file `rel` paths into: after each `crate::`
/// (also `$crate::` in macros, and `crate::{a, b::C}` groups), and after each `super::`
/// chain that climbs to the crate root from the file's module. (A chain inside an inline
/// module climbs one step less than counted here; it can only name what that module's
/// parent has in scope, which a `crate::` path in the same file has brought there.)
fn roots_named<'a>(rel: &str, text: &'a str) -> Vec<&'a str> {
    let depth = module_path(rel).len();
    let mut names = Vec::new();
    for (i, _) in text.match_indices("crate::") {
        if text[..i].chars().next_back().is_some_and(is_ident) {
            continue;
        }
        let rest = &text[i + "crate::".len()..];
        if rest.starts_with('{') {
            names.extend(group_heads(rest));
        } else {
            names.push(ident(rest));
        }
    }
    for (i, _) in text.match_indices("super::") {
        let before = text[..i].chars().next_back();
        if before.is_some_and(is_ident) || before == Some(':') {
            continue; // not the start of a chain
        }
        let mut rest = &text[i..];
        let mut ups = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            ups += 1;
            rest = r;
        }
        if ups >= depth {
            if rest.starts_with('{') {
                names.extend(group_heads(rest));
            } else {
                names.push(ident(rest));
            }
        }
    }
    names
}

/// The graph of the top-level modules of `files` (path relative to `src/`, text).
fn graph(files: &[(String, String)]) -> Graph {
    let modules: BTreeSet<String> =
        files.iter().filter_map(|(rel, _)| module_path(rel).first().map(|m| m.to_string())).collect();
    let mut g = Graph::new();
    for (rel, text) in files {
        let Some(&from) = module_path(rel).first() else { continue };
        let out = g.entry(from.to_string()).or_default();
        for to in roots_named(rel, text) {
            if to != from && modules.contains(to) {
                out.entry(to.to_string()).or_default().insert(rel.clone());
            }
        }
    }
    g
}

/// A chain of modules that comes back to where it started (`[a, b, a]`), if any.
fn find_cycle(g: &Graph) -> Option<Vec<String>> {
    fn visit(
        g: &Graph,
        m: &str,
        stack: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = stack.iter().position(|s| s == m) {
            let mut cycle = stack[at..].to_vec();
            cycle.push(m.to_string());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        stack.push(m.to_string());
        for next in g.get(m).into_iter().flat_map(|out| out.keys()) {
            if let Some(cycle) = visit(g, next, stack, done) {
                return Some(cycle);
            }
        }
        stack.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = BTreeSet::new();
    g.keys().find_map(|m| visit(g, m, &mut Vec::new(), &mut done))
}

/// The graph, one line per module, as `a -> b, c`.
fn describe(g: &Graph) -> String {
    g.iter()
        .map(|(a, out)| format!("{a} -> {}\n", out.keys().cloned().collect::<Vec<_>>().join(", ")))
        .collect()
}

/// A cycle with the files that make each of its steps.
fn explain(g: &Graph, cycle: &[String]) -> String {
    let steps: Vec<String> = cycle
        .windows(2)
        .map(|w| {
            let files: Vec<&str> = g[&w[0]][&w[1]].iter().map(String::as_str).collect();
            format!("  {} -> {} (in {})", w[0], w[1], files.join(", "))
        })
        .collect();
    format!("import circle {}:\n{}", cycle.join(" -> "), steps.join("\n"))
}

#[test]
fn no_import_circle_between_top_level_modules() {
    let g = graph(&crate::util::crate_sources());
    for m in ["base", "cli", "compare", "convert", "geometry", "grid", "mesh", "scene", "simd"] {
        assert!(g.contains_key(m), "no module {m} found under src/:\n{}", describe(&g));
    }
    assert!(g["cli"].contains_key("plan") && g["geometry"].contains_key("scene"), "{}", describe(&g));
    if let Some(cycle) = find_cycle(&g) {
        panic!("{}\nthe graph:\n{}", explain(&g, &cycle), describe(&g));
    }
}

#[test]
fn the_bottom_layer_names_nothing_above_it() {
    let g = graph(&crate::util::crate_sources());
    for m in BOTTOM {
        let above: Vec<String> = g
            .get(m)
            .into_iter()
            .flatten()
            .filter(|(to, _)| !BOTTOM.contains(&to.as_str()))
            .map(|(to, files)| {
                format!("{m} -> {to} (in {})", files.iter().cloned().collect::<Vec<_>>().join(", "))
            })
            .collect();
        assert!(above.is_empty(), "the bottom layer names modules above it: {above:?}");
    }
}

#[test]
fn the_check_sees_paths_in_code_comments_groups_and_super_chains() {
    let file = |rel: &str, text: &str| (rel.to_string(), text.to_string());
    let files = [
        file("a/mod.rs", "use crate::{b::X, c::{Y, Z}};\nfn f() { $crate::d::g() }"),
        file("a/x.rs", "use super::super::e::W; use super::super::{f::V};"),
        file("b.rs", "//! See [`crate::a::T`].\nuse crate::error::E; fn ok() { let _ = super::b_item; }"),
        file("c/mod.rs", "let notcrate::d = 1; // crate::c is itself"),
        file("d.rs", ""),
        file("e.rs", ""),
        file("f.rs", ""),
        file("lib.rs", "pub mod a; use crate::b;"),
    ];
    let g = graph(&files);
    let heads = |m: &str| g[m].keys().cloned().collect::<Vec<_>>();
    assert_eq!(heads("a"), ["b", "c", "d", "e", "f"]);
    assert_eq!(heads("b"), ["a"]);
    assert!(heads("c").is_empty());
    assert!(!g.contains_key("lib"));
    let cycle = find_cycle(&g).expect("a -> b -> a");
    assert_eq!(cycle.first(), cycle.last());
    assert!(explain(&g, &cycle).contains("(in b.rs)"), "{}", explain(&g, &cycle));
    let acyclic = graph(&files[1..]);
    assert_eq!(find_cycle(&acyclic), None, "{}", describe(&acyclic));
}
