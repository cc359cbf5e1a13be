//! The repository keeps its shape: ARCHITECTURE.md is a true codemap, the
//! core stays pure, and no two files of the service layers import each
//! other, directly or round a circle. Read from the source text, so these
//! fail the moment a change breaks them, not at the next review.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `src/<dir>`, as `src/…` paths with `/`.
fn rust_files(dir: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![root().join(dir)];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("read a source folder") {
            let path = entry.expect("a folder entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let relative = path.strip_prefix(root()).expect("under the crate root");
                out.push(relative.to_string_lossy().replace('\\', "/"));
            }
        }
    }
    out.sort();
    out
}

fn read(path: &str) -> String {
    std::fs::read_to_string(root().join(path)).expect("read a source file")
}

/// The `src/…` paths ARCHITECTURE.md names in backticks.
fn codemap_paths() -> BTreeSet<String> {
    read("ARCHITECTURE.md")
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|s| s.starts_with("src/") && !s.contains(char::is_whitespace))
        .map(str::to_owned)
        .collect()
}

#[test]
fn every_path_the_codemap_names_exists() {
    let missing: Vec<_> = codemap_paths().into_iter().filter(|p| !root().join(p).exists()).collect();
    assert!(missing.is_empty(), "ARCHITECTURE.md names paths that do not exist: {missing:?}");
}

/// A module is named by its file (`src/a/b.rs`), a `mod.rs` by its folder (`src/a/`).
#[test]
fn every_module_under_src_is_named_in_the_codemap() {
    let named = codemap_paths();
    let unnamed: Vec<_> = rust_files("src")
        .into_iter()
        .filter(|file| {
            let folder = file.strip_suffix("mod.rs");
            !named.contains(file) && !folder.is_some_and(|f| named.contains(f))
        })
        .collect();
    assert!(unnamed.is_empty(), "modules missing from ARCHITECTURE.md's codemap: {unnamed:?}");
}

/// Source text without comments (so a doc link is not an import) and
/// without its inline test module (whose `super` is the file itself).
fn code_of(path: &str) -> String {
    let text = read(path);
    let code = text.split("#[cfg(test)]\nmod tests {").next().unwrap_or("");
    code.lines().map(|line| line.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

#[test]
fn the_core_uses_no_runtime_wire_or_storage_crate() {
    const FORBIDDEN: [&str; 8] = ["tokio", "axum", "tonic", "sqlx", "serde", "prost", "hyper", "tower"];
    let mut offences = Vec::new();
    for file in rust_files("src/anim") {
        for (n, line) in code_of(&file).lines().enumerate() {
            let words: Vec<&str> = line.split(|c: char| !(c.is_alphanumeric() || c == '_')).collect();
            if FORBIDDEN.iter().any(|krate| words.contains(krate)) {
                offences.push(format!("{file}:{}: {}", n + 1, line.trim()));
            }
        }
    }
    assert!(offences.is_empty(), "src/anim must stay pure:\n{}", offences.join("\n"));
}

/// A file's module path: `src/server/rest/mod.rs` → `server::rest`.
fn module_of(file: &str) -> String {
    let path = file.trim_start_matches("src/").trim_end_matches(".rs");
    path.trim_end_matches("/mod").replace('/', "::")
}

/// The modules of the crate that `file` refers to: `crate::…` and `super::…`
/// paths, and in a `mod.rs` its children by name (`use child::…`). `mod x;`
/// declarations are not imports.
fn imports(file: &str, modules: &BTreeSet<String>) -> BTreeSet<String> {
    let own = module_of(file);
    let own_segments: Vec<&str> = own.split("::").collect();
    let code: String = code_of(file)
        .lines()
        .filter(|line| {
            !line.trim_start().trim_start_matches("pub(crate) ").trim_start_matches("pub ").starts_with("mod ")
        })
        .collect::<Vec<_>>()
        .join("\n");
    let mut out = BTreeSet::new();
    for word in expand_groups(&code).split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')) {
        // A path, not a lone word (`pub(super)` is visibility, not an import).
        if !word.contains("::") {
            continue;
        }
        let segments: Vec<&str> = word.split("::").filter(|s| !s.is_empty()).collect();
        let ups = segments.iter().take_while(|s| **s == "super").count();
        let path: Vec<&str> = match segments.first() {
            Some(&"crate") => segments[1..].to_vec(),
            Some(&"super") => {
                own_segments[..own_segments.len().saturating_sub(ups)].iter().chain(&segments[ups..]).copied().collect()
            }
            Some(&"self") => own_segments.iter().chain(&segments[1..]).copied().collect(),
            Some(_) if file.ends_with("mod.rs") => own_segments.iter().chain(&segments).copied().collect(),
            _ => continue,
        };
        let target = (1..=path.len()).rev().map(|n| path[..n].join("::")).find(|m| modules.contains(m));
        out.extend(target.filter(|t| *t != own));
    }
    out
}

/// `use a::{b, c::d};` written out as `a::b a::c::d`, innermost group first,
/// so every imported path is one word.
fn expand_groups(code: &str) -> String {
    let mut code = code.to_owned();
    while let Some(open) = code.rfind("::{") {
        let Some(len) = code[open..].find('}') else { break };
        let close = open + len;
        let start = code[..open].rfind(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')).map_or(0, |i| i + 1);
        let prefix = &code[start..open];
        let items: Vec<String> = code[open + 3..close]
            .split(',')
            .map(str::trim)
            .filter(|i| !i.is_empty())
            .map(|i| format!("{prefix}::{i}"))
            .collect();
        code.replace_range(start..=close, &items.join(" "));
    }
    code
}

/// The import graph of the files under `src/<dir>`s, by module.
fn import_graph(dirs: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
    let files: Vec<String> = rust_files("src");
    let modules: BTreeSet<String> = files.iter().map(|f| module_of(f)).collect();
    files
        .iter()
        .filter(|f| dirs.iter().any(|d| f.starts_with(&format!("src/{d}/")) || **f == format!("src/{d}.rs")))
        .map(|f| (module_of(f), imports(f, &modules)))
        .collect()
}

/// A circle of imports among `graph`'s modules, if there is one.
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit<'a>(
        node: &'a str,
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<&'a str>,
        done: &mut BTreeSet<&'a str>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|n| *n == node) {
            return Some(path[at..].iter().map(|s| s.to_string()).chain([node.to_string()]).collect());
        }
        if !done.insert(node) {
            return None;
        }
        path.push(node);
        let next = graph.get(node).into_iter().flatten().filter(|n| graph.contains_key(*n));
        let found = next.into_iter().find_map(|n| visit(n, graph, path, done));
        path.pop();
        found
    }
    let mut done = BTreeSet::new();
    graph.keys().find_map(|start| visit(start, graph, &mut Vec::new(), &mut done))
}

