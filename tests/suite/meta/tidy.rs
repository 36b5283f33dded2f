//! The house rules, checked on every run by reading the source tree (no build products needed):
//!
//! - the model and ABI crates hold no `unsafe` and forbid it at their roots;
//! - the layer's OpenXR side (`src/xr/`) and Vulkan side (`src/vk/`) never import each other: they
//!   meet in the bridge;
//! - no `static mut` in any of the workspace's Rust sources;
//! - no import cycle between the layer crate's top-level modules;
//! - every `unsafe` block in the layer has a `SAFETY:` comment on the lines just above it;
//! - no comment cites a file a clone of the repository does not have, or an issue number.
//!
//! Each rule is a checker function over a file's path and text, tested below on small strings so
//! that each is seen to fail, then run over the tree. Comments and string literals are blanked out
//! before code is read, so a rule quoted in prose or in a string does not trip it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::support::{root, rust_files};

// ---------------------------------------------------------------------------------------------
// Reading Rust source.

/// A file's text split in two of the same length and line structure: `code` with comments and the
/// contents of string and character literals blanked, and `comments` with everything but comments
/// blanked.
struct Split {
    code: String,
    comments: String,
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

fn split(text: &str) -> Split {
    let s: Vec<char> = text.chars().collect();
    let mut code = String::with_capacity(text.len());
    let mut comments = String::with_capacity(text.len());
    // Pushes s[i] as code (`as_code`), comment (`as_comment`) or blank in each output.
    let mut push = |c: char, as_code: bool, as_comment: bool| {
        let blank = if c == '\n' { '\n' } else { ' ' };
        code.push(if as_code { c } else { blank });
        comments.push(if as_comment { c } else { blank });
    };
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        let next = s.get(i + 1).copied();
        let prev_ident = i > 0 && is_ident(s[i - 1]);
        if c == '/' && next == Some('/') {
            while i < s.len() && s[i] != '\n' {
                push(s[i], false, true);
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < s.len() {
                if s[i] == '/' && s.get(i + 1) == Some(&'*') {
                    depth += 1;
                    push('/', false, true);
                    push('*', false, true);
                    i += 2;
                } else if s[i] == '*' && s.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    push('*', false, true);
                    push('/', false, true);
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    push(s[i], false, true);
                    i += 1;
                }
            }
        } else if !prev_ident && raw_string_start(&s, i).is_some() {
            // r"..", r#".."#, br"..", cr"..": up to the quote and as many hashes.
            let (quote, hashes) = raw_string_start(&s, i).unwrap();
            while i <= quote {
                push(s[i], true, false);
                i += 1;
            }
            while i < s.len() {
                if s[i] == '"' && (1..=hashes).all(|h| s.get(i + h) == Some(&'#')) {
                    for _ in 0..=hashes {
                        push(s[i], true, false);
                        i += 1;
                    }
                    break;
                }
                push(s[i], false, false);
                i += 1;
            }
        } else if c == '"' {
            push(c, true, false);
            i += 1;
            while i < s.len() && s[i] != '"' {
                if s[i] == '\\' && i + 1 < s.len() {
                    push(s[i], false, false);
                    i += 1;
                }
                push(s[i], false, false);
                i += 1;
            }
            if i < s.len() {
                push('"', true, false);
                i += 1;
            }
        } else if c == '\'' && (next == Some('\\') || s.get(i + 2) == Some(&'\'')) {
            // A character literal ('x', '\n', '\''); anything else after a quote is a lifetime.
            push(c, true, false);
            i += 1;
            if s.get(i) == Some(&'\\') {
                push('\\', false, false);
                i += 1;
            }
            if i < s.len() {
                push(s[i], false, false);
                i += 1;
            }
            while i < s.len() && s[i] != '\'' && s[i] != '\n' {
                push(s[i], false, false);
                i += 1;
            }
            if s.get(i) == Some(&'\'') {
                push('\'', true, false);
                i += 1;
            }
        } else {
            push(c, true, false);
            i += 1;
        }
    }
    Split { code, comments }
}

