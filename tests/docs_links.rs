//! The README and the guides in `docs/` link to each other, to figures and to
//! source files; on a plain clone every such link must resolve. This test
//! reads the Markdown links of `README.md` and of every `.md` file under
//! `docs/` — inline links and images `[text](target)`, and reference
//! definitions `[label]: target` — outside code blocks, code spans and HTML
//! comments, and checks every relative target: the file or directory exists
//! inside the repository, and a `#fragment` names a heading of the Markdown
//! file it points to (GitHub's anchors: the heading's text lower-cased, its
//! punctuation dropped, spaces as hyphens, `-1`, `-2`, … for repeats).
//! External links (`https:`, `mailto:`, any scheme) are not fetched.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

use hcc_system_tests::{TempDir, repo_root};

/// One link as written: the file, its line, the target.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Link {
    file: PathBuf,
    line: usize,
    target: String,
}

/// The Markdown files whose links are checked: `README.md` and every `.md`
/// under `docs/`, in a stable order.
fn markdown_files(root: &Path) -> Vec<PathBuf> {
    let mut files = vec![root.join("README.md")];
    let mut dirs = vec![root.join("docs")];
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// The text of a Markdown file with what is not prose blanked out: fenced
/// code blocks, code spans and HTML comments become spaces (line breaks are
/// kept, so line numbers stay right).
fn prose(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut fence: Option<(char, usize)> = None;
    let mut in_comment = false;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_start_matches(' ');
        let indent = line.len() - trimmed.len();
        let marker = trimmed.chars().next().filter(|c| *c == '`' || *c == '~');
        let run = marker.map_or(0, |m| trimmed.chars().take_while(|c| *c == m).count());
        if let Some((m, n)) = fence {
            if indent <= 3 && marker == Some(m) && run >= n && trimmed[run..].trim().is_empty() {
                fence = None;
            }
            out.push_str(&blank(line));
            continue;
        }
        if !in_comment && indent <= 3 && run >= 3 {
            fence = marker.map(|m| (m, run));
            out.push_str(&blank(line));
            continue;
        }
        out.push_str(&strip_inline(line, &mut in_comment));
    }
    out
}

/// Spaces for every character of `s` but its line break.
fn blank(s: &str) -> String {
    s.chars()
        .map(|c| if c == '\n' { '\n' } else { ' ' })
        .collect()
}

/// One line with its code spans and (possibly multi-line) HTML comments
/// blanked out.
fn strip_inline(line: &str, in_comment: &mut bool) -> String {
    let chars: Vec<char> = line.chars().collect();
    let mut out = String::with_capacity(line.len());
    let mut i = 0;
    while i < chars.len() {
        if *in_comment {
            if chars[i..].starts_with(&['-', '-', '>']) {
                *in_comment = false;
                out.push_str("   ");
                i += 3;
            } else {
                out.push(if chars[i] == '\n' { '\n' } else { ' ' });
                i += 1;
            }
            continue;
        }
        if chars[i..].starts_with(&['<', '!', '-', '-']) {
            *in_comment = true;
            out.push_str("    ");
            i += 4;
            continue;
        }
        if chars[i] == '`' {
            let run = chars[i..].iter().take_while(|c| **c == '`').count();
            // The closing run of exactly as many backticks.
            let mut j = i + run;
            let mut close = None;
            while j < chars.len() {
                if chars[j] == '`' {
                    let r = chars[j..].iter().take_while(|c| **c == '`').count();
                    if r == run {
                        close = Some(j);
                        break;
                    }
                    j += r;
                } else {
                    j += 1;
                }
            }
            if let Some(j) = close {
                out.extend(std::iter::repeat_n(' ', j + run - i));
                i = j + run;
                continue;
            }
        }
        out.push(chars[i]);
        i += 1;
    }
    out
}

/// The links of one file's prose.
fn links_of(file: &Path, text: &str) -> Vec<Link> {
    let mut links = Vec::new();
    for (k, line) in prose(text).lines().enumerate() {
        let chars: Vec<char> = line.chars().collect();
        // Reference definitions: `[label]: target`, up to three spaces in.
        let trimmed = line.trim_start();
        if line.len() - trimmed.len() <= 3
            && trimmed.starts_with('[')
            && let Some(end) = trimmed.find(']')
            && trimmed[end + 1..].starts_with(':')
        {
            let rest = trimmed[end + 2..].trim();
            if let Some(target) = rest.split_whitespace().next() {
                links.push(Link {
                    file: file.to_path_buf(),
                    line: k + 1,
                    target: target.trim_matches(|c| c == '<' || c == '>').to_string(),
                });
            }
            continue;
        }
        // Inline links and images: `[text](target "title")`, the `[` matched.
        for i in 0..chars.len().saturating_sub(1) {
            if chars[i] != ']' || chars[i + 1] != '(' || !opens_before(&chars[..i]) {
                continue;
            }
            let mut depth = 0usize;
            let mut end = None;
            for (j, c) in chars.iter().enumerate().skip(i + 2) {
                match c {
                    '(' => depth += 1,
                    ')' if depth == 0 => {
                        end = Some(j);
                        break;
                    }
                    ')' => depth -= 1,
                    _ => {}
                }
            }
            let Some(end) = end else { continue };
            let inside: String = chars[i + 2..end].iter().collect();
            let inside = inside.trim();
            let target = if let Some(rest) = inside.strip_prefix('<') {
                rest.split('>').next().unwrap_or("").to_string()
            } else {
                inside.split_whitespace().next().unwrap_or("").to_string()
            };
            links.push(Link {
                file: file.to_path_buf(),
                line: k + 1,
                target,
            });
        }
    }
    links
}

