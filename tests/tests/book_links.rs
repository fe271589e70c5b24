//! The rendered book's links: every relative link and image of every page of `target/book/`
//! (built by `scripts/book`, which the test command runs first) reaches a file, inside the book
//! or, for the sources the pages point at, in the repository (the book sits as deep under
//! `target/` as its Markdown under `docs/`, so those links resolve from both); and every
//! `#anchor` into a page of the book names an element id of that page. README.md's links
//! into the book are checked the same way against the pages they render to.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

use host_tools::paths::workspace_root;

/// The values of every `attribute="…"` in an HTML text.
fn attribute_values<'a>(html: &'a str, attribute: &str) -> Vec<&'a str> {
    let key = format!(" {attribute}=\"");
    html.split(&key).skip(1).filter_map(|rest| rest.split('"').next()).collect()
}

/// `path` with `.` and `..` resolved lexically (the files may not exist).
fn normalise(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

/// An HTML entity-encoded attribute value as the browser reads it.
fn decode(value: &str) -> String {
    value.replace("&amp;", "&").replace("&quot;", "\"").replace("&#39;", "'").replace("%20", " ")
}

/// Checks `link` (as written in `from`, a file whose directory relative links start from)
/// against the files and the ids of the book's pages; a broken one is pushed to `broken`.
fn check_link(
    link: &str,
    from: &Path,
    ids: &BTreeMap<PathBuf, BTreeSet<String>>,
    root: &Path,
    broken: &mut Vec<String>,
) {
    let link = decode(link);
    if link.is_empty() || link.contains("://") || link.starts_with("mailto:") || link.starts_with("javascript:") {
        return;
    }
    let (path, fragment) = link.split_once('#').unwrap_or((&link, ""));
    let target = if path.is_empty() { from.to_path_buf() } else { normalise(&from.parent().unwrap().join(path)) };
    let shown = from.strip_prefix(root).unwrap_or(from).display();
    if !target.exists() {
        broken.push(format!("{shown}: {link} (no such file)"));
        return;
    }
    if fragment.is_empty() {
        return;
    }
    // Anchors are checked where the target is one of the book's pages.
    if let Some(page_ids) = ids.get(&target) {
        if !page_ids.contains(fragment) {
            broken.push(format!("{shown}: {link} (no element with id \"{fragment}\" in that page)"));
        }
    }
}

#[test]
fn the_rendered_books_links_and_anchors_resolve() {
    let root = workspace_root();
    let book = root.join("target/book");
    assert!(
        book.join("index.html").is_file(),
        "the book is not built: `scripts/book` builds it into target/book (the test command runs it before the tests)"
    );
    let pages = host_tools::page::files_under(&book, "html");
    let ids: BTreeMap<PathBuf, BTreeSet<String>> = pages
        .iter()
        .map(|p| {
            let html = std::fs::read_to_string(p).unwrap();
            (p.clone(), attribute_values(&html, "id").into_iter().map(decode).collect())
        })
        .collect();
    let mut broken = Vec::new();
    let mut checked = 0;
    for page in &pages {
        let html = std::fs::read_to_string(page).unwrap();
        for link in attribute_values(&html, "href").into_iter().chain(attribute_values(&html, "src")) {
            check_link(link, page, &ids, &root, &mut broken);
            checked += 1;
        }
    }
    // Every page of SUMMARY.md renders, so the book is more than its index.
    assert!(pages.len() >= 20 && checked >= 500, "{} pages, {checked} links: is target/book complete?", pages.len());

    // README.md's links into the book: docs/src/X.md#a is checked as target/book/X.html#a.
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    for part in readme.split("](").skip(1) {
        let link = part.split(')').next().unwrap();
        let Some(inside) = link.strip_prefix("docs/src/") else { continue };
        let (path, fragment) = inside.split_once('#').unwrap_or((inside, ""));
        let rendered = match path.strip_suffix(".md") {
            // The table of contents renders as every page's sidebar; the book opens at index.html.
            Some("SUMMARY") => "index.html".to_string(),
            Some(stem) => format!("{stem}.html"),
            None => path.to_string(),
        };
        let as_rendered = if fragment.is_empty() { rendered } else { format!("{rendered}#{fragment}") };
        check_link(&as_rendered, &book.join("README.md"), &ids, &root, &mut broken);
    }
    assert!(broken.is_empty(), "{} broken links in the book:\n{}", broken.len(), broken.join("\n"));
}

/// The checker itself: a missing file, a missing anchor and a good anchor, on a small book.
#[test]
fn the_link_checker_tells_a_missing_file_and_a_missing_anchor() {
    let dir = std::env::temp_dir().join(format!("servo-book-links-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    let a = dir.join("a.html");
    let b = dir.join("sub/b.html");
    std::fs::write(&a, r#"<h1 id="top">A</h1><a href="sub/b.html#here">b</a>"#).unwrap();
    std::fs::write(&b, r#"<h2 id="here">B</h2>"#).unwrap();
    let ids: BTreeMap<PathBuf, BTreeSet<String>> =
        [(a.clone(), ["top".to_string()].into()), (b.clone(), ["here".to_string()].into())].into();
    let mut broken = Vec::new();
    for link in ["sub/b.html#here", "#top", "sub/../a.html"] {
        check_link(link, &a, &ids, &dir, &mut broken);
    }
    assert!(broken.is_empty(), "{broken:?}");
    check_link("sub/b.html#gone", &a, &ids, &dir, &mut broken);
    check_link("c.html", &a, &ids, &dir, &mut broken);
    check_link("../a.html#top", &b, &ids, &dir, &mut broken);
    assert_eq!(broken.len(), 2, "{broken:?}");
    assert!(broken[0].contains("no element with id \"gone\"") && broken[1].contains("no such file"), "{broken:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}
