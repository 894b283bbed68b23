//! The house rules of the source tree (docs/architecture.md, "Layering"), checked over every
//! library crate's `src/`:
//!
//! - no module circles: a module never names (by `crate::`, `super::`, `self::` or a child's name
//!   in a `use`) a module that names it back, directly or through others; the same for the
//!   top-level modules (a folder and its files count as one), so the folders stack in layers;
//! - no file over 900 lines and no function over 120 lines outside tests;
//! - the runtime's folder map in docs/architecture.md and the README's layout name exactly the
//!   folders of `runtime/src`.
//!
//! The scan is lexical: comments, strings and `#[cfg(test)]` modules are blanked first, then
//! paths are read from the code. Written by hand because the rule is the project's own; a parser
//! would add a dependency to catch nothing more (paths are all it reads).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates whose `src/` the rules cover (the binaries of the others are one file each).
const CRATES: [&str; 9] =
    ["format", "levels", "preprocess", "reference", "runtime", "web", "fixtures", "tests", "xtask"];
const MAX_FILE_LINES: usize = 900;
const MAX_FN_LINES: usize = 120;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The module path of a file under `src/` (`a/mod.rs` and `a.rs` are `a`, `lib.rs` is the root,
/// ""); `None` for binaries.
fn module_of(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).ok()?.with_extension("");
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    if parts.first().is_some_and(|p| p == "bin") || parts.last().is_some_and(|p| p == "main") {
        return None;
    }
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    Some(parts.join("::"))
}

/// `src` with comments, string and char literals replaced by spaces (newlines kept, so line
/// numbers stay).
fn blank_comments_and_strings(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(b.len())] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            let end = b[i..].iter().position(|&c| c == b'\n').map_or(b.len(), |n| i + n);
            blank(&mut out, i, end);
            i = end;
        } else if b[i..].starts_with(b"/*") {
            let (mut depth, mut j) = (1, i + 2);
            while j < b.len() && depth > 0 {
                if b[j..].starts_with(b"/*") {
                    depth += 1;
                    j += 2;
                } else if b[j..].starts_with(b"*/") {
                    depth -= 1;
                    j += 2;
                } else {
                    j += 1;
                }
            }
            blank(&mut out, i, j);
            i = j;
        } else if (b[i] == b'r' || b[i..].starts_with(b"br")) && (i == 0 || !ident(b[i - 1])) && {
            let k = if b[i] == b'b' { i + 2 } else { i + 1 };
            let hashes = b[k..].iter().take_while(|&&c| c == b'#').count();
            b.get(k + hashes) == Some(&b'"')
        } {
            let k = if b[i] == b'b' { i + 2 } else { i + 1 };
            let hashes = b[k..].iter().take_while(|&&c| c == b'#').count();
            let mut close = vec![b'"'];
            close.extend(std::iter::repeat_n(b'#', hashes));
            let start = k + hashes + 1;
            let end = b[start..]
                .windows(close.len())
                .position(|w| w == close)
                .map_or(b.len(), |n| start + n + close.len());
            blank(&mut out, i, end);
            i = end;
        } else if b[i] == b'"' {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            blank(&mut out, i, j + 1);
            i = j + 1;
        } else if b[i] == b'\'' {
            // A char literal ('a', '\n', '\u{..}'), not a lifetime ('a without a closing quote).
            let len = if b.get(i + 1) == Some(&b'\\') {
                b[i + 2..].iter().position(|&c| c == b'\'').map(|n| n + 3)
            } else {
                let ch = src[i + 1..].chars().next().map_or(1, char::len_utf8);
                (b.get(i + 1 + ch) == Some(&b'\'')).then_some(ch + 2)
            };
            match len {
                Some(n) => {
                    blank(&mut out, i, i + n);
                    i += n;
                }
                None => i += 1,
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The byte just past the brace that closes the one at `open`.
fn matching_brace(code: &str, open: usize) -> usize {
    let mut depth = 0usize;
    for (i, c) in code.bytes().enumerate().skip(open) {
        match c {
            b'{' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
    }
    code.len()
}

/// Byte ranges of the `#[cfg(test)]` modules and `#[test]` functions in blanked `code`.
fn test_ranges(code: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for attr in ["#[cfg(test)]", "#[test]"] {
        let mut from = 0;
        while let Some(at) = code[from..].find(attr).map(|n| from + n) {
            from = at + attr.len();
            if let Some(open) = code[from..].find('{').map(|n| from + n) {
                out.push((at, matching_brace(code, open)));
            }
        }
    }
    out
}

/// `code` with its test modules and functions blanked.
fn without_tests(code: &str) -> String {
    let mut b = code.as_bytes().to_vec();
    for (from, to) in test_ranges(code) {
        for c in &mut b[from..to] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    }
    String::from_utf8_lossy(&b).into_owned()
}

/// `tree` without its `as alias` renames and whitespace.
fn without_aliases(tree: &str) -> String {
    let mut out = String::new();
    let mut words = tree.split_whitespace();
    while let Some(w) = words.next() {
        if w == "as" {
            // The alias goes; what follows it (`,`, `}`) stays.
            if let Some(alias) = words.next() {
                out.extend(alias.chars().skip_while(|c| c.is_alphanumeric() || *c == '_'));
            }
        } else {
            out.push_str(w);
        }
    }
    out
}

/// The paths a `use` tree names, from the text after `use` up to its `;` (groups expanded).
fn use_paths(tree: &str) -> Vec<String> {
    let tree = without_aliases(tree);
    let mut out = Vec::new();
    fn walk(prefix: &str, t: &str, out: &mut Vec<String>) {
        // Split the top level of a group at commas.
        if let Some(open) = t.find('{') {
            let head = &t[..open];
            let inner = &t[open + 1..t.rfind('}').unwrap_or(t.len())];
            let (mut depth, mut start) = (0, 0);
            let mut parts = Vec::new();
            for (i, c) in inner.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        parts.push(&inner[start..i]);
                        start = i + 1;
                    }
                    _ => {}
                }
            }
            parts.push(&inner[start..]);
            for p in parts.into_iter().filter(|p| !p.is_empty()) {
                walk(&format!("{prefix}{head}"), p, out);
            }
        } else {
            out.push(format!("{prefix}{t}").trim_end_matches("::*").trim_end_matches("::self").to_string());
        }
    }
    walk("", &tree, &mut out);
    out
}

