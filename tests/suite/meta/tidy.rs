//! The house rules, checked on every run by reading the source tree (no build products needed):
//!
//! - the model and ABI crates hold no `unsafe` and forbid it at their roots;
//! - the layer's OpenXR side (`src/xr/`) and Vulkan side (`src/vk/`) never import each other: they
//!   meet in the bridge;
//! - no `static mut` in any of the workspace's Rust sources;
//! - no import cycle between the layer crate's top-level modules;
//! - every `unsafe` block in the layer has a `SAFETY:` comment on the lines just above it;
//! - no comment cites a file a clone of the repository does not have, or an issue number;
//! - inside `src/vk` and `src/xr`, files stand on floors (a table per tree, [`VK_FLOORS`] and
//!   [`XR_FLOORS`], as docs/ARCHITECTURE.md draws them) and import only from lower floors: never
//!   up, never sideways between rows of one floor, never between the files of a folder whose
//!   files are kept apart; the same in `crates/cli` and `crates/sim` ([`CLI_FLOORS`],
//!   [`SIM_FLOORS`]);
//! - every prose floors table (docs/ARCHITECTURE.md, `src/vk/mod.rs`, `src/xr/mod.rs`, and the
//!   crate docs of `crates/cli` and `crates/sim`) is the table here.
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
// Floors: the files of `src/vk` and `src/xr` in layers, each importing only those below it.

/// One row of a floors table: a file (`loader.rs`) or a folder (`hooks`) of a tree, relative to
/// the tree's root, and its floor. Whether the files of a folder may import each other is said
/// by [`at`] (they may) or [`apart`] (they may not: "a hook never imports another hook").
#[derive(Clone, Copy, Debug)]
struct Place {
    floor: u32,
    path: &'static str,
    sideways: bool,
}

/// A file, or a folder whose files may import each other, on `floor`.
const fn at(floor: u32, path: &'static str) -> Place {
    Place {
        floor,
        path,
        sideways: true,
    }
}

/// A folder on `floor` whose files never import each other.
const fn apart(floor: u32, path: &'static str) -> Place {
    Place {
        floor,
        path,
        sideways: false,
    }
}

// The floors tables, the same as docs/ARCHITECTURE.md's "Floors". Each row: `at(floor, "file.rs")`,
// `at(floor, "folder")` or `apart(floor, "folder")`, paths relative to `src/vk` or `src/xr`; the
// tree's own `mod.rs` is its door and is on no floor. The tens are the floors of
// docs/ARCHITECTURE.md; the units order the files inside one floor's folder, so that a folder has
// no circle of its own either (`base/chain.rs` may import `base/link.rs`, never the reverse).
const VK_FLOORS: &[Place] = &[
    // 1, base/: the FFI edge, chains, the loader's link structs, the one command list, the
    // next-layer tables.
    at(11, "base/mod.rs"),
    at(11, "base/ffi.rs"),
    at(11, "base/link.rs"),
    at(11, "base/structs.rs"),
    at(11, "base/commands.rs"),
    at(12, "base/chain.rs"),
    at(12, "base/next.rs"),
    // 2, translate/: pure struct translation, no device calls.
    at(21, "translate/mod.rs"),
    at(21, "translate/formats.rs"),
    at(21, "translate/sync.rs"),
    at(22, "translate/rate_state.rs"),
    at(22, "translate/render_pass.rs"),
    at(23, "translate/render_pass_v1.rs"),
    // 3, own/ and shaders/: the layer's own device objects.
    at(31, "own/mod.rs"),
    at(31, "own/bindings.rs"),
    at(31, "own/convert_shader.rs"),
    at(31, "own/recon_shader.rs"),
    at(31, "own/shadows.rs"),
    at(31, "own/order.rs"),
    at(32, "own/calls.rs"),
    at(33, "own/converter.rs"),
    at(33, "own/injector.rs"),
    at(33, "own/reconstructor.rs"),
    // 4: per-instance and per-device records, every per-handle index.
    at(40, "registry.rs"),
    // 5: the modes, which never import each other.
    at(50, "decide.rs"),
    at(50, "emulation.rs"),
    at(50, "convert.rs"),
    at(50, "injection.rs"),
    at(50, "reconstruct.rs"),
    // 6: the hooks; a hook never imports another.
    apart(60, "hooks"),
    // 7: the hook tables; 8: the loader interface.
    at(70, "dispatch.rs"),
    at(80, "loader.rs"),
];
const XR_FLOORS: &[Place] = &[
    // 1: the FFI edge, the command list, extension names, handle records, the session's GPU,
    // value conversions, where each view's fovea is, what a map is made from (`MapKey`).
    at(11, "ffi.rs"),
    at(11, "commands.rs"),
    at(11, "extensions.rs"),
    at(11, "records.rs"),
    at(11, "session_gpu.rs"),
    at(11, "values.rs"),
    at(11, "eye_centres.rs"),
    at(11, "foveation.rs"),
    // 2: what is built on them: the next layer's table, density images, the gaze source's
    // sampling; then the gaze source's instance part, which makes the sampling's sessions.
    at(21, "next_layer.rs"),
    at(21, "density_images.rs"),
    at(21, "gaze_sampling.rs"),
    at(22, "gaze.rs"),
    // 3: the registry of instances, sessions, swapchains and their FOV records.
    at(30, "registry.rs"),
    // 4: what lies below (probing the runtime), symmetric FOVs, the session's pattern policy.
    at(40, "below.rs"),
    at(40, "symmetric.rs"),
    at(40, "pattern.rs"),
    // 5: the hooks; 6: the dispatch table; 7: the loader interface.
    apart(50, "hooks"),
    at(60, "dispatch.rs"),
    at(70, "loader.rs"),
];

