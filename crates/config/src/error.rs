//! Errors of scenario loading, and locating a dotted field path or a byte
//! offset in the TOML text so that errors can name the line.

use std::path::{Path, PathBuf};

/// What went wrong while loading a scenario. Every variant names the file;
/// field errors also name the dotted field path (e.g. `level[1].stiffness`,
/// 0-based array indices) and the TOML line where it can be found.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{}: cannot read scenario file: {error}", file.display())]
    Io {
        file: PathBuf,
        error: std::io::Error,
    },
    /// TOML syntax error, unknown/missing field or wrong type (from the TOML parser).
    #[error("{}{}: {}{message}", file.display(), line_suffix(*line), path_prefix(path))]
    Parse {
        file: PathBuf,
        line: Option<usize>,
        path: Option<String>,
        message: String,
    },
    /// A field has a value the scenario cannot use.
    #[error("{}{}: {path}: {message}", file.display(), line_suffix(*line))]
    Invalid {
        file: PathBuf,
        line: Option<usize>,
        path: String,
        message: String,
    },
    /// The robot model could not be built from the URDF.
    #[error("{}{}: robot: {error}", file.display(), line_suffix(*line))]
    Model {
        file: PathBuf,
        line: Option<usize>,
        error: hcc_model::ModelError,
    },
}

impl ConfigError {
    /// The dotted field path the error is about, if any.
    pub fn path(&self) -> Option<&str> {
        match self {
            ConfigError::Parse { path, .. } => path.as_deref(),
            ConfigError::Invalid { path, .. } => Some(path),
            ConfigError::Model { .. } => Some("robot"),
            ConfigError::Io { .. } => None,
        }
    }

    /// The 1-based TOML line the error is about, if known.
    pub fn line(&self) -> Option<usize> {
        match self {
            ConfigError::Parse { line, .. }
            | ConfigError::Invalid { line, .. }
            | ConfigError::Model { line, .. } => *line,
            ConfigError::Io { .. } => None,
        }
    }
}

fn line_suffix(line: Option<usize>) -> String {
    match line {
        Some(l) => format!(":{l}"),
        None => String::new(),
    }
}

fn path_prefix(path: &Option<String>) -> String {
    match path {
        Some(p) if !p.is_empty() => format!("{p}: "),
        _ => String::new(),
    }
}

/// Builds [`ConfigError::Invalid`] for the field `path`, looking up its line in `text`.
pub(crate) fn invalid(
    file: &Path,
    text: &str,
    path: &str,
    message: impl Into<String>,
) -> ConfigError {
    ConfigError::Invalid {
        file: file.to_path_buf(),
        line: locate_path(text, path),
        path: path.to_string(),
        message: message.into(),
    }
}

/// Converts a TOML parser error into [`ConfigError::Parse`], with the line and the
/// dotted path of the key at the error position.
pub(crate) fn from_toml(file: &Path, text: &str, e: &toml::de::Error) -> ConfigError {
    let (line, path) = match e.span() {
        Some(span) => (Some(line_of(text, span.start)), path_at(text, span.start)),
        None => (None, None),
    };
    ConfigError::Parse {
        file: file.to_path_buf(),
        line,
        path,
        message: e.message().trim().to_string(),
    }
}

/// 1-based line number of a byte offset.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    let offset = offset.min(text.len());
    text.as_bytes()[..offset]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Strips a trailing comment (a `#` outside a string) and surrounding whitespace.
fn strip_comment(line: &str) -> &str {
    let mut in_str: Option<char> = None;
    for (i, c) in line.char_indices() {
        match (in_str, c) {
            (None, '"') | (None, '\'') => in_str = Some(c),
            (Some(q), c) if c == q => in_str = None,
            (None, '#') => return line[..i].trim(),
            _ => {}
        }
    }
    line.trim()
}

fn clean_key(k: &str) -> String {
    k.split('.')
        .map(|p| p.trim().trim_matches('"').trim_matches('\''))
        .collect::<Vec<_>>()
        .join(".")
}

/// One scanned line: the table path it belongs to and its key, if it is `key = value`.
struct ScannedLine {
    table: String,
    key: Option<String>,
    is_header: bool,
}

/// Walks the document line by line, tracking `[table]` / `[[array]]` headers
/// (with 0-based indices for arrays of tables).
fn scan(text: &str) -> Vec<ScannedLine> {
    let mut counts: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut table = String::new();
    let mut out = Vec::new();
    // Multi-line arrays: lines inside an open bracket continue the previous key.
    let mut depth: i32 = 0;
    let mut last_key: Option<String> = None;
    for raw in text.split('\n') {
        let line = strip_comment(raw);
        if depth > 0 {
            depth = (depth + bracket_balance(line)).max(0);
            out.push(ScannedLine {
                table: table.clone(),
                key: last_key.clone(),
                is_header: false,
            });
            continue;
        }
        if let Some(name) = line.strip_prefix("[[").and_then(|l| l.strip_suffix("]]")) {
            let name = clean_key(name);
            // Nested arrays of tables (e.g. `[[simulation.wrench]]`) are indexed
            // within the current element of their parent array.
            let key = parent_with_index(&table, &name);
            let idx = counts.entry(key.clone()).or_insert(0);
            table = format!("{key}[{}]", *idx);
            *idx += 1;
            last_key = None;
            out.push(ScannedLine {
                table: table.clone(),
                key: None,
                is_header: true,
            });
        } else if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            table = parent_with_index(&table, &clean_key(name));
            last_key = None;
            out.push(ScannedLine {
                table: table.clone(),
                key: None,
                is_header: true,
            });
        } else if let Some(eq) = line.find('=') {
            let key = clean_key(&line[..eq]);
            depth = bracket_balance(&line[eq + 1..]).max(0);
            last_key = Some(key.clone());
            out.push(ScannedLine {
                table: table.clone(),
                key: Some(key),
                is_header: false,
            });
        } else {
            out.push(ScannedLine {
                table: table.clone(),
                key: None,
                is_header: false,
            });
        }
    }
    out
}