/// The crate modules a file module names: `crate::`/`super::`/`self::` paths anywhere, and
/// `use` paths that start at a child module.
fn named_modules(module: &str, code: &str, modules: &BTreeSet<String>) -> BTreeSet<String> {
    let parent = |m: &str| m.rsplit_once("::").map_or(String::new(), |(p, _)| p.to_string());
    // `super` of `a::b` (a/b.rs) is `a`; of a folder's mod.rs `a` too, its parent.
    let super_of = parent(module);
    let join =
        |base: &str, rest: &str| if base.is_empty() { rest.to_string() } else { format!("{base}::{rest}") };
    let resolve = |path: &str| -> Option<String> {
        let segs: Vec<&str> = path.split("::").filter(|s| !s.is_empty()).collect();
        let (base, rest) = match segs.first() {
            Some(&"crate") => (String::new(), &segs[1..]),
            Some(&"super") => {
                let mut base = super_of.clone();
                let mut rest = &segs[1..];
                while rest.first() == Some(&"super") {
                    base = parent(&base);
                    rest = &rest[1..];
                }
                (base, rest)
            }
            Some(&"self") => (module.to_string(), &segs[1..]),
            Some(first) if modules.contains(&join(module, first)) => (module.to_string(), &segs[..]),
            _ => return None,
        };
        // The longest prefix that is a module.
        (0..=rest.len())
            .rev()
            .map(|k| rest[..k].iter().fold(base.clone(), |b, s| join(&b, s)))
            .find(|m| modules.contains(m))
    };
    let mut out = BTreeSet::new();
    let bytes = code.as_bytes();
    // Paths anywhere in the code.
    for start in ["crate::", "super::", "self::"] {
        let mut from = 0;
        while let Some(at) = code[from..].find(start).map(|n| from + n) {
            from = at + start.len();
            if at > 0
                && (bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'_' || bytes[at - 1] == b':')
            {
                continue;
            }
            let end = code[at..]
                .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                .map_or(code.len(), |n| at + n);
            let path = code[at..end].trim_end_matches(':');
            // `crate::{a, b}` groups are read with the use statements below.
            if let Some(m) = resolve(path).filter(|m| m != module) {
                out.insert(m);
            }
        }
    }
    // Use statements, groups expanded (this also covers `pub use child::Item`).
    let mut from = 0;
    while let Some(at) = code[from..].find("use ").map(|n| from + n) {
        from = at + 4;
        if at > 0 && (bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'_') {
            continue;
        }
        let Some(end) = code[from..].find(';').map(|n| from + n) else { break };
        for path in use_paths(&code[from..end]) {
            if let Some(m) = resolve(&path).filter(|m| m != module) {
                out.insert(m);
            }
        }
    }
    out
}

