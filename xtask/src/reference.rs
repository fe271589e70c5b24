//! The book's generated references: the parts of `docs/src/reference/*.md` that are written
//! from the code, each between two markers, so that the prose around them stays hand-written.
//!
//! - `fmu-variables.md`: every parameter, input and output of the FMU, from the one
//!   declaration in `fmu/src/variables/table.rs` (`servo_axis::model_description`);
//! - `link-protocol.md`: the link's constants, messages and example frames, from
//!   `control_core::protocol` (the constants and frames by calling it, the messages from its
//!   source's declarations and doc comments);
//! - `cli.md`: every `servo` command and option, from clap (`servo cli-reference`).
//!
//! `cargo run -p xtask -- references` writes them; `tests/tests/generated_references.rs`
//! includes this file and fails when a page differs from what the code generates. This file
//! needs only `std`, `servo_axis` and `control_core`, which both crates depend on.

use std::fmt::Write;
use std::path::Path;

/// The command that writes every generated section.
pub const REGENERATE: &str = "cargo run -p xtask -- references";

/// One generated section: the page (relative to the workspace root), its name in the
/// markers, and its content.
pub struct Section {
    pub page: &'static str,
    pub name: &'static str,
    pub content: String,
}

pub fn begin_marker(name: &str) -> String {
    format!("<!-- generated: {name}; `{REGENERATE}` writes it, do not edit by hand -->")
}

pub fn end_marker(name: &str) -> String {
    format!("<!-- end of generated: {name} -->")
}

/// The text between a section's markers in `page_text` (None: markers missing).
pub fn current<'a>(page_text: &'a str, name: &str) -> Option<&'a str> {
    let begin = begin_marker(name);
    let a = page_text.find(&begin)? + begin.len();
    let b = a + page_text[a..].find(&end_marker(name))?;
    Some(&page_text[a..b])
}

/// How a section sits between its markers: one blank line on each side.
pub fn framed(content: &str) -> String {
    format!("\n\n{}\n", content.trim_end())
}

/// `page_text` with the section's content put between its markers.
pub fn splice(page_text: &str, section: &Section) -> Result<String, String> {
    let begin = begin_marker(section.name);
    let (Some(a), Some(_)) = (page_text.find(&begin), current(page_text, section.name)) else {
        return Err(format!("{} has no markers for the generated section \"{}\"", section.page, section.name));
    };
    let a = a + begin.len();
    let b = a + page_text[a..].find(&end_marker(section.name)).unwrap();
    Ok(format!("{}{}{}", &page_text[..a], framed(&section.content), &page_text[b..]))
}

/// The sections that need no build beyond this crate's dependencies (the FMU's variables and
/// the link protocol).
pub fn library_sections() -> Vec<Section> {
    vec![
        Section { page: "docs/src/reference/fmu-variables.md", name: "FMU variables", content: fmu_variables() },
        Section { page: "docs/src/reference/link-protocol.md", name: "link protocol", content: link_protocol() },
    ]
}

/// The CLI section, from `markdown` (what `servo cli-reference` prints).
pub fn cli_section(markdown: String) -> Section {
    Section { page: "docs/src/reference/cli.md", name: "servo CLI", content: markdown }
}

/// `servo cli-reference`'s output, built and run through cargo from the workspace at `root`
/// (the xtask's way; the test takes the same text from `host_tools::command_line` directly).
pub fn cli_markdown(root: &Path) -> Result<String, String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = std::process::Command::new(cargo)
        .current_dir(root)
        .args(["run", "--release", "-q", "-p", "host-tools", "--bin", "servo", "--", "cli-reference"])
        .output()
        .map_err(|e| format!("running cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!("servo cli-reference failed: {}", String::from_utf8_lossy(&out.stderr)));
    }
    String::from_utf8(out.stdout).map_err(|e| format!("servo cli-reference: {e}"))
}