// The same for the two crates built in floors beyond the layer (their crate docs draw them); the
// crate root (`main.rs`, `lib.rs`) is the door.
const CLI_FLOORS: &[Place] = &[
    at(10, "args.rs"),
    at(10, "discovery.rs"),
    at(10, "json.rs"),
    at(20, "target.rs"),
    at(20, "fov.rs"),
    at(20, "config.rs"),
    at(20, "install.rs"),
    at(20, "found.rs"),
    at(20, "vk_doctor.rs"),
    at(20, "xr_doctor.rs"),
    at(20, "demo/setup.rs"),
    at(20, "demo/frames.rs"),
    at(30, "maps.rs"),
    at(30, "report.rs"),
    at(30, "doctor_settings.rs"),
    at(40, "doctor.rs"),
    at(40, "demo/harness.rs"),
    at(40, "demo/loader.rs"),
    at(50, "demo/mod.rs"),
];
const SIM_FLOORS: &[Place] = &[
    at(10, "ffi.rs"),
    at(10, "gaze_script.rs"),
    at(20, "config.rs"),
    at(30, "objects.rs"),
    at(30, "extensions.rs"),
    at(40, "state.rs"),
    at(40, "profiles.rs"),
    at(50, "control.rs"),
    at(50, "system.rs"),
    at(60, "vulkan.rs"),
    at(60, "actions.rs"),
    at(60, "foveation.rs"),
    at(70, "session.rs"),
    at(70, "space.rs"),
    at(70, "swapchain.rs"),
    at(80, "frame.rs"),
    at(80, "instance.rs"),
    at(90, "dispatch.rs"),
    at(100, "negotiate.rs"),
];