/// One crate's modules and what each names.
fn module_graph(krate: &str) -> BTreeMap<String, BTreeSet<String>> {
    let src = workspace().join(krate).join("src");
    let files: Vec<(String, PathBuf)> =
        rust_files(&src).into_iter().filter_map(|f| Some((module_of(&src, &f)?, f))).collect();
    let modules: BTreeSet<String> = files.iter().map(|(m, _)| m.clone()).collect();
    files
        .iter()
        .map(|(m, f)| {
            let code = without_tests(&blank_comments_and_strings(&std::fs::read_to_string(f).unwrap()));
            (m.clone(), named_modules(m, &code, &modules))
        })
        .collect()
}

/// The circles of a graph (its strongly connected components of more than one node), each
/// sorted.
fn circles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    // Kosaraju: order by finish time, then walk the reversed graph.
    let nodes: Vec<&String> = graph.keys().collect();
    let mut seen = BTreeSet::new();
    let mut order = Vec::new();
    for &n in &nodes {
        if seen.contains(n) {
            continue;
        }
        let mut stack = vec![(n.clone(), false)];
        while let Some((v, done)) = stack.pop() {
            if done {
                order.push(v);
                continue;
            }
            if !seen.insert(v.clone()) {
                continue;
            }
            stack.push((v.clone(), true));
            for w in graph.get(&v).into_iter().flatten() {
                if !seen.contains(w) {
                    stack.push((w.clone(), false));
                }
            }
        }
    }
    let mut reversed: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (v, ws) in graph {
        for w in ws {
            reversed.entry(w.clone()).or_default().push(v.clone());
        }
    }
    let mut assigned = BTreeSet::new();
    let mut out = Vec::new();
    for v in order.into_iter().rev() {
        if assigned.contains(&v) {
            continue;
        }
        let mut component = Vec::new();
        let mut stack = vec![v];
        while let Some(x) = stack.pop() {
            if !assigned.insert(x.clone()) {
                continue;
            }
            component.push(x.clone());
            stack.extend(reversed.get(&x).into_iter().flatten().filter(|w| !assigned.contains(*w)).cloned());
        }
        if component.len() > 1 {
            component.sort();
            out.push(component);
        }
    }
    out
}

/// The graph of the top-level modules (a folder with its files is one).
fn top_level(graph: &BTreeMap<String, BTreeSet<String>>) -> BTreeMap<String, BTreeSet<String>> {
    let top = |m: &str| m.split("::").next().unwrap_or("").to_string();
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (m, ws) in graph {
        let entry = out.entry(top(m)).or_default();
        entry.extend(ws.iter().map(|w| top(w)).filter(|w| *w != top(m) && !w.is_empty()));
    }
    out.remove("");
    out
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let mut found = Vec::new();
    for krate in CRATES {
        let graph = module_graph(krate);
        assert!(graph.len() > 1 || krate == "fixtures", "{krate}: no modules found under src/");
        for c in circles(&graph) {
            found.push(format!("{krate}: modules {}", c.join(" <-> ")));
        }
        for c in circles(&top_level(&graph)) {
            found.push(format!("{krate}: top-level modules {}", c.join(" <-> ")));
        }
    }
    assert!(found.is_empty(), "module circles (docs/architecture.md, \"Layering\"):\n{}", found.join("\n"));
}

