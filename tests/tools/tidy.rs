//! The repository keeps its shape: ARCHITECTURE.md is a true map of the
//! workspace, the crates depend on each other in one direction only (the
//! manifests say so, and Cargo enforces what the manifests say), and no two
//! modules of any crate import each other, directly or round a circle. Read
//! from the source text, so these fail the moment a change breaks them, not
//! at the next review.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crate::common::internal_contract_citations;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The source folders of the workspace: each crate's `src/`, and the binary's.
const SOURCE_ROOTS: [&str; 5] =
    ["src", "crates/anim/src", "crates/formats/src", "crates/server/src", "crates/load/src"];

/// Every `.rs` file under `dir`, as repository paths with `/`.
fn rust_files(dir: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![root().join(dir)];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("read a source folder") {
            let path = entry.expect("a folder entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let relative = path.strip_prefix(root()).expect("under the repository root");
                out.push(relative.to_string_lossy().replace('\\', "/"));
            }
        }
    }
    out.sort();
    out
}

fn read(path: &str) -> String {
    std::fs::read_to_string(root().join(path)).expect("read a file")
}

/// The paths ARCHITECTURE.md names in backticks (`crates/…`, `src/…`, `tests/…`, …).
fn codemap_paths() -> BTreeSet<String> {
    read("ARCHITECTURE.md")
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|s| s.contains('/') && !s.contains(char::is_whitespace) && !s.starts_with('/') && !s.contains("://"))
        .filter(|s| root().join(s.split('/').next().unwrap()).is_dir())
        .map(str::to_owned)
        .collect()
}

#[test]
fn every_path_the_codemap_names_exists() {
    let missing: Vec<_> = codemap_paths().into_iter().filter(|p| !root().join(p).exists()).collect();
    assert!(missing.is_empty(), "ARCHITECTURE.md names paths that do not exist: {missing:?}");
}

/// The map names every crate and every top-level folder (`crates/anim/`,
/// `docs/`), not every file: a new module needs no edit here, a new crate or
/// folder does.
#[test]
fn every_crate_and_top_level_folder_is_named_in_the_codemap() {
    let named = codemap_paths();
    let mut folders = Vec::new();
    for entry in std::fs::read_dir(root()).expect("read the repository root") {
        let path = entry.expect("an entry").path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() && !name.starts_with('.') && !["target", "data"].contains(&name.as_str()) {
            folders.push(format!("{name}/"));
        }
    }
    for entry in std::fs::read_dir(root().join("crates")).expect("read crates/") {
        let path = entry.expect("an entry").path();
        folders.push(format!("crates/{}/", path.file_name().unwrap().to_string_lossy()));
    }
    let unnamed: Vec<_> = folders.into_iter().filter(|f| !named.contains(f)).collect();
    assert!(unnamed.is_empty(), "folders missing from ARCHITECTURE.md's map: {unnamed:?}");
}

/// The `[dependencies]` of a manifest, by the name the code uses.
fn dependencies(manifest: &str) -> BTreeSet<String> {
    let text = read(manifest);
    let section = text.split("\n[dependencies]\n").nth(1).expect("a [dependencies] table");
    let section = section.split("\n[").next().unwrap();
    section
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| l.split(['=', '.', ' ']).next().unwrap().to_owned())
        .collect()
}

/// The core is pure: no runtime, wire or storage crate can reach it, because
/// its manifest names none (Cargo refuses code that uses an undeclared crate).
#[test]
fn the_core_depends_on_glam_alone() {
    assert_eq!(dependencies("crates/anim/Cargo.toml"), BTreeSet::from(["glam".to_owned()]));
}

/// The layers in one direction: anim ← formats ← server and load ← the binary.
#[test]
fn the_crates_depend_on_each_other_in_one_direction() {
    let layers = ["anim", "formats", "server", "load"];
    for (krate, forbidden) in
        [("formats", &["server", "load"][..]), ("server", &["load"]), ("load", &["server"]), ("anim", &layers[1..])]
    {
        let deps = dependencies(&format!("crates/{krate}/Cargo.toml"));
        let upward: Vec<_> = forbidden.iter().filter(|f| deps.contains(**f)).collect();
        assert!(upward.is_empty(), "crates/{krate} depends on {upward:?}, a layer above it");
    }
}

/// Source text without comments (so a doc link is not an import) and
/// without its inline test module (whose `super` is the file itself).
fn code_of(path: &str) -> String {
    let text = read(path);
    let test_module = ["", "pub(crate) ", "pub(super) ", "pub "]
        .iter()
        .filter_map(|vis| text.find(&format!("#[cfg(test)]\n{vis}mod tests {{")))
        .min();
    let code = &text[..test_module.unwrap_or(text.len())];
    code.lines().map(|line| line.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n")
}

/// A file's module path within its crate: `crates/server/src/rest/mod.rs` →
/// `rest`; a crate root (`lib.rs`, `main.rs`) is the empty path.
fn module_of(source_root: &str, file: &str) -> String {
    let path = file.trim_start_matches(source_root).trim_start_matches('/').trim_end_matches(".rs");
    if path == "lib" || path == "main" {
        return String::new();
    }
    path.trim_end_matches("/mod").replace('/', "::")
}

/// The modules of the crate that `file` refers to: `crate::…` and `super::…`
/// paths, and in a `mod.rs` or crate root its children by name (`use child::…`).
/// `mod x;` declarations and re-exports (`pub use child::X;`, a folder's
/// interface) are not imports.
fn imports(source_root: &str, file: &str, modules: &BTreeSet<String>) -> BTreeSet<String> {
    let own = module_of(source_root, file);
    let own_segments: Vec<&str> = own.split("::").filter(|s| !s.is_empty()).collect();
    let is_folder = file.ends_with("mod.rs") || file.ends_with("lib.rs") || file.ends_with("main.rs");
    let code: String = code_of(file)
        .lines()
        .filter(|line| {
            !line.trim_start().trim_start_matches("pub(crate) ").trim_start_matches("pub ").starts_with("mod ")
        })
        .collect::<Vec<_>>()
        .join("\n");
    let code = without_reexports(&code);
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
            Some(_) if is_folder => own_segments.iter().chain(&segments).copied().collect(),
            _ => continue,
        };
        let target = (1..=path.len()).rev().map(|n| path[..n].join("::")).find(|m| modules.contains(m));
        out.extend(target.filter(|t| *t != own && !t.is_empty()));
    }
    out
}