/// Every path a text names from a root keyword (`crate`, `$crate`, `super`, `self`), in `use`
/// declarations and inline in code, with `{a, b::c}` groups expanded, each with the byte offset
/// where it starts. A path is its segments up to the first that is not followed by `::`
/// (`crate::vk::registry::get(..)` is `[crate, vk, registry, get]`); a trailing `self` of a
/// group is left out, and a glob ends at its module. `code` has comments and literals blanked.
fn rooted_paths(code: &str) -> Vec<(Vec<String>, usize)> {
    fn skip_ws(s: &[char], i: &mut usize) {
        while *i < s.len() && s[*i].is_whitespace() {
            *i += 1;
        }
    }
    fn ident(s: &[char], i: &mut usize) -> Option<String> {
        let start = *i;
        while *i < s.len() && is_ident(s[*i]) {
            *i += 1;
        }
        (*i > start).then(|| s[start..*i].iter().collect())
    }
    fn double_colon(s: &[char], i: &mut usize) -> bool {
        let mut j = *i;
        skip_ws(s, &mut j);
        if s.get(j) == Some(&':') && s.get(j + 1) == Some(&':') {
            *i = j + 2;
            skip_ws(s, i);
            true
        } else {
            false
        }
    }
    /// The rest of a path after `prefix::`: one segment, a group or a glob.
    fn tree(s: &[char], i: &mut usize, mut prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
        loop {
            skip_ws(s, i);
            match s.get(*i) {
                Some('{') => {
                    *i += 1;
                    loop {
                        skip_ws(s, i);
                        match s.get(*i) {
                            None => return,
                            Some('}') => {
                                *i += 1;
                                return;
                            }
                            Some(',') => *i += 1,
                            Some(_) => {
                                let before = *i;
                                tree(s, i, prefix.clone(), out);
                                // Past what the group item left (`as x`, stray tokens).
                                while *i < s.len() && !matches!(s[*i], ',' | '}' | '{') {
                                    *i += 1;
                                }
                                if *i == before {
                                    *i += 1;
                                }
                            }
                        }
                    }
                }
                Some('*') => {
                    *i += 1;
                    out.push(prefix);
                    return;
                }
                Some(&c) if is_ident(c) => {
                    let name = ident(s, i).unwrap();
                    if name != "self" {
                        prefix.push(name);
                    }
                    if !double_colon(s, i) {
                        out.push(prefix);
                        return;
                    }
                }
                _ => {
                    out.push(prefix);
                    return;
                }
            }
        }
    }

    let s: Vec<char> = code.chars().collect();
    // Byte offsets of the chars, for line numbers.
    let offsets: Vec<usize> = code.char_indices().map(|(at, _)| at).collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < s.len() {
        if !is_ident(s[i]) {
            i += 1;
            continue;
        }
        let start = i;
        let name = ident(&s, &mut i).unwrap();
        let before = start.checked_sub(1).map(|b| s[b]);
        let follows_path = start >= 2 && s[start - 1] == ':' && s[start - 2] == ':';
        if !matches!(name.as_str(), "crate" | "super" | "self") || follows_path {
            continue;
        }
        let name = if before == Some('$') {
            format!("${name}")
        } else {
            name
        };
        let mut j = i;
        if !double_colon(&s, &mut j) {
            continue;
        }
        let mut paths = Vec::new();
        // `super::super::x`: the leading keywords are segments like any other.
        tree(&s, &mut j, vec![name], &mut paths);
        for p in paths {
            out.push((p, offsets[start]));
        }
        i = j.max(i);
    }
    out
}

/// The inline modules (`mod tests { .. }`) around byte offset `at` of `code`, outermost first.
fn inline_modules_at(code: &str, at: usize) -> Vec<String> {
    let w = words(code);
    let mut out = Vec::new();
    for pair in w.windows(2) {
        let (start, kw) = pair[0];
        let (name_at, name) = pair[1];
        if kw != "mod" || start > at {
            continue;
        }
        let after = &code[name_at + name.len()..];
        let Some(rest) = after.trim_start().strip_prefix('{') else {
            continue;
        };
        let open = code.len() - rest.len() - 1;
        // Where its block ends.
        let mut depth = 0usize;
        let mut end = code.len();
        for (off, c) in code[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + off;
                        break;
                    }
                }
                _ => {}
            }
        }
        if open < at && at < end {
            out.push(name.to_owned());
        }
    }
    out
}

/// A file's module path inside its tree: `a/b.rs` is `[a, b]`, `a/mod.rs` is `[a]`, `mod.rs` `[]`.
fn module_of(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel.split('/').map(str::to_owned).collect();
    let last = parts.pop().unwrap_or_default();
    if last != "mod.rs" {
        parts.push(last.trim_end_matches(".rs").to_owned());
    }
    parts
}

/// The row of `table` a file (path relative to the tree) is on: an error unless exactly one.
fn place_of<'t>(rel: &str, table: &'t [Place]) -> Result<&'t Place, String> {
    let rows: Vec<&Place> = table
        .iter()
        .filter(|p| rel == p.path || rel.starts_with(&format!("{}/", p.path)))
        .collect();
    match rows[..] {
        [one] => Ok(one),
        [] => Err("is on no floor of the table".to_owned()),
        _ => Err(format!(
            "is on {} rows of the table ({})",
            rows.len(),
            rows.iter().map(|p| p.path).collect::<Vec<_>>().join(", ")
        )),
    }
}