/// Whether a `[` that the `]` at the end of `before` closes is on the line.
fn opens_before(before: &[char]) -> bool {
    let mut depth = 0usize;
    for c in before.iter().rev() {
        match c {
            ']' => depth += 1,
            '[' if depth == 0 => return true,
            '[' => depth -= 1,
            _ => {}
        }
    }
    false
}

/// GitHub's anchors of a Markdown file's headings.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    for line in prose_keeping_code_spans(text).lines() {
        let trimmed = line.trim_start();
        if line.len() - trimmed.len() > 3 {
            continue;
        }
        let hashes = trimmed.chars().take_while(|c| *c == '#').count();
        if hashes == 0 || hashes > 6 {
            continue;
        }
        let rest = &trimmed[hashes..];
        if !(rest.is_empty() || rest.starts_with(' ') || rest.starts_with('\t')) {
            continue;
        }
        let title = rest.trim().trim_end_matches('#').trim();
        let slug = slug(title);
        let n = seen.entry(slug.clone()).or_insert(0);
        out.insert(if *n == 0 {
            slug.clone()
        } else {
            format!("{slug}-{n}")
        });
        *n += 1;
    }
    out
}

/// The file with only its fenced code blocks blanked (headings may carry code
/// spans, whose text is part of the anchor).
fn prose_keeping_code_spans(text: &str) -> String {
    let mut out = String::new();
    let mut fence: Option<(char, usize)> = None;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_start_matches(' ');
        let marker = trimmed.chars().next().filter(|c| *c == '`' || *c == '~');
        let run = marker.map_or(0, |m| trimmed.chars().take_while(|c| *c == m).count());
        if let Some((m, n)) = fence {
            if marker == Some(m) && run >= n && trimmed[run..].trim().is_empty() {
                fence = None;
            }
            out.push('\n');
            continue;
        }
        if run >= 3 {
            fence = marker.map(|m| (m, run));
            out.push('\n');
            continue;
        }
        out.push_str(line);
    }
    out
}

/// GitHub's anchor of a heading: links replaced by their text, lower-cased,
/// everything but letters, marks, digits, `_`, `-` and spaces dropped, spaces
/// as hyphens.
fn slug(title: &str) -> String {
    // [text](target) → text
    let mut plain = String::new();
    let mut rest = title;
    while let Some(open) = rest.find('[') {
        let Some(close) = rest[open..].find("](") else {
            break;
        };
        let Some(end) = rest[open + close..].find(')') else {
            break;
        };
        plain.push_str(&rest[..open]);
        plain.push_str(&rest[open + 1..open + close]);
        rest = &rest[open + close + end + 1..];
    }
    plain.push_str(rest);
    plain
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            '-' | '_' => Some(c),
            c if c.is_alphanumeric() => Some(c),
            _ => None,
        })
        .collect()
}

/// Percent-decoding of a link's path (`%20` and the like).
fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && i + 2 < bytes.len()
            && let Some(hex) = s.get(i + 1..i + 3)
            && let Ok(b) = u8::from_str_radix(hex, 16)
        {
            out.push(b);
            i += 3;
            continue;
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `path` with `.` and `..` resolved lexically; `None` if it leaves `root`.
fn normalise(root: &Path, path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::CurDir => {}
            other => out.push(other.as_os_str()),
        }
    }
    out.starts_with(root).then_some(out)
}

/// Whether a target is external (has a URL scheme such as `https:`).
fn is_external(target: &str) -> bool {
    match target.find(':') {
        Some(colon) => {
            let scheme = &target[..colon];
            !scheme.is_empty()
                && scheme
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '+' || c == '-' || c == '.')
                && !target[..colon].contains('/')
        }
        None => false,
    }
}

