//! The law's rooms stay small enough to read: no source file of hcc-control
//! over 600 lines, no function over 80 (its signature to its closing brace,
//! as rustfmt lays it out). A stage that outgrows this is split, not let grow.

use std::path::{Path, PathBuf};

const MAX_FILE_LINES: usize = 600;
const MAX_FN_LINES: usize = 80;

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src readable") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// A function's name if `line` opens one (`fn`, after visibility and
/// qualifiers), with its indentation.
fn opens_fn(line: &str) -> Option<(&str, &str)> {
    let body = line.trim_start();
    let indent = &line[..line.len() - body.len()];
    let mut rest = body;
    for prefix in [
        "pub(crate) ",
        "pub(super) ",
        "pub ",
        "const ",
        "unsafe ",
        "async ",
    ] {
        rest = rest.strip_prefix(prefix).unwrap_or(rest);
    }
    let name = rest.strip_prefix("fn ")?;
    let end = name.find(|c: char| !(c.is_alphanumeric() || c == '_'))?;
    Some((indent, &name[..end]))
}

/// (name, first line, lines) of every function with a body in `text`.
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let Some((indent, name)) = opens_fn(line) else {
            continue;
        };
        // A body on one line, or a declaration without one.
        let t = line.trim_end();
        if t.ends_with('}') || t.ends_with(';') {
            continue;
        }
        let close = format!("{indent}}}");
        if let Some(j) = lines[i..].iter().position(|l| *l == close) {
            out.push((name.to_string(), i + 1, j + 1));
        }
    }
    out
}

#[test]
fn the_measure_counts_a_function_from_its_signature_to_its_brace() {
    let text = "/// doc\npub(crate) fn a(\n    x: u8,\n) {\n    x;\n}\n\nimpl T {\n    fn b() {}\n    pub fn c() -> u8 {\n        1\n    }\n}\n";
    let f = functions(text);
    assert_eq!(f, vec![("a".into(), 2, 5), ("c".into(), 10, 3)]);
}

#[test]
fn no_file_over_600_lines_and_no_function_over_80() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    files.sort();
    assert!(files.len() > 20, "the sources were not found: {files:?}");
    let mut too_long = Vec::new();
    for path in &files {
        let text = std::fs::read_to_string(path).expect("readable");
        let name = path.strip_prefix(&src).unwrap().display().to_string();
        let n = text.lines().count();
        if n > MAX_FILE_LINES {
            too_long.push(format!("{name}: {n} lines"));
        }
        for (f, at, len) in functions(&text) {
            if len > MAX_FN_LINES {
                too_long.push(format!("{name}:{at}: fn {f} has {len} lines"));
            }
        }
    }
    assert!(
        too_long.is_empty(),
        "over {MAX_FILE_LINES} lines a file or {MAX_FN_LINES} a function:\n{}",
        too_long.join("\n")
    );
}