/// The circle finder finds a circle (so the test above can fail).
#[test]
fn a_circle_is_found() {
    let modules: BTreeSet<String> = ["a", "b", "c", "c::d"].map(String::from).into();
    let code = |s: &str| without_tests(&blank_comments_and_strings(s));
    let graph: BTreeMap<String, BTreeSet<String>> = [
        ("a", "use crate::b::X;\n// crate::c\n"),
        ("b", "fn f() { crate::c::d::g(); }\n#[cfg(test)]\nmod tests { use crate::a::Y; }\n"),
        ("c", "pub use d::g;\nconst S: &str = \"crate::b\";\n"),
        ("c::d", "use super::super::{a::{self, Z}, b};\n"),
    ]
    .into_iter()
    .map(|(m, src)| (m.to_string(), named_modules(m, &code(src), &modules)))
    .collect();
    assert_eq!(graph["a"], BTreeSet::from(["b".to_string()]));
    assert_eq!(graph["b"], BTreeSet::from(["c::d".to_string()]), "tests and strings are not read");
    assert_eq!(graph["c"], BTreeSet::from(["c::d".to_string()]), "a child named in a use");
    assert_eq!(graph["c::d"], BTreeSet::from(["a".to_string(), "b".to_string()]));
    assert_eq!(circles(&graph), vec![vec!["a".to_string(), "b".to_string(), "c::d".to_string()]]);
    assert_eq!(circles(&top_level(&graph)), vec![vec!["a".to_string(), "b".to_string(), "c".to_string()]]);
}

/// Use trees expand to one path a name; renames keep the name renamed, also where it holds "as".
#[test]
fn use_trees_name_their_paths() {
    assert_eq!(
        use_paths("crate::{passes, a::b as c, d::{self, e}, f::*}"),
        ["crate::passes", "crate::a::b", "crate::d", "crate::d::e", "crate::f"]
    );
}

/// Functions (`fn name`) with their first line and length in lines, outside tests.
fn long_functions(code: &str) -> Vec<(String, usize, usize)> {
    let line_of = |at: usize| code[..at].bytes().filter(|&c| c == b'\n').count() + 1;
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let mut from = 0;
    while let Some(at) = code[from..].find("fn ").map(|n| from + n) {
        from = at + 3;
        if at > 0 && (bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'_') {
            continue;
        }
        let name: String = code[from..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        if name.is_empty() {
            continue;
        }
        // The body starts at the first `{` outside the signature's brackets; a `;` first is a
        // declaration without one.
        let mut depth = 0i32;
        let mut open = None;
        for (i, c) in code[from..].char_indices() {
            match c {
                '(' | '[' | '<' => depth += 1,
                ')' | ']' | '>' => depth -= 1,
                '{' if depth <= 0 => {
                    open = Some(from + i);
                    break;
                }
                ';' if depth <= 0 => break,
                _ => {}
            }
        }
        if let Some(open) = open {
            let close = matching_brace(code, open);
            let lines = line_of(close) - line_of(at) + 1;
            if lines > MAX_FN_LINES {
                out.push((name, line_of(at), lines));
            }
        }
    }
    out
}

#[test]
fn files_and_functions_fit_a_screen_or_two() {
    let mut found = Vec::new();
    for krate in CRATES {
        let root = workspace().join(krate);
        for f in rust_files(&root.join("src")) {
            let text = std::fs::read_to_string(&f).unwrap();
            let name = f.strip_prefix(workspace()).unwrap_or(&f).display().to_string();
            let lines = text.lines().count();
            if lines > MAX_FILE_LINES {
                found.push(format!("{name}: {lines} lines (at most {MAX_FILE_LINES})"));
            }
            for (func, line, n) in long_functions(&without_tests(&blank_comments_and_strings(&text))) {
                found.push(format!("{name}:{line}: fn {func} is {n} lines (at most {MAX_FN_LINES})"));
            }
        }
    }
    assert!(found.is_empty(), "too long (docs/architecture.md, \"Layering\"):\n{}", found.join("\n"));
}

/// The length check sees a long function, and not one in a test module.
#[test]
fn a_long_function_is_found() {
    let body = "    let x = 1;\n".repeat(MAX_FN_LINES);
    let src = format!(
        "fn long(a: Vec<u8>) -> u8 {{\n{body}}}\nfn short() {{ let s = \"}}\"; }}\n#[cfg(test)]\nmod tests {{\n    fn also_long() {{\n{body}    }}\n}}\n"
    );
    let found = long_functions(&without_tests(&blank_comments_and_strings(&src)));
    assert_eq!(found, vec![("long".to_string(), 1, MAX_FN_LINES + 2)]);
}

/// The folders of `runtime/src`.
fn runtime_folders() -> BTreeSet<String> {
    let src = workspace().join("runtime/src");
    std::fs::read_dir(&src)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_dir() && e.path().join("mod.rs").is_file())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect()
}