fn fmu_variables() -> String {
    use servo_axis::model_description as md;
    let (parameters, inputs, outputs) = md::variable_counts();
    let mut s = String::new();
    let _ = writeln!(s, "{parameters} parameters, {inputs} inputs and {outputs} outputs.\n");
    let _ = writeln!(s, "### Parameters and inputs\n");
    s.push_str(&md::markdown_table());
    let _ = writeln!(s, "\n### Outputs\n");
    s.push_str(&md::markdown_outputs_table());
    s
}

/// The protocol's source: its declarations and doc comments are the reference's text.
const PROTOCOL_SOURCE: &str = include_str!("../../control-core/src/protocol.rs");

fn link_protocol() -> String {
    use control_core::protocol::{self, Request, Response};
    let mut s = String::new();
    let _ = writeln!(s, "| constant | value |\n| --- | --- |");
    let _ = writeln!(s, "| protocol version (`protocol::VERSION`) | {} |", protocol::VERSION);
    let _ = writeln!(s, "| largest COBS body, terminator excluded (`MAX_FRAME`) | {} bytes |", protocol::MAX_FRAME);
    let _ =
        writeln!(s, "| check value (`CRC_BYTES`, little-endian, after the message) | {} bytes |", protocol::CRC_BYTES);
    let _ = writeln!(
        s,
        "| check algorithm | CRC-32C (`crc::CRC_32_ISCSI`); check value of `\"123456789\"`: `0x{:08X}` |",
        protocol::crc32(b"123456789")
    );
    let _ = writeln!(
        s,
        "| samples per `Samples` batch (`acquisition_stream::BATCH`) | {} |",
        control_core::acquisition_stream::BATCH
    );
    for (name, title) in [
        ("Request", "Requests (host → drive)"),
        ("Response", "Responses (drive → host)"),
        ("RefusalReason", "`Refused` reasons"),
        ("FrameError", "`FrameError` kinds"),
        ("DefaultsReason", "Why a drive booted with its defaults (`Hello`'s `boot_params`)"),
        ("StorageError", "`Storage` refusals"),
    ] {
        let _ = writeln!(s, "\n### {title}\n");
        let _ = writeln!(s, "| index | `{name}` | payload | meaning |\n| --- | --- | --- | --- |");
        for (i, v) in enum_variants(name).iter().enumerate() {
            let doc = if v.doc.is_empty() { undocumented(name, &v.name).to_string() } else { v.doc.clone() };
            let _ = writeln!(s, "| {i} | `{}` | {} | {doc} |", v.name, v.payload);
        }
    }
    let _ = writeln!(s, "\n### Example frames\n");
    let _ = writeln!(s, "Encoded by `protocol::encode` (postcard, CRC-32C, COBS, zero terminator), in hex:\n");
    let _ = writeln!(s, "| message | frame |\n| --- | --- |");
    let requests: [(&str, Request); 5] = [
        ("`Request::Hello { version }`", Request::Hello { version: protocol::VERSION }),
        ("`Request::GetTelemetry`", Request::GetTelemetry),
        ("`Request::StartSweep`", Request::StartSweep),
        ("`Request::Stream { enabled: true }`", Request::Stream { enabled: true }),
        ("`Request::SaveParams`", Request::SaveParams),
    ];
    for (label, r) in requests {
        let _ = writeln!(s, "| {label} | `{}` |", frame_hex(Some(&r), None));
    }
    for (label, r) in
        [("`Response::Done`", Response::Done), ("`Response::Saved { sequence: 1 }`", Response::Saved { sequence: 1 })]
    {
        let _ = writeln!(s, "| {label} | `{}` |", frame_hex(None, Some(&r)));
    }
    s
}

fn frame_hex(
    request: Option<&control_core::protocol::Request>,
    response: Option<&control_core::protocol::Response>,
) -> String {
    let mut buf = [0u8; control_core::protocol::MAX_FRAME + 1];
    let n = match (request, response) {
        (Some(r), _) => control_core::protocol::encode(r, &mut buf),
        (_, Some(r)) => control_core::protocol::encode(r, &mut buf),
        _ => unreachable!("a request or a response"),
    }
    .expect("a small message fits a frame");
    buf[..n].iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" ")
}