#[test]
fn no_two_files_of_the_server_or_the_stream_engine_import_each_other() {
    let graph = import_graph(&["server", "stream"]);
    assert!(graph.len() > 30, "the graph should cover src/server and src/stream: {:?}", graph.keys());
    assert!(graph["server::grpc"].contains("server::request"), "the scanner should see `use crate::…`");
    assert_eq!(find_cycle(&graph), None, "a circle of imports");
}

#[test]
fn the_cycle_finder_finds_a_circle_round_three_modules() {
    let edge = |a: &str, b: &str| (a.to_string(), BTreeSet::from([b.to_string()]));
    let graph = BTreeMap::from([edge("a", "b"), edge("b", "c"), edge("c", "a"), edge("d", "a")]);
    let cycle = find_cycle(&graph).expect("a → b → c → a");
    assert_eq!(cycle.len(), 4);
    assert_eq!(cycle.first(), cycle.last());
    let acyclic = BTreeMap::from([edge("a", "b"), edge("b", "c"), edge("d", "a")]);
    assert_eq!(find_cycle(&acyclic), None);
}

/// The Markdown the project writes for its users (the third-party READMEs
/// copied beside the example files are not ours).
fn user_docs() -> Vec<String> {
    let mut out: Vec<String> =
        ["README.md", "BENCHMARKS.md", "RELIABILITY.md", "examples/SOURCES.md", "examples/clients/README.md"]
            .map(str::to_owned)
            .into();
    for entry in std::fs::read_dir(root().join("docs")).expect("read docs/") {
        let path = entry.expect("a folder entry").path();
        if path.extension().is_some_and(|e| e == "md") {
            out.push(format!("docs/{}", path.file_name().unwrap().to_string_lossy()));
        }
    }
    out.sort();
    out
}

/// `text` without its fenced code blocks.
fn prose(text: &str) -> String {
    text.split("```").step_by(2).collect::<Vec<_>>().join("\n")
}

/// The anchor GitHub gives a heading: lower case, punctuation dropped, spaces as `-`.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// A user needs only the repository: the docs name no contract they do not
/// have ("SPEC §…"), and every relative link, with its `#anchor`, lands on a
/// file and heading that exist.
#[test]
fn the_user_docs_stand_alone_and_their_links_resolve() {
    let mut broken = Vec::new();
    for doc in user_docs() {
        let text = read(&doc);
        if text.contains("SPEC §") {
            broken.push(format!("{doc} cites SPEC §…: link the docs/ section that says it"));
        }
        let dir = Path::new(&doc).parent().unwrap();
        for link in prose(&text).split("](").skip(1) {
            let Some(target) = link.split(')').next().filter(|t| !t.contains(':') && !t.contains(' ')) else {
                continue;
            };
            let (file, fragment) = target.split_once('#').unwrap_or((target, ""));
            let path = if file.is_empty() { root().join(&doc) } else { root().join(dir).join(file) };
            if !path.exists() {
                broken.push(format!("{doc}: {target}: no such file"));
            } else if !fragment.is_empty() && (file.is_empty() || file.ends_with(".md")) {
                let headings = prose(&std::fs::read_to_string(&path).unwrap())
                    .lines()
                    .filter_map(|l| l.strip_prefix('#'))
                    .map(|l| anchor(l.trim_start_matches('#')))
                    .collect::<BTreeSet<_>>();
                if !headings.contains(fragment) {
                    broken.push(format!("{doc}: {target}: no such heading"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "{broken:#?}");
}