/// The folders a map names: the first word of each line of the code block after `heading`, where
/// it ends in `/` (indented by `indent` spaces).
fn mapped_folders(doc: &str, heading: &str, indent: usize) -> BTreeSet<String> {
    let after = &doc[doc.find(heading).unwrap_or_else(|| panic!("no {heading:?}"))..];
    let block = after.split("```").nth(1).unwrap_or("");
    block
        .lines()
        .filter(|l| l.len() > indent && l[..indent].trim().is_empty() && !l[indent..].starts_with(' '))
        .filter_map(|l| l[indent..].split_whitespace().next())
        .filter_map(|w| w.strip_suffix('/'))
        .map(str::to_string)
        .collect()
}

#[test]
fn the_folder_maps_agree_with_the_tree() {
    let folders = runtime_folders();
    assert!(folders.contains("render") && folders.contains("passes"), "{folders:?}");
    let architecture = std::fs::read_to_string(workspace().join("docs/architecture.md")).unwrap();
    let readme = std::fs::read_to_string(workspace().join("README.md")).unwrap();
    let in_architecture = mapped_folders(&architecture, "## Runtime (renderer library)", 0);
    assert_eq!(in_architecture, folders, "docs/architecture.md's runtime map against runtime/src");
    let in_readme = mapped_folders(&readme, "## Layout", 2);
    assert_eq!(in_readme, folders, "the README's layout (the runtime's folders) against runtime/src");
}

/// The `key = value` lines of `[section]` in a Cargo.toml's text (comments and blank lines
/// left out), in order.
fn toml_section(text: &str, section: &str) -> Vec<String> {
    let mut lines = text.lines().map(str::trim).skip_while(|l| *l != section).skip(1);
    let mut out = Vec::new();
    for l in lines.by_ref() {
        if l.starts_with('[') {
            break;
        }
        if !l.is_empty() && !l.starts_with('#') {
            out.push(l.to_owned());
        }
    }
    out
}

/// CI checks the fuzz target in the main target folder (.ci/run); it finds the dependencies
/// clippy checked there only while both workspaces build them under the same dev profile.
#[test]
fn the_fuzz_workspace_builds_with_the_main_dev_profile() {
    let main = std::fs::read_to_string(workspace().join("Cargo.toml")).unwrap();
    let fuzz = std::fs::read_to_string(workspace().join("fuzz/Cargo.toml")).unwrap();
    for section in ["[profile.dev]", "[profile.dev.package.\"*\"]"] {
        let want = toml_section(&main, section);
        assert!(!want.is_empty(), "no {section} in Cargo.toml");
        assert_eq!(toml_section(&fuzz, section), want, "fuzz/Cargo.toml's {section} against Cargo.toml's");
    }
}