/// What is wrong with the links of `files` (none: every link resolves), and
/// how many relative links were checked.
fn check(root: &Path, files: &[PathBuf]) -> (Vec<String>, usize) {
    let mut problems = Vec::new();
    let mut checked = 0;
    let mut anchor_cache: BTreeMap<PathBuf, BTreeSet<String>> = BTreeMap::new();
    let mut anchors_of = |path: &Path| -> BTreeSet<String> {
        anchor_cache
            .entry(path.to_path_buf())
            .or_insert_with(|| anchors(&std::fs::read_to_string(path).unwrap_or_default()))
            .clone()
    };
    for file in files {
        let text = match std::fs::read_to_string(file) {
            Ok(t) => t,
            Err(e) => {
                problems.push(format!("{}: cannot read: {e}", file.display()));
                continue;
            }
        };
        let shown = file
            .strip_prefix(root)
            .unwrap_or(file)
            .display()
            .to_string();
        for link in links_of(file, &text) {
            let at = format!("{shown}:{}: ({})", link.line, link.target);
            if link.target.is_empty() {
                problems.push(format!("{at}: empty link target"));
                continue;
            }
            if is_external(&link.target) {
                continue;
            }
            checked += 1;
            let (path_part, fragment) = match link.target.split_once('#') {
                Some((p, f)) => (p, Some(f)),
                None => (link.target.as_str(), None),
            };
            let path_part = percent_decode(path_part);
            let resolved = if path_part.is_empty() {
                Some(file.clone())
            } else if let Some(from_root) = path_part.strip_prefix('/') {
                normalise(root, &root.join(from_root))
            } else {
                normalise(root, &file.parent().unwrap_or(root).join(&path_part))
            };
            let Some(resolved) = resolved else {
                problems.push(format!("{at}: leaves the repository"));
                continue;
            };
            if !resolved.exists() {
                let shown = resolved.strip_prefix(root).unwrap_or(&resolved);
                problems.push(format!("{at}: {} does not exist", shown.display()));
                continue;
            }
            if let Some(fragment) = fragment {
                let is_markdown = resolved.extension().is_some_and(|e| e == "md");
                if is_markdown && !anchors_of(&resolved).contains(&percent_decode(fragment)) {
                    problems.push(format!(
                        "{at}: no heading with the anchor #{fragment} in {}",
                        resolved.strip_prefix(root).unwrap_or(&resolved).display()
                    ));
                }
            }
        }
    }
    (problems, checked)
}

#[test]
fn every_relative_link_of_the_readme_and_the_guides_resolves() {
    let root = repo_root();
    let files = markdown_files(&root);
    assert!(
        files.len() >= 5,
        "README.md and the guides in docs/: found {files:?}"
    );
    let (problems, checked) = check(&root, &files);
    assert!(
        problems.is_empty(),
        "broken links in the documentation:\n{}",
        problems.join("\n")
    );
    // The parser must be finding links at all (the README and the guides hold about a hundred).
    assert!(checked >= 50, "only {checked} relative links found");
}

#[test]
fn a_broken_link_a_missing_anchor_and_an_escape_are_found_and_code_is_not_read() {
    let dir = TempDir::new("docs_links");
    let root = dir.path();
    std::fs::create_dir_all(root.join("docs/figures")).unwrap();
    std::fs::write(root.join("docs/figures/plot.png"), b"png").unwrap();
    std::fs::write(
        root.join("docs/guide.md"),
        "# A guide\n\n## `hcc run` and more: the real-time set-up\n\n## Repeat\n\n## Repeat\n",
    )
    .unwrap();
    let readme = "\
# Title

See [the guide](docs/guide.md), [its section](docs/guide.md#hcc-run-and-more-the-real-time-set-up),
[the second repeat](docs/guide.md#repeat-1), [this file](#title) and ![a plot](docs/figures/plot.png).
[a folder](docs/figures) and [the web](https://example.invalid/x#y) are fine.

Broken: [missing file](docs/missing.md), [missing anchor](docs/guide.md#nowhere),
[out](../outside.md) and [local anchor](#nope).
[ref]: docs/also-missing.md

`[not a link](docs/none.md)` and <!-- [nor this](docs/none.md) --> are not read, nor is

```sh
echo [code](docs/none.md)
```
";
    std::fs::write(root.join("README.md"), readme).unwrap();
    let files = markdown_files(root);
    assert_eq!(files.len(), 2, "{files:?}");
    let (problems, checked) = check(root, &files);
    let expected = [
        "README.md:7: (docs/missing.md)",
        "README.md:7: (docs/guide.md#nowhere)",
        "README.md:8: (../outside.md)",
        "README.md:8: (#nope)",
        "README.md:9: (docs/also-missing.md)",
    ];
    assert_eq!(
        problems.len(),
        expected.len(),
        "problems found:\n{}",
        problems.join("\n")
    );
    for (problem, start) in problems.iter().zip(expected) {
        assert!(problem.starts_with(start), "{problem} (expected {start})");
    }
    assert_eq!(checked, 11, "{problems:?}");
}

#[test]
fn anchors_follow_github() {
    assert_eq!(
        slug("Timing and jitter (`hcc jitter`)"),
        "timing-and-jitter-hcc-jitter"
    );
    assert_eq!(
        slug("The safety layer: out of reach, in conflict, at the limits"),
        "the-safety-layer-out-of-reach-in-conflict-at-the-limits"
    );
    assert_eq!(slug("The 6-D pose, [linked](x.md)"), "the-6-d-pose-linked");
    assert_eq!(slug("Schéma_v2 — état"), "schéma_v2--état");
}
