//! The README and the book under docs/ hold together: every page is in docs/SUMMARY.md, and
//! every relative link (pages, results, screenshots, samples) names a file that exists.

use std::path::{Path, PathBuf};

/// README.md and every Markdown file under docs/.
fn pages(root: &Path) -> Vec<PathBuf> {
    let mut out = vec![root.join("README.md")];
    let mut stack = vec![root.join("docs")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The targets of a page's Markdown links `[text](target)`, outside code blocks.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with("    ")) {
        let mut rest = line;
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let end = after.find(')').unwrap_or(after.len());
            out.push(after[..end].to_owned());
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_names_a_file_that_exists_and_every_page_is_in_the_book() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut broken = Vec::new();
    for page in pages(root) {
        let text = std::fs::read_to_string(&page).unwrap();
        for target in links(&text) {
            if target.contains("://") || target.starts_with('#') || target.starts_with("mailto:") {
                continue;
            }
            let file = target.split('#').next().unwrap_or("");
            if !page.parent().unwrap().join(file).exists() {
                broken.push(format!("{}: {target}", page.display()));
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    let summary = std::fs::read_to_string(root.join("docs/SUMMARY.md")).unwrap();
    let listed = links(&summary);
    for page in pages(root) {
        let Ok(rel) = page.strip_prefix(root.join("docs")) else {
            continue;
        };
        let rel = rel.to_string_lossy();
        if rel != "SUMMARY.md" {
            assert!(
                listed.iter().any(|l| *l == rel),
                "docs/{rel} is not in docs/SUMMARY.md"
            );
        }
    }
}

/// docs/config.md and docs/pipeline-config.schema.json are what the configuration types say
/// now (`RAILFUSE_BLESS=1` rewrites them after a change to the types or their doc comments).
#[test]
fn the_configuration_reference_and_schema_are_generated_from_the_types() {
    use railfuse_refuse::config_reference::{markdown, schema};
    let registry = railfuse_refuse::registry::Registry::standard();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let json = serde_json::to_string_pretty(&schema(&registry)).unwrap() + "\n";
    for (file, text) in [
        ("docs/config.md", markdown(&registry)),
        ("docs/pipeline-config.schema.json", json),
    ] {
        let path = root.join(file);
        if std::env::var_os("RAILFUSE_BLESS").is_some() {
            std::fs::write(&path, &text).unwrap();
        }
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            have == text,
            "{file} is not what the configuration types say: regenerate it with \
             RAILFUSE_BLESS=1 cargo test --test docs"
        );
    }
}