/// `code` without its `pub use …;` and `pub(crate) use …;` statements.
fn without_reexports(code: &str) -> String {
    let mut out = String::new();
    let mut rest = code;
    while let Some(at) = rest.find("pub use ").into_iter().chain(rest.find("pub(crate) use ")).min() {
        out.push_str(&rest[..at]);
        rest = rest[at..].split_once(';').map_or("", |(_, after)| after);
    }
    out.push_str(rest);
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

/// The import graph of one crate's modules (the crate root excluded: it
/// declares and re-exports its children, which is not a dependency on them).
fn import_graph(source_root: &str) -> BTreeMap<String, BTreeSet<String>> {
    let files: Vec<String> = rust_files(source_root);
    let modules: BTreeSet<String> = files.iter().map(|f| module_of(source_root, f)).collect();
    files
        .iter()
        .map(|f| (module_of(source_root, f), imports(source_root, f, &modules)))
        .filter(|(module, _)| !module.is_empty())
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
fn no_two_modules_of_any_crate_import_each_other() {
    let server = import_graph("crates/server/src");
    assert!(server.len() > 30, "the graph should cover the server crate: {:?}", server.keys());
    assert!(server["grpc"].contains("request"), "the scanner should see `use crate::…`");
    let mut circles = Vec::new();
    for source_root in SOURCE_ROOTS {
        if let Some(cycle) = find_cycle(&import_graph(source_root)) {
            circles.push(format!("{source_root}: {}", cycle.join(" → ")));
        }
    }
    assert!(circles.is_empty(), "circles of imports:\n{}", circles.join("\n"));
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

/// The Markdown the project writes (the third-party READMEs copied beside
/// the example files are not ours): the top-level documents, the examples'
/// own and every page of docs/.
fn project_docs() -> Vec<String> {
    let mut out: Vec<String> = [
        "README.md",
        "ARCHITECTURE.md",
        "CONTRIBUTING.md",
        "BENCHMARKS.md",
        "RELIABILITY.md",
        "examples/SOURCES.md",
        "examples/clients/README.md",
    ]
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

/// A reader needs only the repository: the documents cite no contract they
/// do not have (`common::internal_contract_citations`) but the `docs/`
/// section that says it.
#[test]
fn no_document_cites_the_internal_spec() {
    let docs = project_docs();
    assert!(docs.len() >= 15, "README, ARCHITECTURE, CONTRIBUTING, BENCHMARKS, RELIABILITY and docs/: {docs:?}");
    let citing: Vec<_> = docs.into_iter().filter(|doc| !internal_contract_citations(&read(doc)).is_empty()).collect();
    assert!(citing.is_empty(), "these cite the internal contract; link the docs/ section instead: {citing:?}");
}

/// Code, tests, protos and examples cite the project's `docs/` too, never the
/// internal contract: a contributor reading a comment has the docs. The
/// SQL migrations are exempt: an applied migration is checksummed, so its
/// text (comments included) can never change.
#[test]
fn no_code_cites_the_internal_spec() {
    let mut files = Vec::new();
    for dir in ["src", "crates", "tests", "proto", "examples", "scripts", "bench", "deploy"] {
        let mut stack = vec![root().join(dir)];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).expect("read a folder") {
                let path = entry.expect("a folder entry").path();
                let name = path.file_name().unwrap().to_string_lossy().into_owned();
                if path.is_dir() && name != "migrations" && name != "target" && name != "node_modules" {
                    stack.push(path);
                } else if path.is_file()
                    && std::fs::read_to_string(&path).is_ok_and(|t| !internal_contract_citations(&t).is_empty())
                {
                    files.push(path.strip_prefix(root()).unwrap().display().to_string());
                }
            }
        }
    }
    assert!(files.is_empty(), "these cite the internal contract; cite the docs/ section instead: {files:?}");
}

/// Every relative link, with its `#anchor`, lands on a file and a heading that
/// exist, so the map's roads lead somewhere.
#[test]
fn every_link_in_the_documents_resolves() {
    let mut broken = Vec::new();
    for doc in project_docs() {
        let text = read(&doc);
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

/// The README and ARCHITECTURE.md are maps, not archives: short enough to read
/// in one sitting, the reference one link away in docs/.
#[test]
fn the_readme_and_the_architecture_stay_maps() {
    for (doc, limit) in [("README.md", 12 * 1024), ("ARCHITECTURE.md", 20 * 1024)] {
        let bytes = read(doc).len();
        assert!(bytes <= limit, "{doc} is {bytes} bytes, over {limit}: move reference material to docs/");
    }
    let readme = read("README.md");
    for section in ["## The two commands", "## Limits and non-goals"] {
        assert!(readme.lines().any(|l| l == section), "README.md lacks {section:?}");
    }
    for command in ["cargo run --release -- serve", "cargo test"] {
        let given = readme.lines().any(|l| l.starts_with(&format!("{command} ")));
        assert!(given, "README.md's two commands stay exactly as they are: {command}");
    }
}
