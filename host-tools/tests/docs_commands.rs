//! Every `servo` command the README and the book show parses with the CLI as it is: a command
//! line in an `sh` block whole, a command named in inline code (`servo tune --device`, a
//! mention that leaves out values) as far as its subcommands and options go. An option or a
//! command renamed or removed fails here, naming the page and the command. Usage sketches
//! (with `[optional]` parts or `…`) are skipped.

use clap::error::ErrorKind;
use host_tools::command_line::command;
use host_tools::paths::workspace_root;

/// The `servo …` command lines of a page, whitespace collapsed, each with whether it is a whole
/// command line (from an `sh` block: continuation lines joined, a trailing comment, `&` or
/// pipe cut off) or a mention (inline code).
fn commands(page: &str) -> Vec<(String, bool)> {
    let mut found = Vec::new();
    let (mut in_sh, mut in_block) = (false, false);
    let mut joined = String::new();
    // Prose is read a paragraph at a time: an inline span may wrap onto the next line.
    let mut paragraph = String::new();
    let mentions = |paragraph: &mut String, found: &mut Vec<(String, bool)>| {
        for (i, span) in paragraph.split('`').enumerate() {
            let span = servo_command(span);
            if i % 2 == 1 && span.starts_with("servo ") {
                found.push((collapse(span.trim_end_matches('&')), false));
            }
        }
        paragraph.clear();
    };
    for line in page.lines() {
        let trimmed = line.trim_start();
        if let Some(lang) = trimmed.strip_prefix("```") {
            mentions(&mut paragraph, &mut found);
            in_sh = !in_block && matches!(lang.trim(), "sh" | "bash" | "console");
            in_block = !in_block;
            continue;
        }
        if in_block && !in_sh {
            continue;
        }
        if in_sh {
            joined.push_str(line.trim_end().trim_end_matches('\\'));
            if line.trim_end().ends_with('\\') {
                joined.push(' ');
                continue;
            }
            let text = std::mem::take(&mut joined);
            let text = text.split(" #").next().unwrap().split(" | ").next().unwrap().trim().trim_end_matches('&');
            let text = servo_command(text.trim().trim_start_matches("$ "));
            if text.starts_with("servo ") {
                found.push((collapse(&text), true));
            }
        } else if trimmed.is_empty() {
            mentions(&mut paragraph, &mut found);
        } else {
            paragraph.push_str(line);
            paragraph.push(' ');
        }
    }
    mentions(&mut paragraph, &mut found);
    found
}

/// `cargo run … --bin servo -- ARGS` as `servo ARGS` (the README's form on a fresh clone).
fn servo_command(text: &str) -> String {
    match text.split_once("--bin servo -- ") {
        Some((cargo, args)) if cargo.trim_start().starts_with("cargo run") => format!("servo {args}"),
        _ => text.to_string(),
    }
}

fn collapse(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Shell words of `line` (quotes removed; no variables or globs in these commands).
fn words(line: &str) -> Vec<String> {
    let (mut out, mut word, mut quote) = (Vec::new(), String::new(), None);
    for c in line.chars() {
        match (quote, c) {
            (None, '\'' | '"') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            (None, c) if c.is_whitespace() => {
                if !word.is_empty() {
                    out.push(std::mem::take(&mut word));
                }
            }
            _ => word.push(c),
        }
    }
    if !word.is_empty() {
        out.push(word);
    }
    out
}

#[test]
fn every_servo_command_in_the_docs_parses() {
    let root = workspace_root();
    let mut pages = vec![root.join("README.md")];
    pages.extend(host_tools::page::files_under(&root.join("docs/src"), "md"));
    let (mut checked, mut broken) = (0, Vec::new());
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        for (line, whole) in commands(&text) {
            if line.contains('[') || line.contains('…') || line.contains("...") || line.contains('<') {
                continue;
            }
            match command().try_get_matches_from(words(&line)) {
                Ok(_) => checked += 1,
                // A group named alone (`servo bench`), or help.
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::DisplayHelp
                            | ErrorKind::DisplayVersion
                            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
                            | ErrorKind::MissingSubcommand
                    ) =>
                {
                    checked += 1
                }
                // A mention leaves values and required arguments out; its words must still be
                // the CLI's.
                Err(e) if !whole && !matches!(e.kind(), ErrorKind::UnknownArgument | ErrorKind::InvalidSubcommand) => {
                    checked += 1
                }
                Err(e) => broken.push(format!(
                    "{}: `{line}`: {}",
                    page.strip_prefix(&root).unwrap().display(),
                    e.to_string().lines().next().unwrap_or("")
                )),
            }
        }
    }
    assert!(broken.is_empty(), "{} commands in the docs do not parse:\n{}", broken.len(), broken.join("\n"));
    assert!(checked >= 100, "only {checked} commands found: is the extraction broken?");
}

/// The extraction: continuation lines, comments, inline spans; a renamed option is caught.
#[test]
fn the_extraction_finds_commands_and_a_wrong_option_fails() {
    let page = "Run `servo sweep\n--oracle` first.\n\n```sh\nservo sweep --point torque \\\n  --amplitude 0.2   # a comment\nservo index &\ncargo run --release -q -p host-tools --bin servo -- run --fmpy\n```\n\n```text\n`servo nothing`\n```\n";
    let found: Vec<_> = commands(page).into_iter().map(|(c, whole)| format!("{whole} {c}")).collect();
    assert_eq!(
        found,
        [
            "false servo sweep --oracle",
            "true servo sweep --point torque --amplitude 0.2",
            "true servo index",
            "true servo run --fmpy"
        ]
    );
    assert!(command().try_get_matches_from(words("servo sweep --point torque --amplitude 0.2")).is_ok());
    let wrong = command().try_get_matches_from(words("servo sweep --no-such-option 1")).unwrap_err();
    assert_eq!(wrong.kind(), ErrorKind::UnknownArgument);
    let wrong = command().try_get_matches_from(words("servo no-such-command")).unwrap_err();
    assert_eq!(wrong.kind(), ErrorKind::InvalidSubcommand);
    assert_eq!(words("servo x --set 'a b'"), ["servo", "x", "--set", "a b"]);
}
