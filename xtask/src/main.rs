//! `cargo run -p xtask -- bundle`: build the FMU library (`fmu/library/`, profile
//! `fmu-library`) for the host and write the two archives from the project's own model descriptions:
//! - `target/fmu/servo_axis.fmu`: FMI 3.0 Co-Simulation (`binaries/x86_64-linux`),
//! - `target/fmu/servo_axis_fmi2.fmu`: FMI 2.0 Co-Simulation (`binaries/linux64`),
//!
//! each with `documentation/index.html`. One binary exports both APIs.
//!
//! `bundle --all-platforms` packs the three binaries `scripts/platforms` builds (it runs this
//! after them) instead: x86_64 Linux for glibc 2.17, x86_64 Windows and aarch64 Linux (glibc
//! 2.17), as `binaries/x86_64-linux`, `x86_64-windows`, `aarch64-linux` (FMI 3.0) and
//! `linux64`, `win64`, `aarch64-linux` (FMI 2.0: the standard names no aarch64 folder; FMI
//! 2.0.4 suggests the FMI 3.0 tuple, which is what FMI 2.0 importers that support ARM look for).
//! `cargo run -p xtask -- parameter-table` prints the FMU's parameter table (Markdown).
//!
//! `cargo run -p xtask -- references [--check]` writes the book's generated references
//! (`docs/src/reference/`: the FMU's variables, the link protocol, the `servo` CLI) between
//! their markers, or with `--check` says which differ from what the code generates (exit 1);
//! `tests/tests/generated_references.rs` runs the same check in the test command.

mod reference;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use servo_axis::model_description::{self, MODEL_IDENTIFIER};
fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("bundle") if args.len() == 1 => bundle(),
        Some("bundle") if args.len() == 2 && args[1] == "--all-platforms" => bundle_all_platforms(),
        Some("references") if args.len() == 1 => references(false),
        Some("references") if args.len() == 2 && args[1] == "--check" => references(true),
        Some("parameter-table") if args.len() == 1 => {
            print!("{}", model_description::markdown_table());
            Ok(())
        }
        _ => {
            eprintln!(
                "usage: cargo run -p xtask -- bundle | references | parameter-table\n\n  \
                 bundle           build target/fmu/servo_axis.fmu (FMI 3.0) and target/fmu/servo_axis_fmi2.fmu (FMI 2.0)\n                   \
                 (--all-platforms: pack the x86_64 Linux, Windows and aarch64 Linux binaries that\n                   \
                 scripts/platforms builds; run that script, it calls this)\n  \
                 references       write the book's generated references in docs/src/reference/ (the FMU's\n                   \
                 variables, the link protocol, the servo CLI) between their markers\n                   \
                 (--check: exit 1 naming the pages that differ, writing nothing)\n  \
                 parameter-table  print the FMU's parameters and inputs as a Markdown table"
            );
            std::process::exit(2);
        }
    }
}

fn bundle() -> Result<()> {
    let root = workspace_root();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .args(["build", "--profile", LIBRARY_PROFILE, "-q", "-p", LIBRARY_PACKAGE, "--config", LIBRARY_RUSTFLAGS])
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .status()
        .context("running cargo build for the FMU library")?;
    if !status.success() {
        bail!("cargo build -p {LIBRARY_PACKAGE} --profile {LIBRARY_PROFILE} failed");
    }
    if !cfg!(all(target_arch = "x86_64", target_os = "linux")) {
        bail!("the bundle packs the host's library as binaries/x86_64-linux: run it on x86_64 Linux");
    }
    let target_dir = target_dir(&root);
    let library = target_dir.join(format!("{LIBRARY_PROFILE}/lib{LIBRARY_NAME}.so"));
    let binary = std::fs::read(&library).with_context(|| format!("reading {}", library.display()))?;
    write_archives(&target_dir, &[Binary { fmi3: "x86_64-linux", fmi2: "linux64", extension: "so", bytes: binary }])
}

/// The package that builds the FMU's shared library, its Cargo profile and its library name
/// (the archives name the binary after the model identifier instead).
const LIBRARY_PACKAGE: &str = "servo-fmu-library";
const LIBRARY_PROFILE: &str = "fmu-library";
const LIBRARY_NAME: &str = "servo_axis_fmu";
/// The library's code generation (`scripts/platforms` passes the same): LLVM's SLP vectoriser
/// off. It pairs neighbouring fields into 16-byte loads, and where the fields were stored one
/// by one just before (the outputs after a step, the plant's state after a tick) such a load
/// waits for the stores to reach the cache. Without it the FMI boundary costs about 2 % of the
/// bare simulation less (`servo bench fmu`); the results are the same bits.
/// A `RUSTFLAGS` or `CARGO_ENCODED_RUSTFLAGS` in the environment would replace these flags
/// (cargo takes the first source of flags it finds): the build runs without them.
const LIBRARY_RUSTFLAGS: &str = r#"build.rustflags=["-C", "no-vectorize-slp"]"#;

fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from).unwrap_or_else(|| root.join("target"))
}

