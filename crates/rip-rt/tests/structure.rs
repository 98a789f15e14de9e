//! The shape of rip-rt's source, checked so that later work cannot bring back what was
//! removed: no import cycle between its modules (the I/O-free logic, `loop_core`, `rest`,
//! `envelope`, `step`, never reaches the modules that talk to the device), no source file over
//! 800 non-blank lines, no function over 150 lines. Test modules and test files are exempt.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const SRC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/src");
const MAX_FILE_LINES: usize = 800;
const MAX_FN_LINES: usize = 150;

/// Every source file but the tests (`tests.rs`, and `#[cfg(test)]` modules are cut off below).
fn sources() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs")
                && path.file_name().is_some_and(|n| n != "tests.rs")
            {
                out.push(path);
            }
        }
    }
    let mut out = Vec::new();
    walk(Path::new(SRC), &mut out);
    out.sort();
    out
}

/// The file's text before its test module.
fn text(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    text.split("#[cfg(test)]\nmod tests")
        .next()
        .unwrap()
        .to_string()
}

/// [`text`] without its comment lines (a module named in a doc comment is no import).
fn code(path: &Path) -> String {
    text(path)
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The top-level module a file belongs to (`cli/excite_cmd.rs` is `cli`'s).
fn module_of(path: &Path) -> String {
    let rel = path.strip_prefix(SRC).unwrap();
    let first = rel
        .components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy();
    first.trim_end_matches(".rs").to_string()
}

#[test]
fn no_import_cycle_between_modules() {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let files = sources();
    let modules: BTreeSet<String> = files.iter().map(|p| module_of(p)).collect();
    for path in &files {
        let m = module_of(path);
        if m == "lib" || m == "bin" {
            continue;
        }
        let code = code(path);
        let deps = graph.entry(m.clone()).or_default();
        for prefix in ["crate::", "rip_rt::"] {
            for (i, _) in code.match_indices(prefix) {
                let rest = &code[i + prefix.len()..];
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if name != m && modules.contains(&name) {
                    deps.insert(name);
                }
            }
        }
    }
    // Depth-first search for a back edge; the path to it is the cycle.
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(m.to_string(), 1);
        path.push(m.to_string());
        for d in graph.get(m).into_iter().flatten() {
            match state.get(d.as_str()).copied().unwrap_or(0) {
                1 => {
                    let start = path.iter().position(|p| p == d).unwrap();
                    let mut cycle = path[start..].to_vec();
                    cycle.push(d.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(d, graph, state, path) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        path.pop();
        state.insert(m.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in graph.keys() {
        if state.get(m.as_str()).copied().unwrap_or(0) == 0 {
            if let Some(cycle) = visit(m, &graph, &mut state, &mut Vec::new()) {
                panic!("import cycle: {}", cycle.join(" -> "));
            }
        }
    }
    // The checker sees the edges that matter: the I/O-free loop logic uses the config.
    assert!(graph["loop_core"].contains("config"), "{graph:?}");
}

#[test]
fn no_file_over_800_and_no_function_over_150_lines() {
    let mut long = Vec::new();
    for path in sources() {
        let text = text(&path);
        let non_blank = text.lines().filter(|l| !l.trim().is_empty()).count();
        if non_blank > MAX_FILE_LINES {
            long.push(format!("{}: {non_blank} non-blank lines", path.display()));
        }
        // A function starts at a line whose item is `fn` and ends at the line where its
        // braces balance again.
        let code = code(&path);
        let lines: Vec<&str> = code.lines().collect();
        let mut i = 0;
        while i < lines.len() {
            let t = lines[i].trim_start();
            let is_fn = [
                "fn ",
                "pub fn ",
                "pub(crate) fn ",
                "const fn ",
                "pub const fn ",
            ]
            .iter()
            .any(|p| t.starts_with(p));
            if !is_fn || t.ends_with(';') {
                i += 1;
                continue;
            }
            let (mut depth, mut opened, mut j) = (0i64, false, i);
            while j < lines.len() {
                for ch in lines[j].chars() {
                    match ch {
                        '{' => {
                            depth += 1;
                            opened = true;
                        }
                        '}' => depth -= 1,
                        _ => {}
                    }
                }
                if opened && depth <= 0 {
                    break;
                }
                j += 1;
            }
            let n = j - i + 1;
            if n > MAX_FN_LINES {
                long.push(format!("{}:{}: {n} lines: {t}", path.display(), i + 1));
            }
            i = j + 1;
        }
    }
    assert!(long.is_empty(), "too long:\n{}", long.join("\n"));
}
