//! The documents' commands and links, checked against the tree on every run, so that what
//! `README.md` and `docs/*.md` tell a reader to type keeps working as the code moves
//! (docs/testing.md#the-documents-commands):
//!
//! - in every ```` ```sh ````/```` ```bash ```` block, each `cargo test`, `cargo bench` and `cargo run`
//!   command's `--test`, `--bench` and `--example` targets exist in the packages it selects, and each
//!   of a `cargo test`'s name filters is a substring of at least one test path (`module::fn`) in
//!   those targets, read from their sources;
//! - every relative link (Markdown or `<img src>`) names a file that exists, and a link into a
//!   Markdown file with a `#fragment` names one of its headings; so does every file of this
//!   repository named in inline code (`src/vk/convert.rs`: a path starting in one of its folders);
//! - every Rust item path named in inline code (`bridge::inject::generation`, `Session::eyes`,
//!   `crate::common::guard`, a test module `xr::gaze`) is declared in the workspace's sources, and
//!   an item named beside a file (`` `src/x.rs` (`item`) ``, `` `item` in `x.rs` ``) is in that
//!   file;
//! - `docs/README.md` links every other document;
//! - blocks marked ```` ```sh runnable ```` run, with `cargo run [--release] [-q] --` replaced by
//!   the `fovea` binary of this build, in a temporary folder with its own XDG folders: quick,
//!   hermetic commands only.
//!
//! Test paths are read from source rather than from `cargo test -- --list`: building every target
//! to list it would take minutes, and a name filter is a substring of `module::fn` either way.
//! Every `fn` counts, so a helper's name passes as a filter: the check catches names that no
//! longer exist anywhere, which is how documents go stale.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::support::{root, run_with_timeout, rust_files};

// ---------------------------------------------------------------------------------------------
// Markdown.

/// A fenced code block: its info string (`sh runnable`), the line its fence opens on, its text.
#[derive(Debug)]
struct Block {
    info: String,
    line: usize,
    body: String,
}

/// The fenced blocks of a Markdown text; fences may be indented (inside list items), and a
/// block's lines lose the fence's indentation.
fn blocks(md: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut open: Option<(usize, String, usize, String)> = None; // indent, fence, line, info
    let mut body = String::new();
    for (n, line) in md.lines().enumerate() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        match &open {
            None => {
                let ticks = trimmed.chars().take_while(|&c| c == '`').count();
                if ticks >= 3 {
                    let fence = "`".repeat(ticks);
                    let info = trimmed[ticks..].trim().to_owned();
                    open = Some((indent, fence, n + 1, info));
                    body.clear();
                }
            }
            Some((ind, fence, start, info)) => {
                if trimmed.starts_with(fence.as_str()) && trimmed.trim_end() == fence.as_str() {
                    out.push(Block {
                        info: info.clone(),
                        line: *start,
                        body: std::mem::take(&mut body),
                    });
                    open = None;
                } else {
                    let cut = indent.min(*ind);
                    body.push_str(&line[cut..]);
                    body.push('\n');
                }
            }
        }
    }
    out
}

fn is_shell(info: &str) -> bool {
    matches!(
        info.split_whitespace().next(),
        Some("sh" | "bash" | "shell")
    )
}

fn is_runnable(info: &str) -> bool {
    is_shell(info) && info.split_whitespace().any(|w| w == "runnable")
}

/// The text outside fenced blocks and inline code spans (where links are read).
fn prose(md: &str) -> String {
    let mut out = String::new();
    let mut fence: Option<String> = None;
    for line in md.lines() {
        let trimmed = line.trim_start();
        let ticks = trimmed.chars().take_while(|&c| c == '`').count();
        match &fence {
            Some(f) => {
                if trimmed.trim_end() == f.as_str() {
                    fence = None;
                }
                out.push('\n');
                continue;
            }
            None if ticks >= 3 => {
                fence = Some("`".repeat(ticks));
                out.push('\n');
                continue;
            }
            None => {}
        }
        // Inline code spans: a run of n backticks up to the next run of n.
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            if chars[i] == '`' {
                let n = chars[i..].iter().take_while(|&&c| c == '`').count();
                let mut j = i + n;
                let mut closed = None;
                while j < chars.len() {
                    if chars[j] == '`' {
                        let m = chars[j..].iter().take_while(|&&c| c == '`').count();
                        if m == n {
                            closed = Some(j + m);
                            break;
                        }
                        j += m;
                    } else {
                        j += 1;
                    }
                }
                match closed {
                    Some(end) => i = end,
                    None => {
                        out.extend(&chars[i..i + n]);
                        i += n;
                    }
                }
            } else {
                out.push(chars[i]);
                i += 1;
            }
        }
        out.push('\n');
    }
    out
}

/// The targets of a text's links: `](target)` and `src="target"`, titles dropped.
fn links(md: &str) -> Vec<String> {
    let text = prose(md);
    let mut out = Vec::new();
    for (start, end) in [("](", ')'), ("src=\"", '"')] {
        let mut rest = text.as_str();
        while let Some(i) = rest.find(start) {
            rest = &rest[i + start.len()..];
            if let Some(j) = rest.find(end) {
                let target = rest[..j].split_whitespace().next().unwrap_or("");
                let target = target.trim_start_matches('<').trim_end_matches('>');
                out.push(target.to_owned());
                rest = &rest[j..];
            }
        }
    }
    out
}

/// The inline code spans of a text outside its fenced blocks that name a file of this repository:
/// a path whose first two components are a folder here (`src/vk/convert.rs`,
/// `tests/suite/hello_xr.rs`), outside `target/`. Paths of other projects quoted in the documents (Mesa's
/// `src/amd/…`, the loader's `src/loader/`) do not start in such a folder and are left alone.
fn repository_paths(root: &Path, md: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_fence = false;
    for line in md.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        for (i, span) in line.split('`').enumerate() {
            let plain = !span.contains(|c: char| c.is_whitespace() || "*{}…<>$,;".contains(c));
            if i % 2 == 0 || !plain || span.contains("NNN") {
                continue;
            }
            let path = span.split(['#', ':']).next().unwrap_or("");
            let mut parts = path.split('/');
            let (Some(a), Some(b)) = (parts.next(), parts.next()) else {
                continue;
            };
            // `target/` holds build outputs, which a fresh checkout does not have.
            if !a.is_empty() && !b.is_empty() && a != "target" && root.join(a).join(b).is_dir() {
                out.push(path.to_owned());
            }
        }
    }
    out
}