/// One platform's library and its folder names under `binaries/`.
struct Binary {
    fmi3: &'static str,
    fmi2: &'static str,
    extension: &'static str,
    bytes: Vec<u8>,
}

/// The three platforms' libraries as `scripts/platforms` leaves them: x86_64 Linux from
/// `cargo zigbuild --target x86_64-unknown-linux-gnu.2.17`, Windows and aarch64 Linux from
/// the build-std cross builds in `target/cross/` (the DLL stripped of its symbol table).
fn bundle_all_platforms() -> Result<()> {
    let root = workspace_root();
    let target_dir = target_dir(&root);
    let sources = [
        ("x86_64-linux", "linux64", "so", format!("x86_64-unknown-linux-gnu/{LIBRARY_PROFILE}/lib{LIBRARY_NAME}.so")),
        // Stripped of its symbol table by scripts/platforms.
        ("x86_64-windows", "win64", "dll", format!("cross/{MODEL_IDENTIFIER}.dll")),
        (
            "aarch64-linux",
            "aarch64-linux",
            "so",
            format!("cross/aarch64-unknown-linux-gnu/{LIBRARY_PROFILE}/lib{LIBRARY_NAME}.so"),
        ),
    ];
    let mut binaries = Vec::new();
    for (fmi3, fmi2, extension, relative) in sources {
        let path = target_dir.join(relative);
        let bytes = std::fs::read(&path)
            .with_context(|| format!("reading {} (scripts/platforms builds it, then calls this)", path.display()))?;
        binaries.push(Binary { fmi3, fmi2, extension, bytes });
    }
    write_archives(&target_dir, &binaries)
}

fn write_archives(target_dir: &Path, binaries: &[Binary]) -> Result<()> {
    let out = target_dir.join("fmu");
    std::fs::create_dir_all(&out)?;
    let documentation = model_description::documentation_html();
    let mut fmi3_entries = vec![("modelDescription.xml".to_string(), model_description::fmi3().into_bytes())];
    let mut fmi2_entries = vec![("modelDescription.xml".to_string(), model_description::fmi2().into_bytes())];
    for b in binaries {
        let file = format!("{MODEL_IDENTIFIER}.{}", b.extension);
        fmi3_entries.push((format!("binaries/{}/{file}", b.fmi3), b.bytes.clone()));
        fmi2_entries.push((format!("binaries/{}/{file}", b.fmi2), b.bytes.clone()));
    }
    fmi3_entries.push(("documentation/index.html".to_string(), documentation.clone().into_bytes()));
    fmi2_entries.push(("documentation/index.html".to_string(), documentation.into_bytes()));
    // The licence texts where FMI 3.0 puts them (documentation/licenses/), in both archives.
    let root = workspace_root();
    for licence in ["LICENSE-MIT", "LICENSE-APACHE"] {
        let text = std::fs::read(root.join(licence)).with_context(|| format!("reading {licence}"))?;
        fmi3_entries.push((format!("documentation/licenses/{licence}.txt"), text.clone()));
        fmi2_entries.push((format!("documentation/licenses/{licence}.txt"), text));
    }
    let fmi3 = out.join(format!("{MODEL_IDENTIFIER}.fmu"));
    write_archive(&fmi3, &fmi3_entries)?;
    let fmi2 = out.join(format!("{MODEL_IDENTIFIER}_fmi2.fmu"));
    write_archive(&fmi2, &fmi2_entries)?;
    let platforms: Vec<&str> = binaries.iter().map(|b| b.fmi3).collect();
    println!(
        "FMU ready: {} (FMI 3.0, {} bytes), {} (FMI 2.0, {} bytes); binaries: {}",
        fmi3.display(),
        std::fs::metadata(&fmi3)?.len(),
        fmi2.display(),
        std::fs::metadata(&fmi2)?.len(),
        platforms.join(", ")
    );
    Ok(())
}

/// Write (or with `check`, compare) every generated section of the book's reference pages.
fn references(check: bool) -> Result<()> {
    let root = workspace_root();
    let mut sections = reference::library_sections();
    sections.push(reference::cli_section(reference::cli_markdown(&root).map_err(anyhow::Error::msg)?));
    let mut stale = Vec::new();
    for section in &sections {
        let path = root.join(section.page);
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", section.page))?;
        let new = reference::splice(&text, section).map_err(anyhow::Error::msg)?;
        if new == text {
            println!("{}: {} is current", section.page, section.name);
        } else if check {
            stale.push(section.page);
            println!("{}: {} differs from what the code generates", section.page, section.name);
        } else {
            std::fs::write(&path, new)?;
            println!("{}: {} written", section.page, section.name);
        }
    }
    if !stale.is_empty() {
        bail!("stale: {} (run `{}`)", stale.join(", "), reference::REGENERATE);
    }
    Ok(())
}

fn write_archive(path: &Path, entries: &[(String, Vec<u8>)]) -> Result<()> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (name, data) in entries {
        zip.start_file(name.as_str(), options)?;
        zip.write_all(data)?;
    }
    let bytes = zip.finish()?.into_inner();
    // Write next to the target and rename: an importer never sees half an archive.
    let tmp = path.with_extension("fmu.part");
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}