/// Rewrites a header name `a.b` so that a prefix matching the current table's
/// array element keeps its index (`level[2]` + `level.task` → `level[2].task`).
fn parent_with_index(current: &str, name: &str) -> String {
    let current_plain = strip_indices(current);
    if !current.is_empty() && name.starts_with(&format!("{current_plain}.")) {
        format!("{current}{}", &name[current_plain.len()..])
    } else {
        // Try shorter prefixes of the current table.
        let mut cur = current.to_string();
        while let Some(pos) = cur.rfind('.') {
            cur.truncate(pos);
            let plain = strip_indices(&cur);
            if name.starts_with(&format!("{plain}.")) {
                return format!("{cur}{}", &name[plain.len()..]);
            }
        }
        name.to_string()
    }
}

fn strip_indices(p: &str) -> String {
    let mut s = String::with_capacity(p.len());
    let mut skip = false;
    for c in p.chars() {
        match c {
            '[' => skip = true,
            ']' => skip = false,
            _ if !skip => s.push(c),
            _ => {}
        }
    }
    s
}

fn bracket_balance(s: &str) -> i32 {
    let mut in_str: Option<char> = None;
    let mut d = 0;
    for c in s.chars() {
        match (in_str, c) {
            (None, '"') | (None, '\'') => in_str = Some(c),
            (Some(q), c) if c == q => in_str = None,
            (None, '[') | (None, '{') => d += 1,
            (None, ']') | (None, '}') => d -= 1,
            _ => {}
        }
    }
    d
}

fn join(table: &str, key: &str) -> String {
    if table.is_empty() {
        key.to_string()
    } else {
        format!("{table}.{key}")
    }
}

/// Dotted path of the key (or table header) at a byte offset.
pub(crate) fn path_at(text: &str, offset: usize) -> Option<String> {
    let line = line_of(text, offset);
    let scanned = scan(text);
    let l = scanned.get(line - 1)?;
    Some(match &l.key {
        Some(k) => join(&l.table, k),
        None => l.table.clone(),
    })
}

/// 1-based line where a dotted path (e.g. `level[1].stiffness`, `simulation.wrench[0].force`)
/// is defined; falls back to the closest enclosing table or key. Element indices of
/// plain arrays (`q0[3]`) are ignored.
pub(crate) fn locate_path(text: &str, path: &str) -> Option<usize> {
    let scanned = scan(text);
    let mut candidate = path.to_string();
    loop {
        for (i, l) in scanned.iter().enumerate() {
            let p = match &l.key {
                Some(k) => join(&l.table, k),
                None if l.is_header => l.table.clone(),
                None => continue,
            };
            if p == candidate {
                return Some(i + 1);
            }
        }
        // Drop the last component (`.key` or `[index]`) and try again.
        let cut = candidate.rfind(['.', '['])?;
        candidate.truncate(cut);
        if candidate.is_empty() {
            return None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOC: &str = r#"name = "x"
[robot]
urdf = "a.urdf" # comment
[[level]]
task = "position"
stiffness = [
  1, 2,
]
[[level]]
task = "joint"
goal = [0.3]
[simulation]
duration_s = 3.0
[[simulation.wrench]]
link = "tcp"
[[simulation.wrench]]
link = "base"
force = [1, 2, 3]
"#;

    #[test]
    fn locate_paths() {
        assert_eq!(locate_path(DOC, "robot.urdf"), Some(3));
        assert_eq!(locate_path(DOC, "level[0].stiffness"), Some(6));
        assert_eq!(locate_path(DOC, "level[1].goal"), Some(11));
        assert_eq!(locate_path(DOC, "level[1].goal[0]"), Some(11));
        assert_eq!(locate_path(DOC, "level[1].damping"), Some(9));
        assert_eq!(locate_path(DOC, "simulation.duration_s"), Some(13));
        assert_eq!(locate_path(DOC, "simulation.wrench[1].force"), Some(18));
        assert_eq!(locate_path(DOC, "simulation.wrench[0]"), Some(14));
        assert_eq!(locate_path(DOC, "initial.q0"), None);
    }

    #[test]
    fn path_at_offsets() {
        let off = DOC.find("2,\n]").unwrap();
        assert_eq!(path_at(DOC, off).as_deref(), Some("level[0].stiffness"));
        let off = DOC.find("\"base\"").unwrap();
        assert_eq!(
            path_at(DOC, off).as_deref(),
            Some("simulation.wrench[1].link")
        );
        assert_eq!(path_at(DOC, 0).as_deref(), Some("name"));
    }
}