/// Where a raw string literal starting at `i` has its opening quote, and its count of hashes.
fn raw_string_start(s: &[char], i: usize) -> Option<(usize, usize)> {
    let mut j = i;
    if matches!(s.get(j), Some('b') | Some('c')) {
        j += 1;
    }
    if s.get(j) != Some(&'r') {
        return None;
    }
    j += 1;
    let hashes = s[j..].iter().take_while(|&&c| c == '#').count();
    (s.get(j + hashes) == Some(&'"')).then_some((j + hashes, hashes))
}

/// The 1-based line of byte offset `at`.
fn line_of(text: &str, at: usize) -> usize {
    text[..at].matches('\n').count() + 1
}

/// The identifiers and keywords of `code`, with their byte offsets.
fn words(code: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut start = None;
    for (at, c) in code.char_indices().chain([(code.len(), ' ')]) {
        match (start, is_ident(c)) {
            (None, true) => start = Some(at),
            (Some(s), false) => {
                out.push((s, &code[s..at]));
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// The top-level modules a file of the layer names through `crate::` (or `$crate::` in a macro),
/// including each name of a `crate::{a::.., b::..}` group, with the line of each.
fn crate_references(text: &str) -> Vec<(String, usize)> {
    let code = split(text).code;
    let mut out = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| is_ident(c) || c == ':') {
            continue;
        }
        let line = line_of(&code, at);
        let rest = code[at + "crate::".len()..].trim_start();
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 0;
            let mut item_start = true;
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && is_ident(c) => {
                        let name: String =
                            group[i..].chars().take_while(|&c| is_ident(c)).collect();
                        out.push((name, line));
                        item_start = false;
                    }
                    c if !c.is_whitespace() => item_start = false,
                    _ => {}
                }
            }
        } else {
            let name: String = rest.chars().take_while(|&c| is_ident(c)).collect();
            if !name.is_empty() {
                out.push((name, line));
            }
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// The rules, each over one file's path (for messages) and text.

/// (a) `unsafe` anywhere in a crate that must have none.
fn unsafe_uses(path: &str, text: &str) -> Vec<String> {
    let code = split(text).code;
    words(&code)
        .into_iter()
        .filter(|(_, w)| *w == "unsafe")
        .map(|(at, _)| {
            format!(
                "{path}:{}: `unsafe` in a crate that must have none",
                line_of(&code, at)
            )
        })
        .collect()
}

/// (a) A crate root without `#![forbid(unsafe_code)]`.
fn missing_forbid_unsafe(path: &str, text: &str) -> Vec<String> {
    let code: String = split(text).code.split_whitespace().collect();
    if code.contains("#![forbid(unsafe_code)]") {
        Vec::new()
    } else {
        vec![format!(
            "{path}:1: the crate root lacks `#![forbid(unsafe_code)]`"
        )]
    }
}

/// (b) A file of one side of the layer naming the other side's module.
fn imports_of(path: &str, text: &str, forbidden: &str) -> Vec<String> {
    crate_references(text)
        .into_iter()
        .filter(|(m, _)| m == forbidden)
        .map(|(_, line)| {
            format!(
                "{path}:{line}: uses `crate::{forbidden}`; the OpenXR and Vulkan sides meet only \
                 in the bridge"
            )
        })
        .collect()
}

/// (c) `static mut`.
fn static_muts(path: &str, text: &str) -> Vec<String> {
    let code = split(text).code;
    let w = words(&code);
    w.windows(2)
        .filter(|p| p[0].1 == "static" && p[1].1 == "mut")
        .map(|p| {
            format!(
                "{path}:{}: `static mut` (use an atomic, a lock or a OnceLock)",
                line_of(&code, p[0].0)
            )
        })
        .collect()
}

/// (d) A cycle in a graph of modules, as the path around it (first node repeated at the end).
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|n| n == node) {
            let mut cycle = path[at..].to_vec();
            cycle.push(node.to_owned());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_owned());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(next, graph, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(node.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|n| visit(n, graph, &mut Vec::new(), &mut done))
}

/// (e) `unsafe {` blocks without a `SAFETY:` comment on the same line or in the comment lines just
/// above it.
fn unsafe_blocks_without_safety(path: &str, text: &str) -> Vec<String> {
    let Split { code, comments } = split(text);
    let code_lines: Vec<&str> = code.lines().collect();
    let comment_lines: Vec<&str> = comments.lines().collect();
    let mut out = Vec::new();
    for (at, w) in words(&code) {
        if w != "unsafe" || !code[at + w.len()..].trim_start().starts_with('{') {
            continue;
        }
        let line = line_of(&code, at) - 1;
        let mut documented = comment_lines[line].contains("SAFETY:");
        // Upwards through lines that hold only a comment.
        let mut l = line;
        while !documented && l > 0 && code_lines[l - 1].trim().is_empty() {
            l -= 1;
            if comment_lines[l].trim().is_empty() {
                break;
            }
            documented = comment_lines[l].contains("SAFETY:");
        }
        if !documented {
            out.push(format!(
                "{path}:{}: `unsafe` block without a `// SAFETY:` comment just above it",
                line + 1
            ));
        }
    }
    out
}

/// What comments must not cite: files that live outside the repository.
const OUTSIDE_FILES: [&str; 6] = [
    "shared/docs",
    "openxr-layer-facts.md",
    "vulkan-layer-facts.md",
    "headsets-and-numbers.md",
    "users-and-conventions.md",
    "prior-art.md",
];

/// (f) Comments citing a file outside the repository or an issue number (`issue #N`).
fn outside_citations(path: &str, text: &str) -> Vec<String> {
    let comments = split(text).comments;
    let mut out = Vec::new();
    for (n, line) in comments.lines().enumerate() {
        let lower = line.to_ascii_lowercase();
        for file in OUTSIDE_FILES {
            if lower.contains(file) {
                out.push(format!(
                    "{path}:{}: a comment cites `{file}`, which a clone does not have",
                    n + 1
                ));
            }
        }
        let issue = lower.match_indices("issue #").any(|(at, m)| {
            lower[at + m.len()..]
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_digit())
        });
        if issue {
            out.push(format!(
                "{path}:{}: a comment cites an issue number; say what it means instead",
                n + 1
            ));
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// The tree.

/// `path` relative to the repository's root, for messages.
fn shown(path: &Path) -> String {
    path.strip_prefix(root())
        .unwrap_or(path)
        .display()
        .to_string()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Runs `rule` over `files`; fails with every violation, one per line.
fn check(files: &[PathBuf], rule: impl Fn(&str, &str) -> Vec<String>) {
    assert!(!files.is_empty(), "no files to check");
    let found: Vec<String> = files
        .iter()
        .flat_map(|f| rule(&shown(f), &read(f)))
        .collect();
    assert!(
        found.is_empty(),
        "{} violation(s):\n{}",
        found.len(),
        found.join("\n")
    );
}

/// Every Rust file of the workspace (build output and hidden folders left out).
fn workspace_rust_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                if name != "target" && !name.starts_with('.') {
                    walk(&p, out);
                }
            } else if name.ends_with(".rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(&root(), &mut out);
    out.sort();
    out
}

/// The layer crate's top-level modules (folders and files under src/, not the root lib.rs) and,
/// for each, the others its files name through `crate::`, with one place that does.
fn module_graph() -> BTreeMap<String, BTreeMap<String, String>> {
    let src = root().join("src");
    let top_of = |f: &Path| -> Option<String> {
        let first = f.strip_prefix(&src).ok()?.components().next()?;
        let name = first.as_os_str().to_str()?;
        (name != "lib.rs").then(|| name.trim_end_matches(".rs").to_owned())
    };
    let files = rust_files(&src);
    let tops: BTreeSet<String> = files.iter().filter_map(|f| top_of(f)).collect();
    let mut graph: BTreeMap<String, BTreeMap<String, String>> =
        tops.iter().map(|t| (t.clone(), BTreeMap::new())).collect();
    for f in &files {
        let Some(from) = top_of(f) else { continue };
        for (to, line) in crate_references(&read(f)) {
            if to != from && tops.contains(&to) {
                graph
                    .get_mut(&from)
                    .unwrap()
                    .entry(to)
                    .or_insert_with(|| format!("{}:{line}", shown(f)));
            }
        }
    }
    graph
}

#[test]
fn the_model_and_abi_crates_have_no_unsafe() {
    for krate in ["crates/model", "crates/abi", "crates/config"] {
        let dir = root().join(krate);
        check(&rust_files(&dir), unsafe_uses);
        check(&[dir.join("src/lib.rs")], missing_forbid_unsafe);
    }
}

#[test]
fn the_openxr_and_vulkan_sides_do_not_import_each_other() {
    // The Vulkan side may not exist yet; the rule holds from its first file.
    let mut files = rust_files(&root().join("src/xr"));
    files.extend(rust_files(&root().join("src/vk")));
    check(&files, |p, t| {
        let other = if p.starts_with("src/xr/") { "vk" } else { "xr" };
        imports_of(p, t, other)
    });
}

#[test]
fn no_static_mut() {
    check(&workspace_rust_files(), static_muts);
}

#[test]
fn no_import_cycle_between_the_layers_top_level_modules() {
    let graph = module_graph();
    for expected in ["xr", "bridge", "gpu", "common"] {
        assert!(graph.contains_key(expected), "src/{expected} is missing");
    }
    let edges = graph
        .iter()
        .map(|(k, v)| (k.clone(), v.keys().cloned().collect()))
        .collect();
    if let Some(cycle) = find_cycle(&edges) {
        let evidence: Vec<String> = cycle
            .windows(2)
            .map(|p| format!("  {} -> {}: {}", p[0], p[1], graph[&p[0]][&p[1]]))
            .collect();
        panic!(
            "import cycle between the layer's top-level modules: {}\n{}",
            cycle.join(" -> "),
            evidence.join("\n")
        );
    }
}

#[test]
fn every_unsafe_block_says_why_it_is_sound() {
    check(
        &rust_files(&root().join("src")),
        unsafe_blocks_without_safety,
    );
}

#[test]
fn no_comment_cites_outside_files_or_issue_numbers() {
    let mut files = workspace_rust_files();
    files.extend(
        std::fs::read_dir(root().join("include"))
            .unwrap()
            .map(|e| e.unwrap().path()),
    );
    check(&files, outside_citations);
}

// ---------------------------------------------------------------------------------------------
// Each checker, seen to fail and to pass.

#[test]
fn split_blanks_comments_and_literals_and_keeps_lines() {
    let text = "let a = \"unsafe { }\"; // unsafe\n/* static mut\n /* nested */ x */ let b = 'u';\nlet r = r#\"static mut \"# ; fn f<'a>(x: &'a u8) {}\n";
    let s = split(text);
    assert_eq!(s.code.len(), text.len());
    assert_eq!(s.code.lines().count(), text.lines().count());
    assert!(!s.code.contains("unsafe") && !s.code.contains("static"));
    assert!(s.code.contains("let b = ' ';"), "{}", s.code);
    assert!(s.code.contains("fn f<'a>(x: &'a u8)"), "{}", s.code);
    assert!(s.comments.contains("// unsafe") && s.comments.contains("x */"));
    assert!(!s.comments.contains("let"));
}

#[test]
fn unsafe_is_found_in_code_only() {
    assert_eq!(
        unsafe_uses("m.rs", "fn f() {}\nfn g() { unsafe { h() } }\n"),
        ["m.rs:2: `unsafe` in a crate that must have none"]
    );
    assert!(unsafe_uses(
        "m.rs",
        "// unsafe\nlet s = \"unsafe\"; let unsafe_code = 1;\n"
    )
    .is_empty());
    assert_eq!(missing_forbid_unsafe("lib.rs", "//! doc\n").len(), 1);
    assert_eq!(
        missing_forbid_unsafe("lib.rs", "// #![forbid(unsafe_code)]\n").len(),
        1
    );
    assert!(missing_forbid_unsafe("lib.rs", "//! doc\n#![forbid(unsafe_code)]\n").is_empty());
}

#[test]
fn crate_references_name_top_level_modules() {
    let text = "use crate::common::lock;\nuse crate::{\n    bridge::Map,\n    gpu::{self, Up},\n};\n\
                // crate::vk in a comment\nlet s = \"crate::vk\";\nfoo::crate::x; $crate::xr::y!();\n";
    assert_eq!(
        crate_references(text),
        [
            ("common".to_owned(), 1),
            ("bridge".to_owned(), 2),
            ("gpu".to_owned(), 2),
            ("xr".to_owned(), 8)
        ]
    );
    assert_eq!(
        imports_of("src/xr/a.rs", "fn f() {}\nuse crate::vk::Device;\n", "vk"),
        ["src/xr/a.rs:2: uses `crate::vk`; the OpenXR and Vulkan sides meet only in the bridge"]
    );
    assert!(imports_of("src/xr/a.rs", "use crate::vkx::A;\n// crate::vk\n", "vk").is_empty());
}

#[test]
fn static_mut_is_found() {
    assert_eq!(
        static_muts("a.rs", "static A: u8 = 0;\nstatic\n  mut B: u8 = 0;\n"),
        ["a.rs:2: `static mut` (use an atomic, a lock or a OnceLock)"]
    );
    assert!(static_muts("a.rs", "// static mut\nlet s = \"static mut\";\n").is_empty());
}

#[test]
fn cycles_are_found() {
    let graph = |edges: &[(&str, &str)]| {
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in edges {
            g.entry(a.to_string()).or_default().insert(b.to_string());
            g.entry(b.to_string()).or_default();
        }
        g
    };
    // Today's intended layering.
    let layered = graph(&[
        ("xr", "common"),
        ("xr", "bridge"),
        ("xr", "gpu"),
        ("gpu", "common"),
        ("gpu", "bridge"),
        ("bridge", "common"),
    ]);
    assert_eq!(find_cycle(&layered), None);
    let cyclic = graph(&[
        ("xr", "gpu"),
        ("gpu", "bridge"),
        ("bridge", "xr"),
        ("bridge", "common"),
    ]);
    assert_eq!(
        find_cycle(&cyclic).unwrap(),
        ["bridge", "xr", "gpu", "bridge"]
    );
    assert!(find_cycle(&graph(&[("a", "a")])).is_some());
}

#[test]
fn unsafe_blocks_need_a_safety_comment_just_above() {
    let ok = "// SAFETY: p is valid.\nlet a = unsafe { *p };\n\
              // SAFETY: two lines\n// of reasons.\nunsafe {\n    f();\n}\n\
              let b = unsafe { g() }; // SAFETY: same line.\n\
              unsafe fn h() {}\n";
    assert_eq!(
        unsafe_blocks_without_safety("a.rs", ok),
        Vec::<String>::new()
    );
    let bad = "// SAFETY: for the first.\nlet a = unsafe { *p };\nlet b = unsafe { *q };\n\
               // SAFETY: too far up.\n\nunsafe { f() }\n// a comment, but not why\nunsafe { g() }\n";
    assert_eq!(
        unsafe_blocks_without_safety("a.rs", bad),
        [
            "a.rs:3: `unsafe` block without a `// SAFETY:` comment just above it",
            "a.rs:6: `unsafe` block without a `// SAFETY:` comment just above it",
            "a.rs:8: `unsafe` block without a `// SAFETY:` comment just above it",
        ]
    );
}

#[test]
fn citations_of_outside_files_and_issues_are_found() {
    let text = "//! See the facts (openxr-layer-facts.md §2).\nlet a = 1; // as issue #12 asks\n\
                /* ../shared/docs/x */\nlet s = \"prior-art.md issue #3\";\n// an issue with #s, issue 4\n";
    assert_eq!(
        outside_citations("a.rs", text),
        [
            "a.rs:1: a comment cites `openxr-layer-facts.md`, which a clone does not have",
            "a.rs:2: a comment cites an issue number; say what it means instead",
            "a.rs:3: a comment cites `shared/docs`, which a clone does not have",
        ]
    );
}