/// GitHub's anchor for a heading: lower case, punctuation but `-` and `_` dropped, spaces to `-`.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|&c| c.is_alphanumeric() || c == '-' || c == '_' || c == ' ')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a Markdown text's headings (outside fenced blocks), repeated ones numbered as
/// GitHub numbers them.
fn anchors(md: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    let mut in_fence = false;
    for line in md.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        let Some(h) = line.strip_prefix('#').filter(|_| !in_fence) else {
            continue;
        };
        let h = h.trim_start_matches('#');
        if !h.starts_with(' ') {
            continue;
        }
        let a = anchor(h);
        let n = seen.entry(a.clone()).or_insert(0);
        out.insert(if *n == 0 {
            a.clone()
        } else {
            format!("{a}-{n}")
        });
        *n += 1;
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Shell.

/// A block's simple commands, as words: `\` continuations joined, comments dropped, split at
/// `&&`, `||`, `;` and `|`. Quotes are kept out of the words; nothing is expanded.
fn commands(body: &str) -> Vec<Vec<String>> {
    let joined = body.replace("\\\n", " ");
    let mut out = Vec::new();
    for line in joined.lines() {
        let mut words: Vec<String> = Vec::new();
        let mut word = String::new();
        let mut in_word = false;
        let mut quote: Option<char> = None;
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        let flush = |words: &mut Vec<String>, word: &mut String, in_word: &mut bool| {
            if *in_word {
                words.push(std::mem::take(word));
                *in_word = false;
            }
        };
        while i < chars.len() {
            let c = chars[i];
            if let Some(q) = quote {
                if c == q {
                    quote = None;
                } else {
                    word.push(c);
                }
                i += 1;
                continue;
            }
            match c {
                '\'' | '"' => {
                    quote = Some(c);
                    in_word = true;
                }
                '#' if !in_word => break,
                ' ' | '\t' => flush(&mut words, &mut word, &mut in_word),
                ';' | '|' | '&' => {
                    flush(&mut words, &mut word, &mut in_word);
                    if !words.is_empty() {
                        out.push(std::mem::take(&mut words));
                    }
                    while i + 1 < chars.len() && matches!(chars[i + 1], '|' | '&') {
                        i += 1;
                    }
                }
                _ => {
                    word.push(c);
                    in_word = true;
                }
            }
            i += 1;
        }
        flush(&mut words, &mut word, &mut in_word);
        if !words.is_empty() {
            out.push(words);
        }
    }
    out
}

/// What a `cargo test`, `cargo bench` or `cargo run` command selects.
#[derive(Debug, Default)]
struct Cargo {
    sub: String,
    packages: Vec<String>,
    workspace: bool,
    tests: Vec<String>,
    benches: Vec<String>,
    examples: Vec<String>,
    lib: bool,
    filters: Vec<String>,
    exact: bool,
}

/// Cargo's options that take a value (the value is the next word unless given with `=`).
const CARGO_VALUED: &[&str] = &[
    "-p",
    "--package",
    "--test",
    "--bench",
    "--example",
    "--bin",
    "-F",
    "--features",
    "--target",
    "--profile",
    "--manifest-path",
    "-j",
    "--jobs",
    "--message-format",
    "--color",
    "--target-dir",
    "--exclude",
    "-Z",
    "--config",
];

/// libtest's and criterion's options that take a value.
const HARNESS_VALUED: &[&str] = &[
    "--skip",
    "--test-threads",
    "--format",
    "--color",
    "--logfile",
    "-Z",
    "--warm-up-time",
    "--measurement-time",
    "--sample-size",
    "--save-baseline",
    "--baseline",
];

/// The cargo command in a simple command's words (after any `VAR=value`, `sudo` or wrapper such
/// as `.ci/trixie`), when it is `cargo test`, `cargo bench` or `cargo run`.
fn parse_cargo(words: &[String]) -> Option<Cargo> {
    let at = words.iter().position(|w| w == "cargo")?;
    let mut args = words[at + 1..].iter().filter(|w| !w.starts_with('+'));
    let sub = args.next()?.clone();
    if !matches!(sub.as_str(), "test" | "bench" | "run") {
        return None;
    }
    let mut c = Cargo {
        sub,
        ..Cargo::default()
    };
    let mut after_dashes = false;
    while let Some(w) = args.next() {
        if !after_dashes {
            if w == "--" {
                after_dashes = true;
                continue;
            }
            let (name, inline) = match w.split_once('=') {
                Some((n, v)) if n.starts_with('-') => (n, Some(v.to_owned())),
                _ => (w.as_str(), None),
            };
            if CARGO_VALUED.contains(&name) {
                let value = inline.or_else(|| args.next().cloned()).unwrap_or_default();
                match name {
                    "-p" | "--package" => c.packages.push(value),
                    "--test" => c.tests.push(value),
                    "--bench" => c.benches.push(value),
                    "--example" => c.examples.push(value),
                    _ => {}
                }
            } else if name == "--workspace" || name == "--all" {
                c.workspace = true;
            } else if name == "--lib" {
                c.lib = true;
            } else if !w.starts_with('-') && c.sub == "test" {
                c.filters.push(w.clone());
            }
        } else if c.sub == "test" {
            if HARNESS_VALUED.contains(&w.as_str()) {
                args.next();
            } else if w == "--exact" {
                c.exact = true;
            } else if !w.starts_with('-') {
                c.filters.push(w.clone());
            }
        }
        // After `--`, `cargo bench` and `cargo run` pass criterion's or the binary's own arguments.
    }
    Some(c)
}

// ---------------------------------------------------------------------------------------------
// The workspace.

/// The workspace's packages (name → folder) and its default members, from the Cargo.toml files.
struct Workspace {
    packages: BTreeMap<String, PathBuf>,
    defaults: Vec<String>,
}

/// The quoted strings of a TOML array `key = [ ... ]`.
fn toml_array(toml: &str, key: &str) -> Option<Vec<String>> {
    let start = toml
        .lines()
        .scan(0, |at, l| {
            let here = *at;
            *at += l.len() + 1;
            Some((here, l))
        })
        .find(|(_, l)| l.trim_start().starts_with(&format!("{key} =")))?
        .0;
    let rest = &toml[start..];
    let list = &rest[rest.find('[')? + 1..rest.find(']')?];
    Some(
        list.split(',')
            .map(|s| s.trim().trim_matches('"').to_owned())
            .filter(|s| !s.is_empty())
            .collect(),
    )
}

fn package_name(toml: &str) -> Option<String> {
    let after = &toml[toml.find("[package]")?..];
    let line = after
        .lines()
        .find(|l| l.trim_start().starts_with("name ="))?;
    Some(line.split('"').nth(1)?.to_owned())
}

impl Workspace {
    fn read(root: &Path) -> Workspace {
        let toml = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
        let members = toml_array(&toml, "members").expect("workspace members");
        let mut packages = BTreeMap::new();
        let mut by_dir = BTreeMap::new();
        for m in &members {
            let dir = root.join(m);
            let text = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
            let name = package_name(&text).unwrap_or_else(|| panic!("no package name in {m}"));
            by_dir.insert(m.clone(), name.clone());
            packages.insert(name, dir);
        }
        let defaults = toml_array(&toml, "default-members")
            .unwrap_or_else(|| vec![".".to_owned()])
            .iter()
            .map(|m| by_dir[m].clone())
            .collect();
        Workspace { packages, defaults }
    }

    /// The package folders a command selects, or the names it gets wrong.
    fn selected(&self, c: &Cargo) -> Result<Vec<PathBuf>, String> {
        let names: Vec<String> = if !c.packages.is_empty() {
            c.packages.clone()
        } else if c.workspace {
            self.packages.keys().cloned().collect()
        } else {
            self.defaults.clone()
        };
        names
            .iter()
            .map(|n| {
                self.packages
                    .get(n)
                    .cloned()
                    .ok_or_else(|| format!("no package `{n}` in the workspace"))
            })
            .collect()
    }
}

/// A target of a package: its root file and the source files (with their module paths) it holds.
fn target(dir: &Path, kind: &str, name: &str) -> Option<Vec<(PathBuf, Vec<String>)>> {
    let file = dir.join(kind).join(format!("{name}.rs"));
    let folder = dir.join(kind).join(name);
    if folder.join("main.rs").is_file() {
        return Some(modules_under(&folder));
    }
    if file.is_file() {
        let mut out = vec![(file, Vec::new())];
        if folder.is_dir() {
            out.extend(modules_under(&folder));
        }
        return Some(out);
    }
    None
}

/// Every Rust file under `dir` with its module path relative to `dir` (`main.rs`, `lib.rs` and
/// `mod.rs` name their folder).
fn modules_under(dir: &Path) -> Vec<(PathBuf, Vec<String>)> {
    rust_files(dir)
        .into_iter()
        .map(|f| {
            let rel = f.strip_prefix(dir).unwrap().with_extension("");
            let mut path: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if matches!(
                path.last().map(String::as_str),
                Some("mod" | "main" | "lib")
            ) {
                path.pop();
            }
            (f, path)
        })
        .collect()
}

/// Every source file of a package that `cargo test` without target options runs tests from.
fn all_targets(dir: &Path) -> Vec<(PathBuf, Vec<String>)> {
    let mut out = modules_under(&dir.join("src"));
    for kind in ["tests", "examples"] {
        let Ok(entries) = std::fs::read_dir(dir.join(kind)) else {
            continue;
        };
        let mut names: Vec<String> = entries
            .filter_map(|e| {
                let p = e.ok()?.path();
                let stem = p.file_stem()?.to_string_lossy().into_owned();
                (p.is_dir() || p.extension().is_some_and(|x| x == "rs")).then_some(stem)
            })
            .collect();
        names.sort();
        names.dedup();
        for n in names {
            out.extend(target(dir, kind, &n).unwrap_or_default());
        }
    }
    out
}

/// A Rust text with comments and the insides of string and character literals blanked, so that
/// braces and `fn` in them are not read as code.
fn code_only(text: &str) -> String {
    let s: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        let next = s.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < s.len() && s[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < s.len() {
                if s[i] == '/' && s.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if s[i] == '*' && s.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if c == 'r'
            && (next == Some('"') || next == Some('#'))
            && (i == 0 || !(s[i - 1].is_alphanumeric() || s[i - 1] == '_'))
        {
            // A raw string: r"…" or r#"…"#.
            let hashes = s[i + 1..].iter().take_while(|&&c| c == '#').count();
            if s.get(i + 1 + hashes) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            i += 2 + hashes;
            let close: String = std::iter::once('"')
                .chain(std::iter::repeat_n('#', hashes))
                .collect();
            let close: Vec<char> = close.chars().collect();
            while i < s.len() && !s[i..].starts_with(&close) {
                i += 1;
            }
            i += close.len();
            out.push_str("\"\"");
        } else if c == '"' {
            i += 1;
            while i < s.len() && s[i] != '"' {
                i += if s[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if c == '\''
            && (s.get(i + 2) == Some(&'\'') || (next == Some('\\') && s.len() > i + 3))
        {
            // A character literal ('x' or '\n', '\u{…}'); a lifetime has no closing quote.
            i += 1;
            while i < s.len() && s[i] != '\'' {
                i += if s[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("' '");
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// The paths (`module::inner::fn`) of every function in a file whose module path is `module`,
/// inline `mod name { … }` blocks included.
fn fn_paths(text: &str, module: &[String]) -> Vec<String> {
    let code = code_only(text);
    let words: Vec<&str> = code
        .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == '{' || c == '}' || c == ';'))
        .flat_map(split_braces)
        .filter(|w| !w.is_empty())
        .collect();
    let mut out = Vec::new();
    let mut depth = 0usize;
    let mut stack: Vec<(String, usize)> = Vec::new();
    let mut pending_mod: Option<String> = None;
    let mut i = 0;
    while i < words.len() {
        match words[i] {
            "{" => {
                depth += 1;
                if let Some(m) = pending_mod.take() {
                    stack.push((m, depth));
                }
            }
            "}" => {
                if stack.last().is_some_and(|(_, d)| *d == depth) {
                    stack.pop();
                }
                depth = depth.saturating_sub(1);
            }
            ";" => pending_mod = None,
            "mod" if i + 1 < words.len() => {
                pending_mod = Some(words[i + 1].to_owned());
                i += 1;
            }
            "fn" if i + 1 < words.len() => {
                let mut path: Vec<&str> = module.iter().map(String::as_str).collect();
                path.extend(stack.iter().map(|(m, _)| m.as_str()));
                path.push(words[i + 1]);
                out.push(path.join("::"));
                i += 1;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Splits a word so that each brace and semicolon stands alone.
fn split_braces(w: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, c) in w.char_indices() {
        if matches!(c, '{' | '}' | ';') {
            out.push(&w[start..i]);
            out.push(&w[i..i + 1]);
            start = i + 1;
        }
    }
    out.push(&w[start..]);
    out
}

// ---------------------------------------------------------------------------------------------
// The checks.

/// What is wrong with one cargo command, as problem lines.
fn check_cargo(ws: &Workspace, c: &Cargo) -> Vec<String> {
    let dirs = match ws.selected(c) {
        Ok(d) => d,
        Err(e) => return vec![e],
    };
    let mut problems = Vec::new();
    let mut sources: Vec<(PathBuf, Vec<String>)> = Vec::new();
    for (kind, names) in [
        ("tests", &c.tests),
        ("benches", &c.benches),
        ("examples", &c.examples),
    ] {
        for n in names {
            let found: Vec<_> = dirs.iter().filter_map(|d| target(d, kind, n)).collect();
            if found.is_empty() {
                let flag = &kind[..kind.len() - if kind == "benches" { 2 } else { 1 }];
                problems.push(format!(
                    "no {kind} target `{n}` (`--{flag} {n}`) in the selected packages"
                ));
            }
            sources.extend(found.into_iter().flatten());
        }
    }
    if c.lib {
        for d in &dirs {
            sources.extend(modules_under(&d.join("src")));
        }
    }
    if c.filters.is_empty() || c.sub != "test" {
        return problems;
    }
    if c.tests.is_empty() && c.examples.is_empty() && c.benches.is_empty() && !c.lib {
        for d in &dirs {
            sources.extend(all_targets(d));
        }
    }
    let mut paths = Vec::new();
    for (file, module) in &sources {
        let text = std::fs::read_to_string(file).unwrap();
        paths.extend(fn_paths(&text, module));
    }
    for f in &c.filters {
        let hit = paths.iter().any(|p| {
            if c.exact {
                p == f
            } else {
                p.contains(f.as_str())
            }
        });
        if !hit {
            problems.push(format!(
                "the filter `{f}` matches no test path (`module::fn`) in the selected targets"
            ));
        }
    }
    problems
}

// ---------------------------------------------------------------------------------------------
// Rust items named in the documents.

/// Crates of other projects whose paths the documents quote (`std::env::var`, `ash::vk::Device`):
/// not looked up.
const OUTSIDE_CRATES: &[&str] = &[
    "std",
    "core",
    "alloc",
    "ash",
    "openxr",
    "openxr_sys",
    "tracing",
    "tracing_subscriber",
    "toml",
    "serde_json",
    "glam",
    "proptest",
    "criterion",
    "libc",
    "libloading",
    "png",
];

/// Types of other projects the documents name with a member (`Arc::drop_slow`); OpenXR's `Xr…`
/// and Vulkan's `Vk…` are recognised by their prefix.
const OUTSIDE_TYPES: &[&str] = &["Arc", "QCoreApplication"];

/// What this repository's Rust sources declare, for looking up the item paths the documents name.
struct Items {
    /// Every path an item or module can be named by, and each suffix of it
    /// (`fovea::xr::gaze::used`, `xr::gaze::used`, `gaze::used`, `used`).
    paths: BTreeSet<String>,
    /// Each type (struct, enum, trait, union, type alias) with the words of the files that declare
    /// or implement it, where its members are.
    types: BTreeMap<String, BTreeSet<String>>,
    /// Every string literal that looks like a path (`"fovea::stats"`, a log target).
    literals: BTreeSet<String>,
}

/// Each Rust source root of the workspace with the module path its files start from: the
/// packages' `src` (named as their crate), `tests/`, `benches/` and `examples/` (named as their
/// targets, `tests/suite/xr/gaze.rs` is `suite::xr::gaze`).
fn source_roots(root: &Path) -> Vec<(PathBuf, Vec<String>)> {
    let ws = Workspace::read(root);
    let mut out = Vec::new();
    for (name, dir) in &ws.packages {
        let krate = name.replace('-', "_");
        out.push((dir.join("src"), vec![krate]));
        for kind in ["tests", "benches", "examples"] {
            let Ok(entries) = std::fs::read_dir(dir.join(kind)) else {
                continue;
            };
            for e in entries.flatten() {
                let p = e.path();
                let Some(stem) = p.file_stem().map(|s| s.to_string_lossy().into_owned()) else {
                    continue;
                };
                if p.is_dir() || p.extension().is_some_and(|x| x == "rs") {
                    out.push((p, vec![stem]));
                }
            }
        }
    }
    out
}

impl Items {
    fn read(root: &Path) -> Items {
        let mut items = Items {
            paths: BTreeSet::new(),
            types: BTreeMap::new(),
            literals: BTreeSet::new(),
        };
        for (dir, base) in source_roots(root) {
            let files = if dir.is_file() {
                vec![(dir.clone(), Vec::new())]
            } else {
                modules_under(&dir)
            };
            for (file, module) in files {
                let text = std::fs::read_to_string(&file).unwrap();
                let module: Vec<String> = base.iter().cloned().chain(module).collect();
                items.add_file(&text, &module);
            }
        }
        items
    }

    fn add_path(&mut self, path: &[String]) {
        for i in 0..path.len() {
            self.paths.insert(path[i..].join("::"));
        }
    }

    fn add_file(&mut self, text: &str, module: &[String]) {
        for lit in text.split('"').skip(1).step_by(2) {
            if lit.contains("::") && lit.chars().all(|c| c.is_alphanumeric() || "_:".contains(c)) {
                self.literals.insert(lit.to_owned());
            }
        }
        let code = code_only(text);
        let words: Vec<&str> = code
            .split(|c: char| !(c.is_alphanumeric() || "_;!{}".contains(c)))
            .flat_map(split_braces)
            .filter(|w| !w.is_empty())
            .collect();
        let file_words: BTreeSet<String> = words
            .iter()
            .map(|w| w.trim_end_matches('!').to_owned())
            .collect();
        self.add_path(module);
        // Inline modules (`mod check { .. }`) open with their brace and close with it.
        let mut depth = 0usize;
        let mut stack: Vec<(String, usize)> = Vec::new();
        let mut pending_mod: Option<String> = None;
        let mut in_use = false;
        for (i, w) in words.iter().enumerate() {
            let here = || -> Vec<String> {
                let mut m = module.to_vec();
                m.extend(stack.iter().map(|(n, _)| n.clone()));
                m
            };
            let next = words.get(i + 1).copied();
            match *w {
                "{" => {
                    depth += 1;
                    if let Some(m) = pending_mod.take() {
                        stack.push((m, depth));
                    }
                }
                "}" => {
                    if stack.last().is_some_and(|(_, d)| *d == depth) {
                        stack.pop();
                    }
                    depth = depth.saturating_sub(1);
                }
                ";" => {
                    pending_mod = None;
                    in_use = false;
                }
                "use" => in_use = true,
                // What a `use` brings in is named from here too (re-exports).
                _ if in_use && !matches!(*w, "self" | "crate" | "super" | "as") => {
                    let path = [here(), vec![(*w).to_owned()]].concat();
                    self.add_path(&path);
                }
                _ if in_use => {}
                "fn" | "struct" | "enum" | "trait" | "type" | "const" | "static" | "mod"
                | "union" | "macro_rules!" => {
                    let Some(name) =
                        next.filter(|n| n.starts_with(|c: char| c.is_alphabetic() || c == '_'))
                    else {
                        continue;
                    };
                    let path = [here(), vec![name.to_owned()]].concat();
                    self.add_path(&path);
                    if *w == "mod" {
                        pending_mod = Some(name.to_owned());
                    }
                    if matches!(*w, "struct" | "enum" | "trait" | "type" | "union") {
                        self.types
                            .entry(name.to_owned())
                            .or_default()
                            .extend(file_words.iter().cloned());
                    }
                }
                "impl" => {
                    // `impl<T> Trait for Type`, `impl Type`: the type's members are in this file.
                    for (j, t) in words.iter().enumerate().skip(i + 1).take(8) {
                        if matches!(*t, "{" | ";" | "where") {
                            break;
                        }
                        if t.starts_with(char::is_uppercase) && words.get(j + 1) != Some(&"for") {
                            self.types
                                .entry((*t).to_owned())
                                .or_default()
                                .extend(file_words.iter().cloned());
                        }
                    }
                }
                _ => {}
            }
        }
    }

    /// Why `path` (`hooks::frame::wait_frame`, `Session::eyes`, `xr::foveation::MapKey`) names
    /// nothing here; `None` when it does, or when it is another project's.
    fn missing(&self, path: &str) -> Option<String> {
        let parts: Vec<&str> = path.trim_start_matches("crate::").split("::").collect();
        let first = parts[0];
        if self.literals.contains(path) || OUTSIDE_CRATES.contains(&first) {
            return None;
        }
        let is_type = |p: &str| p.starts_with(char::is_uppercase) && p.contains(char::is_lowercase);
        // The part up to the first type, and the type's member after it.
        let (module, member) = match parts.iter().position(|p| is_type(p)) {
            Some(t) => (&parts[..=t], parts.get(t + 1).copied()),
            None => (&parts[..], None),
        };
        let ty = module.last().copied().filter(|p| is_type(p));
        let outside =
            first.starts_with("Xr") || first.starts_with("Vk") || OUTSIDE_TYPES.contains(&first);
        if module.len() == 1 && ty.is_some() && outside {
            return None;
        }
        let joined = module.join("::");
        let found = if module.len() == 1 && ty.is_some() {
            self.types.contains_key(first)
        } else {
            self.paths.contains(&joined)
        };
        if !found {
            return Some(format!("`{joined}` is declared nowhere"));
        }
        match (ty, member) {
            (Some(t), Some(m)) => {
                let known = self.types.get(t).is_some_and(|words| words.contains(m));
                (!known).then(|| format!("`{t}` has no `{m}`"))
            }
            _ => None,
        }
    }
}

/// The Rust item paths a Markdown text names in inline code outside fenced blocks: spans of
/// identifiers joined by `::` (`common::guard`, `Session::eyes`, `foveation::MapKey`), a trailing
/// call (`()`, `(index, key)`) dropped and a trailing group (`Registry::{instances, sessions}`)
/// expanded.
fn item_paths(md: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_fence = false;
    for line in md.lines() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        for span in line.split('`').skip(1).step_by(2) {
            let span = span.split('(').next().unwrap_or("");
            let (head, group) = match span.split_once("::{") {
                Some((h, g)) => (h, g.strip_suffix('}').unwrap_or("")),
                None => (span, ""),
            };
            let ident_path = |p: &str| {
                p.contains("::")
                    && p.split("::").all(|part| {
                        part.starts_with(|c: char| c.is_alphabetic() || c == '_')
                            && part.chars().all(|c| c.is_alphanumeric() || c == '_')
                    })
            };
            if group.is_empty() {
                if ident_path(head) {
                    out.push(head.to_owned());
                }
            } else {
                for member in group.split(',').map(str::trim) {
                    let p = format!("{head}::{member}");
                    if ident_path(&p) {
                        out.push(p);
                    }
                }
            }
        }
    }
    out
}

/// The items named beside a file, as (file, item): `` `src/xr/gaze.rs` (`used`) ``,
/// `` `used` (`src/xr/gaze.rs`) `` and `` `used` in `gaze.rs` ``.
fn file_items(md: &str) -> Vec<(String, String)> {
    let is_item = |w: &str| {
        !w.is_empty()
            && w.starts_with(|c: char| c.is_alphabetic() || c == '_')
            && w.chars().all(|c| c.is_alphanumeric() || c == '_')
    };
    let is_file =
        |w: &str| w.ends_with(".rs") && w.chars().all(|c| c.is_alphanumeric() || "_./".contains(c));
    let mut out = Vec::new();
    for line in md.lines() {
        // Inline code spans and the text between them, alternating.
        let parts: Vec<&str> = line.split('`').collect();
        for i in (1..parts.len()).step_by(2) {
            let Some(next) = parts.get(i + 2) else { break };
            let (a, between, b) = (parts[i], parts[i + 1], *next);
            match between {
                " (" if is_file(a) && is_item(b) => out.push((a.to_owned(), b.to_owned())),
                " (" | " in " if is_item(a) && is_file(b) => out.push((b.to_owned(), a.to_owned())),
                _ => {}
            }
        }
    }
    out
}

/// What a Markdown file names that the sources do not declare. A file named by a path that does
/// not start at the root (`lock.rs`, `hooks/session.rs`) is every Rust file whose path ends so.
fn dead_items(root: &Path, items: &Items, file: &str, md: &str) -> Vec<String> {
    let mut out = Vec::new();
    for path in item_paths(md) {
        if let Some(why) = items.missing(&path) {
            out.push(format!(
                "{file}: `{path}` names no item of this repository: {why}"
            ));
        }
    }
    let pairs = file_items(md);
    let every: Vec<PathBuf> = if pairs.is_empty() {
        Vec::new()
    } else {
        source_roots(root)
            .into_iter()
            .flat_map(|(d, _)| if d.is_file() { vec![d] } else { rust_files(&d) })
            .collect()
    };
    for (source, item) in pairs {
        let candidates: Vec<PathBuf> = if root.join(&source).is_file() {
            vec![root.join(&source)]
        } else {
            let tail = format!("/{source}");
            every
                .iter()
                .filter(|f| f.to_string_lossy().ends_with(&tail))
                .cloned()
                .collect()
        };
        if candidates.is_empty() {
            continue; // a path that is gone is reported as such
        }
        let named = candidates.iter().any(|f| {
            std::fs::read_to_string(f)
                .unwrap_or_default()
                .split(|c: char| !(c.is_alphanumeric() || c == '_'))
                .any(|w| w == item)
        });
        if !named {
            out.push(format!("{file}: `{source}` has no `{item}`"));
        }
    }
    out
}

#[test]
fn every_rust_item_the_documents_name_exists() {
    let root = root();
    let items = Items::read(&root);
    assert!(
        items.missing("common::guard").is_none() && items.missing("Session::eyes").is_none(),
        "the source scan finds nothing"
    );
    let mut problems = Vec::new();
    let mut named = 0;
    for (file, md) in documents() {
        named += item_paths(&md).len();
        problems.extend(dead_items(&root, &items, &file, &md));
    }
    assert!(named > 50, "only {named} item paths found in the documents");
    assert!(
        problems.is_empty(),
        "{} item(s) the documents name do not exist:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// What is wrong with one Markdown file's commands and links: `file` is its path under `root`.
fn check_markdown(root: &Path, file: &str, md: &str) -> Vec<String> {
    let ws = Workspace::read(root);
    let mut problems = Vec::new();
    for b in blocks(md).iter().filter(|b| is_shell(&b.info)) {
        for words in commands(&b.body) {
            if let Some(c) = parse_cargo(&words) {
                for p in check_cargo(&ws, &c) {
                    problems.push(format!("{file}:{}: `{}`: {p}", b.line, words.join(" ")));
                }
            }
        }
    }
    for path in repository_paths(root, md) {
        if !root.join(&path).exists() {
            problems.push(format!("{file}: `{path}` names no file of this repository"));
        }
    }
    let dir = root.join(file).parent().unwrap().to_owned();
    for link in links(md) {
        if link.is_empty() || link.contains("://") || link.starts_with("mailto:") {
            continue;
        }
        let (path, fragment) = match link.split_once('#') {
            Some((p, f)) => (p, Some(f)),
            None => (link.as_str(), None),
        };
        let target = if path.is_empty() {
            root.join(file)
        } else {
            dir.join(path)
        };
        if !target.exists() {
            problems.push(format!("{file}: the link `{link}` names no file"));
            continue;
        }
        if let Some(fragment) = fragment {
            if target.extension().is_some_and(|x| x == "md") {
                let text = std::fs::read_to_string(&target).unwrap();
                if !anchors(&text).contains(fragment) {
                    problems.push(format!("{file}: the link `{link}` names no heading there"));
                }
            }
        }
    }
    problems
}

/// README.md and every docs/*.md, as (path under the root, text).
fn documents() -> Vec<(String, String)> {
    let root = root();
    let mut files = vec!["README.md".to_owned()];
    let mut docs: Vec<String> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .filter_map(|e| {
            let p = e.ok()?.path();
            let name = p.file_name()?.to_string_lossy().into_owned();
            (p.extension()? == "md").then(|| format!("docs/{name}"))
        })
        .collect();
    docs.sort();
    files.extend(docs);
    files
        .into_iter()
        .map(|f| {
            let text = std::fs::read_to_string(root.join(&f)).unwrap();
            (f, text)
        })
        .collect()
}

#[test]
fn every_cargo_command_names_targets_and_tests_that_exist_and_every_link_resolves() {
    let root = root();
    let docs = documents();
    assert!(
        docs.len() > 5,
        "README.md and docs/*.md: found {}",
        docs.len()
    );
    let mut problems = Vec::new();
    let mut cargo_commands = 0;
    for (file, md) in &docs {
        cargo_commands += blocks(md)
            .iter()
            .filter(|b| is_shell(&b.info))
            .flat_map(|b| commands(&b.body))
            .filter(|w| parse_cargo(w).is_some())
            .count();
        problems.extend(check_markdown(&root, file, md));
    }
    assert!(
        cargo_commands > 10,
        "only {cargo_commands} cargo commands found"
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The documents of `docs/` (file names) that the index `docs/README.md` does not link.
fn unlisted<'a>(index: &str, files: &[&'a str]) -> Vec<&'a str> {
    let listed: BTreeSet<String> = links(index).into_iter().collect();
    files
        .iter()
        .copied()
        .filter(|f| *f != "README.md" && !listed.contains(*f))
        .collect()
}

#[test]
fn the_index_lists_every_document() {
    let docs = documents();
    let index = &docs
        .iter()
        .find(|(f, _)| f == "docs/README.md")
        .expect("docs/README.md")
        .1;
    let files: Vec<&str> = docs
        .iter()
        .filter_map(|(f, _)| f.strip_prefix("docs/"))
        .collect();
    assert!(files.len() > 10, "{files:?}");
    let missing = unlisted(index, &files);
    assert!(
        missing.is_empty(),
        "docs/README.md does not list {missing:?}"
    );
    assert_eq!(
        unlisted(
            "| [a.md](a.md) | one |\n`b.md`\n",
            &["a.md", "b.md", "README.md"]
        ),
        ["b.md"],
        "a document named but not linked is not listed"
    );
}

/// The `fovea` binary of this build, refused when older than the sources it is built from.
fn fovea_binary() -> PathBuf {
    let bin = fovea_harness::artifact("fovea").unwrap_or_else(|e| panic!("{e}"));
    let built = std::fs::metadata(&bin).unwrap().modified().unwrap();
    let root = root();
    for dir in [
        "crates/cli/src",
        "crates/model/src",
        "crates/config/src",
        "crates/abi/src",
    ] {
        for f in rust_files(&root.join(dir)) {
            let changed = std::fs::metadata(&f).unwrap().modified().unwrap();
            assert!(
                changed <= built,
                "{} is older than {}: run `cargo build --workspace` first",
                bin.display(),
                f.display()
            );
        }
    }
    bin
}

/// A runnable block as a script: `cargo run [--release] [-q] --` replaced by `bin`; any other
/// cargo command refused.
fn runnable_script(body: &str, bin: &Path) -> Result<String, String> {
    let mut script = String::new();
    for line in body.replace("\\\n", " ").lines() {
        let mut words: Vec<&str> = line.split_whitespace().collect();
        if let Some(at) = words.iter().position(|w| *w == "cargo") {
            let end = words[at..].iter().position(|w| *w == "--");
            let head = &words[at..at + end.unwrap_or(words.len() - at)];
            let plain = head.get(1) == Some(&"run")
                && head[2..].iter().all(|w| matches!(*w, "--release" | "-q"));
            if end.is_none() || !plain {
                return Err(format!(
                    "a runnable block may only `cargo run --`: `{line}`"
                ));
            }
            let bin = bin.to_str().unwrap();
            words.splice(at..=at + end.unwrap(), [bin]);
        }
        script.push_str(&words.join(" "));
        script.push('\n');
    }
    Ok(script)
}

#[test]
fn runnable_blocks_run() {
    let mut ran = 0;
    let mut problems = Vec::new();
    let mut bin = None;
    for (file, md) in documents() {
        for b in blocks(&md).iter().filter(|b| is_runnable(&b.info)) {
            let bin = bin.get_or_insert_with(fovea_binary);
            let script = match runnable_script(&b.body, bin) {
                Ok(s) => s,
                Err(e) => {
                    problems.push(format!("{file}:{}: {e}", b.line));
                    continue;
                }
            };
            let dir = std::env::temp_dir().join(format!(
                "fovea-docs-{}-{}-{}",
                std::process::id(),
                file.replace('/', "_"),
                b.line
            ));
            std::fs::remove_dir_all(&dir).ok();
            std::fs::create_dir_all(&dir).unwrap();
            let finished = run_with_timeout(
                Command::new("bash")
                    .args(["-euo", "pipefail", "-c", &script])
                    .current_dir(&dir)
                    .env("HOME", dir.join("home"))
                    .env("XDG_CONFIG_HOME", dir.join("config"))
                    .env("XDG_DATA_HOME", dir.join("data"))
                    .env("XDG_STATE_HOME", dir.join("state"))
                    .env_remove("FOVEA_CONFIG")
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped()),
                Duration::from_secs(120),
            );
            match finished.status {
                Some(s) if s.success() => ran += 1,
                status => problems.push(format!(
                    "{file}:{}: the block ended {status:?}:\n{script}{}{}",
                    b.line, finished.stdout, finished.stderr
                )),
            }
            std::fs::remove_dir_all(&dir).ok();
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert!(ran >= 1, "no runnable block found in README.md or docs/");
}

// ---------------------------------------------------------------------------------------------
// The checker's own tests, on strings that must fail (and one that must pass).

fn problems_of(md: &str) -> Vec<String> {
    check_markdown(&root(), "docs/example.md", md)
}

#[test]
fn a_command_whose_targets_and_filters_exist_passes() {
    let md = "```sh\ncargo build --workspace && FOO=1 cargo test --test suite docs_commands -- --nocapture\n\
              cargo test -p fovea-cli --test cli maps\ncargo bench -p fovea-model --bench density\n\
              cargo run --release --example foveated_vulkan -- --levels high\n\
              sudo .ci/trixie cargo test --test suite -- monado --skip nothing_at_all\n```\n\
              [architecture](ARCHITECTURE.md#code-map) <img src=\"maps/quest3_low_left.png\">\n";
    assert_eq!(problems_of(md), Vec::<String>::new());
}

#[test]
fn a_missing_test_target_fails() {
    let p = problems_of("```sh\ncargo test --test fuzz_sequences\n```\n");
    assert_eq!(p.len(), 1, "{p:?}");
    assert!(p[0].contains("no tests target `fuzz_sequences`"), "{p:?}");
    // In a package that has no such target: the CLI's tests are not the layer's.
    let p = problems_of("```bash\ncargo test -p fovea-cli --test suite\n```\n");
    assert!(p.len() == 1 && p[0].contains("`suite`"), "{p:?}");
    let p = problems_of("```sh\ncargo bench --bench no_such_bench\n```\n");
    assert!(p.len() == 1 && p[0].contains("benches target"), "{p:?}");
}

#[test]
fn a_filter_that_matches_nothing_fails() {
    let p = problems_of(
        "```sh\ncargo test --test suite -- random_call_sequences no_test_is_called_this\n```\n",
    );
    assert_eq!(p.len(), 1, "{p:?}");
    assert!(p[0].contains("`no_test_is_called_this`"), "{p:?}");
    // A filter before `--`, and one that exists only in another package's tests.
    let p = problems_of("```sh\ncargo test --test suite unknown_structs_in_the_cli\n```\n");
    assert_eq!(p.len(), 1, "{p:?}");
    let p = problems_of("```sh\ncargo test --test suite -- --exact docs_commands\n```\n");
    assert_eq!(p.len(), 1, "an exact filter names a whole path: {p:?}");
}

#[test]
fn a_dead_link_fails() {
    let p = problems_of("See [the missing page](no-such-page.md) and ![x](gpu/none.png).\n");
    assert_eq!(p.len(), 2, "{p:?}");
    let p = problems_of("See [a heading that is not there](ARCHITECTURE.md#no-such-heading).\n");
    assert!(p.len() == 1 && p[0].contains("no heading"), "{p:?}");
    // Links inside code are not links.
    let p = problems_of("`[x](gone.md)`\n\n```text\n[y](gone.md)\n```\n");
    assert_eq!(p, Vec::<String>::new());
}

#[test]
fn a_file_name_that_is_gone_fails() {
    let p = problems_of("The test is `tests/suite/no_such_module.rs`; see `src/vk/gone.rs#L3`.\n");
    assert_eq!(p.len(), 2, "{p:?}");
    assert!(p[0].contains("`tests/suite/no_such_module.rs`"), "{p:?}");
    // Files that exist, and other projects' paths, pass.
    let p = problems_of(
        "`tests/suite/main.rs`, `crates/cli/tests/cli/`, Mesa's `src/amd/vulkan/radv_device.c`, `target/demo/`\n",
    );
    assert_eq!(p, Vec::<String>::new());
}

#[test]
fn the_parsers_read_shell_rust_and_markdown_as_written() {
    let c = commands(
        "A=1 cargo test --test suite x \\\n  -- y --skip z # comment\necho a | b; c && d\n",
    );
    assert_eq!(c.len(), 5, "{c:?}");
    let cargo = parse_cargo(&c[0]).unwrap();
    assert_eq!(cargo.tests, ["suite"]);
    assert_eq!(cargo.filters, ["x", "y"]);
    let paths = fn_paths(
        "mod a { fn one() {} }\nconst S: &str = \"fn not_a_fn() {\";\nmod b { mod c { fn two<'x>(_: &'x u8) { let _ = '{'; } } }\nfn three() {}\n",
        &["top".to_owned()],
    );
    assert_eq!(paths, ["top::a::one", "top::b::c::two", "top::three"]);
    assert_eq!(anchor(" No `static mut`"), "no-static-mut");
    assert!(anchors("# T\n## On a real GPU\n## On a real GPU\n").contains("on-a-real-gpu-1"));
    assert!(is_runnable("sh runnable") && !is_runnable("sh") && !is_runnable("text runnable"));
}

#[test]
fn an_item_that_is_gone_fails() {
    let root = root();
    let items = Items::read(&root);
    let md =
        "`common::ffi::guard`, `hooks::check_lost`, `Session::no_such_member`, `NoSuchType::x`, \
              `crates/abi/src/lib.rs` (`NO_SUCH_NAME`), `gone_fn` (`src/xr/gaze.rs`), `Gone` in `lock.rs`\n";
    let p = dead_items(&root, &items, "docs/example.md", md);
    assert_eq!(p.len(), 7, "{p:#?}");
    // Items that exist, in the forms the documents use, and other projects' names, pass.
    let md = "`common::guard`, `crate::xr::foveation::MapKey`, `Session::eyes`, `Registry::{instances, sessions}`, \
              `DensityImages::refresh(index, key, inputs)`, `fovea_model::Fov`, `xr::gaze`, `fovea::stats`, \
              `XrApplicationInfo::applicationName`, `std::env::var`, `crates/abi/src/lib.rs` (`EXTENSIONS`), \
              `used` (`src/xr/gaze.rs`), `SpinMutex` in `lock.rs`, `session_gpu` in `hooks/session.rs`\n\
              ```rust\nlet x = gone::item();\n```\n";
    assert_eq!(
        dead_items(&root, &items, "docs/example.md", md),
        Vec::<String>::new()
    );
}
