//! The book's generated references are what the code generates: the FMU's variables (from
//! `fmu/src/variables/table.rs`), the link protocol (from `control_core::protocol`) and the
//! `servo` CLI (from clap, through `servo cli-reference`), each between its markers in
//! `docs/src/reference/`. A page that differs fails, naming the command that writes it. The
//! book's table of contents names only pages that exist.

// The xtask's generators, shared: the test compares, the xtask writes (`splice` is its alone).
#[path = "../../xtask/src/reference.rs"]
#[allow(dead_code)]
mod reference;

use host_tools::paths::workspace_root;

fn check(section: &reference::Section) {
    let path = workspace_root().join(section.page);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", section.page));
    let Some(found) = reference::current(&text, section.name) else {
        panic!("{} has lost the markers of its generated section \"{}\"", section.page, section.name);
    };
    assert!(
        found == reference::framed(&section.content),
        "{}: the generated section \"{}\" differs from what the code generates: run `{}`",
        section.page,
        section.name,
        reference::REGENERATE
    );
}

#[test]
fn the_fmu_variables_and_the_link_protocol_pages_are_current() {
    let sections = reference::library_sections();
    let variables = &sections[0].content;
    assert!(variables.lines().count() > 150, "every parameter, input and output has a row");
    for name in ["`ctrl.current_loop_hz`", "`sweep.precision_db`", "`position_command`", "`motor_position`", "`faults`"]
    {
        assert!(variables.contains(name), "the FMU variables page lacks {name}");
    }
    let protocol = &sections[1].content;
    for name in ["`Hello`", "`SaveParams`", "`Samples`", "`Crc`"] {
        assert!(protocol.contains(name), "the link protocol page lacks {name}");
    }
    for section in &sections {
        check(section);
    }
}

#[test]
fn the_cli_page_is_current() {
    // From the one definition `servo` parses with (no nested cargo: a second build inside the
    // test run, with its own feature set, rewrote the FMU's unhashed rlib under the run).
    let markdown = host_tools::cli::markdown_reference(&host_tools::command_line::command());
    for command in ["## `servo sweep`", "## `servo bench sweep`", "## `servo virtual-drive`", "--precision-db"] {
        assert!(markdown.contains(command), "servo cli-reference lacks {command}");
    }
    check(&reference::cli_section(markdown));
}

/// Every page SUMMARY.md links exists, and every page under docs/src is linked (mdBook would
/// otherwise build a book without it, or create an empty page).
#[test]
fn the_books_table_of_contents_names_every_page() {
    let src = workspace_root().join("docs/src");
    let summary = std::fs::read_to_string(src.join("SUMMARY.md")).unwrap();
    let mut linked = Vec::new();
    for part in summary.split("](").skip(1) {
        let target = part.split(')').next().unwrap();
        assert!(src.join(target).is_file(), "SUMMARY.md links {target}, which does not exist");
        linked.push(target.to_string());
    }
    for path in host_tools::page::files_under(&src, "md") {
        if !path.ends_with("SUMMARY.md") {
            let relative = path.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
            assert!(linked.contains(&relative), "docs/src/{relative} is not in SUMMARY.md");
        }
    }
}

/// Relative links between the book's pages (and from README.md into the book) point at files
/// that exist.
#[test]
fn relative_links_point_at_existing_files() {
    let root = workspace_root();
    let mut pages = vec![root.join("README.md")];
    pages.extend(host_tools::page::files_under(&root.join("docs/src"), "md"));
    let mut broken = Vec::new();
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        for part in text.split("](").skip(1) {
            let target = part.split(')').next().unwrap().split('#').next().unwrap();
            if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            if !page.parent().unwrap().join(target).exists() {
                broken.push(format!("{} → {target}", page.strip_prefix(&root).unwrap().display()));
            }
        }
    }
    assert!(broken.is_empty(), "links to missing files:\n{}", broken.join("\n"));
}