/// What a variant means where its declaration has no doc comment (a doc comment added in the
/// source takes its place).
fn undocumented(enumeration: &str, variant: &str) -> &'static str {
    match (enumeration, variant) {
        ("Request", "Sequence") => {
            "A stop-sequence event (seed 004): answered `Done`, or `Refused` with the sequence's reason."
        }
        ("Request", "StartSweep") => {
            "Start the sweep of the parameters in force (`sweep.*`): answered `Done`, or `Refused(Sweep)`."
        }
        ("Request", "ClearFaults") => "Clear the latched faults.",
        ("Request", "GetTelemetry") => "Answered with `Telemetry`.",
        ("Response", "Hello") => {
            "The answer to `Hello`: the drive's protocol version, and where its parameters came from at boot."
        }
        ("Response", "Done") => "The request was carried out.",
        ("Response", "Refused") => "The request was refused and changed nothing: why.",
        ("Response", "Telemetry") => "The answer to `GetTelemetry`.",
        ("Response", "FrameError") => "The frame did not decode and was not acted upon: why.",
        _ => "",
    }
}

struct Variant {
    name: String,
    payload: String,
    doc: String,
}

/// The variants of `pub enum <name>` in the protocol's source, in declaration order (postcard
/// encodes a variant as its index), with their payloads and doc comments.
fn enum_variants(name: &str) -> Vec<Variant> {
    let head = format!("pub enum {name} {{");
    let start =
        PROTOCOL_SOURCE.find(&head).unwrap_or_else(|| panic!("control-core/src/protocol.rs declares no {head}"));
    let body = &PROTOCOL_SOURCE[start + head.len()..];
    let body = &body[..body.find("\n}").expect("the enum ends")];
    let mut variants = Vec::new();
    let mut doc = Vec::new();
    let mut fields: Option<(String, Vec<String>, Vec<String>)> = None;
    for line in body.lines() {
        let indent = line.len() - line.trim_start().len();
        let t = line.trim();
        if let Some((vname, vdoc, list)) = fields.as_mut() {
            if indent == 4 && t.starts_with('}') {
                variants.push(Variant {
                    name: vname.clone(),
                    payload: format!("`{{ {} }}`", list.join(", ")),
                    doc: vdoc.join(" "),
                });
                fields = None;
            } else if !t.starts_with("//") && !t.is_empty() {
                list.push(t.trim_end_matches(',').to_string());
            }
            continue;
        }
        if indent != 4 || t.is_empty() {
            continue;
        }
        if let Some(d) = t.strip_prefix("///") {
            doc.push(doc_text(d.trim()));
        } else if t.starts_with("#[") || t.starts_with("//") {
        } else if let Some(vname) = t.strip_suffix(" {") {
            fields = Some((vname.to_string(), std::mem::take(&mut doc), Vec::new()));
        } else if let Some((vname, rest)) = t.split_once('(') {
            let ty = rest.trim_end_matches(',').trim_end_matches(')');
            variants.push(Variant {
                name: vname.to_string(),
                payload: format!("`{ty}`"),
                doc: std::mem::take(&mut doc).join(" "),
            });
        } else if let Some((vname, rest)) = t.split_once(" { ") {
            let list = rest.trim_end_matches(',').trim_end_matches('}').trim().trim_end_matches(',');
            variants.push(Variant {
                name: vname.to_string(),
                payload: format!("`{{ {list} }}`"),
                doc: std::mem::take(&mut doc).join(" "),
            });
        } else {
            variants.push(Variant {
                name: t.trim_end_matches(',').to_string(),
                payload: "—".into(),
                doc: std::mem::take(&mut doc).join(" "),
            });
        }
    }
    variants
}

/// A doc comment's line as table text: intra-doc links as plain code, no `|`.
fn doc_text(d: &str) -> String {
    d.replace("[`", "`").replace("`]", "`").replace('|', "\\|")
}