/// The floors rule over one tree: `tree` is its folder for messages (`src/vk`), `module` its
/// path from the crate root (`["vk"]`), `files` its Rust files (path relative to the tree, text).
///
/// Every file but the tree's `mod.rs` is on exactly one row of `table`, and every row holds a
/// file. Every module of the tree a file names (through `crate::vk::..`, `super::..`,
/// `self::..`) is its own or one of its own submodules, or on a strictly lower floor, or in the
/// same folder row as the file where that row allows sideways imports. The tree's `mod.rs` is on
/// no floor: naming it from inside the tree is going up.
fn floor_violations(
    tree: &str,
    module: &[&str],
    files: &[(String, String)],
    table: &[Place],
) -> Vec<String> {
    let mut out = Vec::new();
    let modules: BTreeMap<Vec<String>, &str> = files
        .iter()
        .map(|(rel, _)| (module_of(rel), rel.as_str()))
        .collect();
    for row in table {
        let holds = files.iter().any(|(rel, _)| {
            rel != "mod.rs" && (rel == row.path || rel.starts_with(&format!("{}/", row.path)))
        });
        if !holds {
            out.push(format!(
                "{tree}/{}: a row of the floors table (floor {}) that holds no file",
                row.path, row.floor
            ));
        }
    }
    for (rel, text) in files {
        if rel == "mod.rs" {
            continue;
        }
        let from = match place_of(rel, table) {
            Ok(p) => p,
            Err(e) => {
                out.push(format!("{tree}/{rel}: {e}"));
                continue;
            }
        };
        let own = module_of(rel);
        let code = split(text).code;
        let mut seen = BTreeSet::new();
        for (path, at) in rooted_paths(&code) {
            // `pub(in crate::vk)` says who may see an item; it imports nothing.
            if code[..at].trim_end().ends_with("(in") {
                continue;
            }
            let mut current = own.clone();
            current.extend(inline_modules_at(&code, at));
            // The path as segments from the tree's root; `None` outside the tree.
            let inside: Option<Vec<String>> = match path[0].as_str() {
                "crate" | "$crate" => {
                    let rest = &path[1..];
                    (rest.len() >= module.len() && rest.iter().zip(module).all(|(a, b)| a == b))
                        .then(|| rest[module.len()..].to_vec())
                }
                "self" => Some(current.iter().chain(&path[1..]).cloned().collect()),
                _ => {
                    let supers = path.iter().take_while(|s| *s == "super").count();
                    (supers <= current.len()).then(|| {
                        let mut p = current[..current.len() - supers].to_vec();
                        p.extend(path[supers..].iter().cloned());
                        p
                    })
                }
            };
            let Some(inside) = inside else { continue };
            // The module it names: the longest prefix that is a file of the tree.
            let target = (0..=inside.len())
                .rev()
                .map(|n| inside[..n].to_vec())
                .find(|m| modules.contains_key(m))
                .unwrap_or_default();
            if target.starts_with(&own) {
                continue;
            }
            let line = line_of(&code, at);
            let named = if target.is_empty() {
                "mod.rs".to_owned()
            } else {
                target.join("::")
            };
            if !seen.insert(named.clone()) {
                continue;
            }
            if target.is_empty() {
                out.push(format!(
                    "{tree}/{rel}:{line}: names the tree's root ({tree}/mod.rs), which is above \
                     every floor: name the module instead"
                ));
                continue;
            }
            let to_rel = modules[&target];
            let to = match place_of(to_rel, table) {
                Ok(p) => p,
                // Reported for that file itself.
                Err(_) => continue,
            };
            if std::ptr::eq(from, to) {
                if !from.sideways {
                    out.push(format!(
                        "{tree}/{rel}:{line}: imports `{named}` beside it in `{}` (floor {}), \
                         whose files never import each other",
                        from.path, from.floor
                    ));
                }
            } else if to.floor >= from.floor {
                out.push(format!(
                    "{tree}/{rel}:{line}: imports `{named}` on floor {} from floor {}: imports \
                     run only to lower floors",
                    to.floor, from.floor
                ));
            }
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
    for expected in ["xr", "bridge", "common"] {
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

/// The Rust files of `src/<name>`, each as its path relative to that folder and its text.
fn tree_files(name: &str) -> Vec<(String, String)> {
    let dir = root().join("src").join(name);
    rust_files(&dir)
        .into_iter()
        .map(|f| {
            let rel = f.strip_prefix(&dir).unwrap().to_string_lossy().into_owned();
            (rel, read(&f))
        })
        .collect()
}

/// A crate's files (path relative to its `src`, text), its root file named `mod.rs`: the door of
/// the tree, as a folder's `mod.rs` is.
fn crate_tree_files(krate: &str) -> Vec<(String, String)> {
    let dir = root().join("crates").join(krate).join("src");
    rust_files(&dir)
        .into_iter()
        .map(|f| {
            let rel = f.strip_prefix(&dir).unwrap().to_string_lossy().into_owned();
            let rel = match rel.as_str() {
                "main.rs" | "lib.rs" => "mod.rs".to_owned(),
                _ => rel,
            };
            (rel, read(&f))
        })
        .collect()
}

#[test]
fn the_cli_and_the_simulator_are_built_in_floors() {
    let mut found = Vec::new();
    for (name, table) in [("cli", CLI_FLOORS), ("sim", SIM_FLOORS)] {
        let files = crate_tree_files(name);
        assert!(
            files.iter().any(|(rel, _)| rel == "mod.rs"),
            "crates/{name}/src has no crate root"
        );
        found.extend(floor_violations(
            &format!("crates/{name}/src"),
            &[],
            &files,
            table,
        ));
    }
    assert!(
        found.is_empty(),
        "{} floor violation(s):\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn the_vulkan_and_openxr_sides_are_built_in_floors() {
    let mut found = Vec::new();
    for (name, table) in [("vk", VK_FLOORS), ("xr", XR_FLOORS)] {
        let files = tree_files(name);
        assert!(!files.is_empty(), "src/{name} has no Rust files");
        found.extend(floor_violations(
            &format!("src/{name}"),
            &[name],
            &files,
            table,
        ));
    }
    assert!(
        found.is_empty(),
        "{} floor violation(s):\n{}",
        found.len(),
        found.join("\n")
    );
}

/// The rows of the floors table that follows `marker` in `text` (a Markdown file, or a module's
/// `//!` doc): each file the row names, relative to the tree, with its floor and, where the row
/// gives one (`3a`, `3b`), its order inside the floor's folder. A folder the row names without
/// naming its files (`shaders/`) stands for every file in it. A path cell reads `` `own/`: 3a
/// `bindings`, `shadows`; 3b `calls` ``, `` `hooks/` (mod, actions, frame) `` or `` `loader.rs` ``.
fn prose_floors(text: &str, marker: &str) -> Vec<(String, u32, Option<u32>)> {
    let at = text
        .find(marker)
        .unwrap_or_else(|| panic!("no `{marker}` to find the floors table after"));
    let lines = text[at..]
        .lines()
        .map(|l| l.trim_start().trim_start_matches("//!").trim())
        .skip_while(|l| !l.starts_with("| floor |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'));
    let mut out = Vec::new();
    for row in lines {
        let cells: Vec<&str> = row.split('|').collect();
        let Some(floor) = cells.get(1).and_then(|c| c.trim().parse::<u32>().ok()) else {
            panic!("a floors row without a floor: {row}");
        };
        let (mut folder, mut unit, mut named) = (String::new(), None, true);
        let words = cells[2]
            .split(|c: char| !(c.is_ascii_alphanumeric() || "_./".contains(c)))
            .filter(|w| !w.is_empty());
        for w in words {
            let order = w
                .strip_suffix(|c: char| c.is_ascii_lowercase())
                .is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()));
            if order {
                unit = Some(u32::from(w.as_bytes()[w.len() - 1] - b'a') + 1);
            } else if let Some(f) = w.strip_suffix('/') {
                if !named {
                    out.push((folder.trim_end_matches('/').to_owned(), floor, unit));
                }
                folder = format!("{f}/");
                named = false;
            } else {
                let name = if w.ends_with(".rs") {
                    w.to_owned()
                } else {
                    format!("{w}.rs")
                };
                out.push((format!("{folder}{name}"), floor, unit));
                named = true;
            }
        }
        if !named {
            out.push((folder.trim_end_matches('/').to_owned(), floor, unit));
        }
    }
    out
}

/// Where a prose floors table (`rows`, from [`prose_floors`]) differs from the tidy test's own
/// `table` over the tree's `files` (paths relative to the tree): a file it leaves out (a folder's
/// own `mod.rs` may be left out where the folder is named), a file or folder it names that is not
/// there, a floor other than the table's tens or an order inside a folder other than its units.
/// The tree's `mod.rs`, the door, is on no floor, and a row naming it is not read.
fn prose_drift(
    doc: &str,
    rows: &[(String, u32, Option<u32>)],
    files: &[String],
    table: &[Place],
) -> Vec<String> {
    let mut out = Vec::new();
    let rows: Vec<&(String, u32, Option<u32>)> =
        rows.iter().filter(|(p, ..)| p != "mod.rs").collect();
    for (path, ..) in &rows {
        let there = files
            .iter()
            .any(|f| f == path || f.starts_with(&format!("{path}/")));
        if !there {
            out.push(format!(
                "{doc}: the floors table names `{path}`, which is no Rust file there"
            ));
        }
    }
    for f in files.iter().filter(|f| *f != "mod.rs") {
        let Ok(place) = place_of(f, table) else {
            continue; // the floors test reports it
        };
        let covering: Vec<_> = rows
            .iter()
            .filter(|(p, ..)| p == f || f.starts_with(&format!("{p}/")))
            .collect();
        match covering[..] {
            [] if f.ends_with("/mod.rs")
                && rows
                    .iter()
                    .any(|(p, ..)| p.starts_with(f.trim_end_matches("mod.rs"))) => {}
            [] => out.push(format!(
                "{doc}: `{f}` is missing from the floors table (floor {})",
                place.floor / 10
            )),
            [(_, floor, unit)] => {
                if *floor != place.floor / 10 || unit.is_some_and(|u| u != place.floor % 10) {
                    let given = match unit {
                        Some(u) => format!("{floor}{}", char::from(b'a' + *u as u8 - 1)),
                        None => floor.to_string(),
                    };
                    out.push(format!(
                        "{doc}: `{f}` is on floor {given} there, {} in tidy.rs",
                        place.floor
                    ));
                }
            }
            _ => out.push(format!(
                "{doc}: `{f}` is on {} rows of the floors table",
                covering.len()
            )),
        }
    }
    out
}

#[test]
fn the_prose_floors_tables_are_the_tidy_tests() {
    let architecture = read(&root().join("docs/ARCHITECTURE.md"));
    let mut found = Vec::new();
    for (name, table, heading) in [
        ("vk", VK_FLOORS, "### The Vulkan layer, `src/vk/`"),
        ("xr", XR_FLOORS, "### The OpenXR side, `src/xr/`"),
    ] {
        let files: Vec<String> = tree_files(name).into_iter().map(|(rel, _)| rel).collect();
        let door = read(&root().join("src").join(name).join("mod.rs"));
        for (doc, text, marker) in [
            ("docs/ARCHITECTURE.md".to_owned(), &architecture, heading),
            (format!("src/{name}/mod.rs"), &door, "| floor |"),
        ] {
            let mut rows = prose_floors(text, marker);
            // A folder of other files (`shaders/`: GLSL and SPIR-V) is on its floor too, with no
            // Rust file for tidy.rs to place.
            rows.retain(|(p, ..)| {
                let dir = root().join("src").join(name).join(p);
                !(dir.is_dir() && rust_files(&dir).is_empty())
            });
            assert!(rows.len() > 5, "{doc}: no floors table read for src/{name}");
            found.extend(prose_drift(&doc, &rows, &files, table));
        }
    }
    // The two crates built in floors draw theirs in their crate docs; the crate root is the door.
    for (name, table, root_file) in [
        ("cli", CLI_FLOORS, "main.rs"),
        ("sim", SIM_FLOORS, "lib.rs"),
    ] {
        let doc = format!("crates/{name}/src/{root_file}");
        let mut rows = prose_floors(&read(&root().join(&doc)), "| floor |");
        for (p, ..) in &mut rows {
            if p == root_file {
                *p = "mod.rs".to_owned();
            }
        }
        assert!(rows.len() > 5, "{doc}: no floors table read");
        let files: Vec<String> = crate_tree_files(name)
            .into_iter()
            .map(|(rel, _)| rel)
            .collect();
        found.extend(prose_drift(&doc, &rows, &files, table));
    }
    assert!(
        found.is_empty(),
        "{} difference(s) between the prose floors tables and tidy.rs's:\n{}",
        found.len(),
        found.join("\n")
    );
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

#[test]
fn rooted_paths_expand_groups_and_skip_comments_and_literals() {
    let text = "use crate::vk::{registry::{self, Records}, base::ffi::guard as g};\n\
                let x = super::own::Map::new(); // crate::vk::hooks\n\
                let s = \"self::x\"; pub(crate) fn f(&self) { self.g(); }\n\
                use super::super::base::*; $crate::vk::loader::go!(); a::crate::b;\n";
    let code = split(text).code;
    let paths: Vec<(String, usize)> = rooted_paths(&code)
        .into_iter()
        .map(|(p, at)| (p.join("::"), line_of(&code, at)))
        .collect();
    let expected = [
        ("crate::vk::registry", 1),
        ("crate::vk::registry::Records", 1),
        ("crate::vk::base::ffi::guard", 1),
        ("super::own::Map::new", 2),
        ("super::super::base", 4),
        ("$crate::vk::loader::go", 4),
    ];
    let expected: Vec<(String, usize)> =
        expected.iter().map(|(p, l)| (p.to_string(), *l)).collect();
    assert_eq!(paths, expected);
    assert_eq!(
        inline_modules_at(&code, code.len() - 1),
        Vec::<String>::new()
    );
    let nested = "fn a() {}\nmod tests {\n    mod deep { use super::x; }\n    fn b() {}\n}\n";
    let at = nested.find("super").unwrap();
    assert_eq!(inline_modules_at(nested, at), ["tests", "deep"]);
    assert_eq!(
        inline_modules_at(nested, nested.find("fn b").unwrap()),
        ["tests"]
    );
}

/// A small tree in floors, as [`floor_violations`] reads one: (path, text).
fn floored_tree(extra: &[(&str, &str)]) -> Vec<(String, String)> {
    let mut files: BTreeMap<&str, &str> = [
        ("mod.rs", "mod base;\nmod registry;\nmod hooks;\nmod loader;\nuse self::hooks::pass;\n"),
        ("base/mod.rs", "pub mod ffi;\npub use self::ffi::guard;\n"),
        ("base/ffi.rs", "pub fn guard() {}\nuse super::helper; // a sibling in a sideways folder\n"),
        ("registry.rs", "use crate::vk::base::ffi;\nuse crate::common::lock;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n"),
        ("hooks/mod.rs", "pub mod image;\npub mod pass;\npub use pass::begin;\n"),
        ("hooks/image.rs", "use crate::vk::{base::ffi::guard, registry::Records};\n"),
        ("hooks/pass.rs", "use super::super::registry;\nfn f() { crate::vk::base::guard(); }\n"),
        ("loader.rs", "use crate::vk::hooks::{image, pass};\nuse crate::xr::Thing;\n"),
    ]
    .into_iter()
    .collect();
    files.extend(extra.iter().copied());
    files
        .into_iter()
        .map(|(p, t)| (p.to_owned(), t.to_owned()))
        .collect()
}

const FLOORED: [Place; 4] = [
    at(1, "base"),
    at(2, "registry.rs"),
    apart(3, "hooks"),
    at(4, "loader.rs"),
];

#[test]
fn floors_hold_in_a_tree_built_in_floors() {
    assert_eq!(
        floor_violations("src/vk", &["vk"], &floored_tree(&[]), &FLOORED),
        Vec::<String>::new()
    );
}

#[test]
fn floors_catch_imports_going_up_or_sideways() {
    let violations = |extra: &[(&str, &str)], table: &[Place]| {
        floor_violations("src/vk", &["vk"], &floored_tree(extra), table)
    };
    // Up, in a group, inline in code, and through `$crate` in a macro.
    assert_eq!(
        violations(
            &[(
                "registry.rs",
                "use crate::vk::{base::ffi, hooks::{image}};\nfn f() { super::loader::go(); }\n\
                 // crate::vk::loader, in a comment\nlet s = \"crate::vk::loader\";\n"
            )],
            &FLOORED
        ),
        [
            "src/vk/registry.rs:1: imports `hooks::image` on floor 3 from floor 2: imports run \
             only to lower floors",
            "src/vk/registry.rs:2: imports `loader` on floor 4 from floor 2: imports run only \
             to lower floors",
        ]
    );
    assert_eq!(
        violations(
            &[(
                "base/ffi.rs",
                "macro_rules! m { () => { $crate::vk::registry::get() } }\n"
            )],
            &FLOORED
        ),
        [
            "src/vk/base/ffi.rs:1: imports `registry` on floor 2 from floor 1: imports run only \
          to lower floors"
        ]
    );
    // A visibility restriction names the root and imports nothing.
    assert!(violations(
        &[(
            "base/ffi.rs",
            "pub(in crate::vk) use m;\npub(in crate::vk) fn f() {}\n"
        )],
        &FLOORED
    )
    .is_empty());
    // Sideways inside a folder whose files never import each other, the folder's mod.rs too.
    assert_eq!(
        violations(
            &[("hooks/pass.rs", "use super::image::x;\nuse super::begin;\n")],
            &FLOORED
        ),
        [
            "src/vk/hooks/pass.rs:1: imports `hooks::image` beside it in `hooks` (floor 3), \
             whose files never import each other",
            "src/vk/hooks/pass.rs:2: imports `hooks` beside it in `hooks` (floor 3), whose \
             files never import each other",
        ]
    );
    // Two rows on one floor do not import each other.
    let same_floor = [
        at(1, "base"),
        at(2, "registry.rs"),
        apart(3, "hooks"),
        at(3, "loader.rs"),
    ];
    assert_eq!(
        violations(&[], &same_floor),
        [
            "src/vk/loader.rs:1: imports `hooks::image` on floor 3 from floor 3: imports run \
             only to lower floors",
            "src/vk/loader.rs:1: imports `hooks::pass` on floor 3 from floor 3: imports run \
             only to lower floors",
        ]
    );
    // The tree's root is above every floor.
    assert_eq!(
        violations(
            &[("registry.rs", "fn f() {}\nuse super::Shared;\n")],
            &FLOORED
        ),
        [
            "src/vk/registry.rs:2: names the tree's root (src/vk/mod.rs), which is above every \
          floor: name the module instead"
        ]
    );
}

#[test]
fn floors_tables_hold_every_file_once() {
    let violations = |extra: &[(&str, &str)], table: &[Place]| {
        floor_violations("src/vk", &["vk"], &floored_tree(extra), table)
    };
    assert_eq!(
        violations(&[("extra.rs", "")], &FLOORED),
        ["src/vk/extra.rs: is on no floor of the table"]
    );
    let twice = [
        at(1, "base"),
        at(1, "base/ffi.rs"),
        at(2, "registry.rs"),
        apart(3, "hooks"),
        at(4, "loader.rs"),
    ];
    assert_eq!(
        violations(&[], &twice),
        ["src/vk/base/ffi.rs: is on 2 rows of the table (base, base/ffi.rs)"]
    );
    let stale = [
        at(1, "base"),
        at(2, "registry.rs"),
        apart(3, "hooks"),
        at(4, "loader.rs"),
        at(5, "gone.rs"),
    ];
    assert_eq!(
        violations(&[], &stale),
        ["src/vk/gone.rs: a row of the floors table (floor 5) that holds no file"]
    );
}

#[test]
fn prose_floors_tables_are_read_and_their_drift_found() {
    let doc = "### Tree\n\n| floor | path | job |\n|---|---|---|\n| 3 | `loader.rs` | top |\n\
               | 2 | `hooks/` (mod, frame) | hooks |\n| 1 | `base/`: 1a `ffi`; 1b `chain` | base |\n";
    let rows = prose_floors(doc, "### Tree");
    let want: Vec<(String, u32, Option<u32>)> = vec![
        ("loader.rs".into(), 3, None),
        ("hooks/mod.rs".into(), 2, None),
        ("hooks/frame.rs".into(), 2, None),
        ("base/ffi.rs".into(), 1, Some(1)),
        ("base/chain.rs".into(), 1, Some(2)),
    ];
    assert_eq!(rows, want);
    let table = [
        at(11, "base/mod.rs"),
        at(11, "base/ffi.rs"),
        at(12, "base/chain.rs"),
        apart(20, "hooks"),
        at(30, "loader.rs"),
    ];
    let files: Vec<String> = [
        "mod.rs",
        "base/mod.rs",
        "base/ffi.rs",
        "base/chain.rs",
        "hooks/mod.rs",
        "hooks/frame.rs",
        "loader.rs",
    ]
    .map(String::from)
    .to_vec();
    assert_eq!(
        prose_drift("d", &rows, &files, &table),
        Vec::<String>::new()
    );
    // A file the prose leaves out, one it names that is gone, a floor and an order that differ.
    let mut more = files.clone();
    more.push("hooks/session.rs".into());
    let stale = doc
        .replace("1b `chain`", "1a `chain`")
        .replace("| 3 |", "| 4 |")
        .replace("frame)", "frame, gone)");
    let found = prose_drift("d", &prose_floors(&stale, "### Tree"), &more, &table);
    assert_eq!(
        found,
        [
            "d: the floors table names `hooks/gone.rs`, which is no Rust file there",
            "d: `base/chain.rs` is on floor 1a there, 12 in tidy.rs",
            "d: `loader.rs` is on floor 4 there, 30 in tidy.rs",
            "d: `hooks/session.rs` is missing from the floors table (floor 2)",
        ]
    );
    // A folder named without its files stands for all of them.
    let folder = doc.replace("(mod, frame)", "");
    assert_eq!(
        prose_drift("d", &prose_floors(&folder, "### Tree"), &more, &table),
        Vec::<String>::new()
    );
}
