//! What every command takes (`--fmu`, `--out`, `--json`) and its progress bar.

use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args, Clone)]
pub struct Common {
    /// FMU to run (default: the one the project builds)
    #[arg(long, global = true)]
    pub fmu: Option<PathBuf>,
    /// Output folder (default: out/<command>/)
    #[arg(long, global = true)]
    pub out: Option<PathBuf>,
    /// Print machine-readable figures (JSON) on stdout instead of tables
    #[arg(long, global = true)]
    pub json: bool,
}

pub fn progress_bar(label: &str, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(1000);
    pb.set_style(
        ProgressStyle::with_template("{prefix:>22} [{bar:40}] {percent:>3}% {elapsed_precise}")
            .unwrap()
            .progress_chars("=> "),
    );
    pb.set_prefix(label.to_string());
    pb
}

/// The command-line reference as Markdown (the book's `reference/cli.md`, written by `cargo
/// run -p xtask -- references` from `servo cli-reference`): every command, visible or not in
/// `--help`'s summary, with its description and every option, its value, default and help.
pub fn markdown_reference(command: &clap::Command) -> String {
    let mut out = String::new();
    reference_section(&mut out, command, &[]);
    out
}

fn reference_section(out: &mut String, command: &clap::Command, parents: &[&str]) {
    use std::fmt::Write;
    let mut path: Vec<&str> = parents.to_vec();
    path.push(command.get_name());
    let full = path.join(" ");
    let _ = writeln!(out, "## `{full}`\n");
    if let Some(about) = command.get_long_about().or(command.get_about()) {
        let _ = writeln!(out, "{}\n", markdown_text(&about.to_string(), ""));
    }
    let positionals: Vec<&clap::Arg> = command.get_positionals().filter(|a| !a.is_hide_set()).collect();
    let mut synopsis = full.clone();
    if command.get_arguments().any(|a| !a.is_positional() && !a.is_hide_set()) {
        synopsis.push_str(" [OPTIONS]");
    }
    for a in &positionals {
        let name = value_name(a);
        let many = a.get_num_args().is_some_and(|n| n.max_values() > 1);
        let dots = if many { "..." } else { "" };
        synopsis.push_str(&if a.is_required_set() { format!(" <{name}>{dots}") } else { format!(" [{name}]{dots}") });
    }
    let visible: Vec<&clap::Command> = command.get_subcommands().filter(|c| !c.is_hide_set()).collect();
    if !visible.is_empty() {
        synopsis.push_str(" <COMMAND>");
    }
    let _ = writeln!(out, "```text\n{synopsis}\n```\n");
    if !visible.is_empty() {
        let _ = writeln!(out, "| command | what it does |\n| --- | --- |");
        for c in &visible {
            let about = c.get_about().map(|a| a.to_string()).unwrap_or_default();
            let first = about.lines().next().unwrap_or("").replace('|', "\\|");
            let _ = writeln!(
                out,
                "| [`{full} {}`](#{}) | {} |",
                c.get_name(),
                anchor(&format!("{full} {}", c.get_name())),
                markdown_text(&first, "")
            );
        }
        out.push('\n');
    }
    let args: Vec<&clap::Arg> = command.get_arguments().filter(|a| !a.is_hide_set()).collect();
    if !args.is_empty() {
        let _ = writeln!(out, "Arguments and options:\n");
        for a in args {
            let mut head = if a.is_positional() {
                format!("`<{}>`", value_name(a))
            } else {
                let mut names = Vec::new();
                if let Some(s) = a.get_short() {
                    names.push(format!("-{s}"));
                }
                if let Some(l) = a.get_long() {
                    names.push(format!("--{l}"));
                }
                let mut flag = names.join(", ");
                if a.get_action().takes_values() {
                    flag.push_str(&format!(" <{}>", value_name(a)));
                }
                format!("`{flag}`")
            };
            let defaults: Vec<String> =
                a.get_default_values().iter().map(|v| v.to_string_lossy().into_owned()).collect();
            if !defaults.is_empty() && a.get_action().takes_values() {
                head.push_str(&format!(" (default `{}`)", defaults.join(",")));
            }
            let possible: Vec<String> = a
                .get_possible_values()
                .iter()
                .filter(|p| !p.is_hide_set())
                .map(|p| format!("`{}`", p.get_name()))
                .collect();
            if !possible.is_empty() && !matches!(a.get_action(), clap::ArgAction::SetTrue | clap::ArgAction::SetFalse) {
                head.push_str(&format!(" (one of {})", possible.join(", ")));
            }
            if a.get_action().takes_values() && a.get_num_args().is_some_and(|n| n.max_values() > 1)
                || matches!(a.get_action(), clap::ArgAction::Append)
            {
                head.push_str(" (repeatable)");
            }
            let help = a.get_long_help().or(a.get_help()).map(|h| h.to_string()).unwrap_or_default();
            if help.is_empty() {
                let _ = writeln!(out, "- {head}");
            } else {
                let _ = writeln!(out, "- {head}: {}", markdown_text(&help, "  "));
            }
        }
        out.push('\n');
    }
    for c in command.get_subcommands().filter(|c| !c.is_hide_set()) {
        reference_section(out, c, &path);
    }
}

fn value_name(a: &clap::Arg) -> String {
    match a.get_value_names() {
        Some(names) if !names.is_empty() => names.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(" "),
        _ => a.get_id().as_str().to_uppercase(),
    }
}

/// The heading's anchor as mdBook and GitHub make it: lower case, spaces as `-`, other
/// punctuation dropped.
fn anchor(heading: &str) -> String {
    heading
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            '-' | '_' => Some(c),
            c if c.is_alphanumeric() => Some(c.to_ascii_lowercase()),
            _ => None,
        })
        .collect()
}

/// Help text as Markdown: `<`, `>` and `*` escaped outside code spans (an `<axis>` would read
/// as an HTML tag),
/// lines after the first indented by `indent` (a list item's continuation).
fn markdown_text(text: &str, indent: &str) -> String {
    let mut escaped = String::with_capacity(text.len());
    let mut in_code = false;
    for c in text.trim().chars() {
        match c {
            '`' => {
                in_code = !in_code;
                escaped.push(c);
            }
            '<' if !in_code => escaped.push_str("&lt;"),
            '>' if !in_code => escaped.push_str("&gt;"),
            '*' if !in_code => escaped.push_str("\\*"),
            _ => escaped.push(c),
        }
    }
    let mut lines = escaped.lines();
    let mut out = lines.next().unwrap_or("").trim_end().to_string();
    for line in lines {
        out.push('\n');
        if !line.trim().is_empty() {
            out.push_str(indent);
            out.push_str(line.trim_end());
        }
    }
    out
}
