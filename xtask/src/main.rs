//! `cargo run -p xtask -- bundle`: build the FMU library (release) and write the two
//! archives from the project's own model descriptions:
//! - `target/fmu/servo_axis.fmu`: FMI 3.0 Co-Simulation (`binaries/x86_64-linux`),
//! - `target/fmu/servo_axis_fmi2.fmu`: FMI 2.0 Co-Simulation (`binaries/linux64`),
//!
//! each with `documentation/index.html`. One binary exports both APIs.
//! `cargo run -p xtask -- parameter-table` prints the README's parameter table.

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
        Some("bundle") => bundle(),
        Some("parameter-table") => {
            print!("{}", model_description::markdown_table());
            Ok(())
        }
        _ => {
            eprintln!(
                "usage: cargo run -p xtask -- bundle | parameter-table\n\n  \
                 bundle           build target/fmu/servo_axis.fmu (FMI 3.0) and target/fmu/servo_axis_fmi2.fmu (FMI 2.0)\n  \
                 parameter-table  print the parameters and inputs as the README's Markdown table"
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
        .args(["build", "--release", "-q", "-p", "servo-fmu", "--lib"])
        .status()
        .context("running cargo build for the FMU library")?;
    if !status.success() {
        bail!("cargo build -p servo-fmu failed");
    }
    let library = root.join(format!("target/release/lib{MODEL_IDENTIFIER}.so"));
    let binary = std::fs::read(&library).with_context(|| format!("reading {}", library.display()))?;
    let out = root.join("target/fmu");
    std::fs::create_dir_all(&out)?;
    let documentation = model_description::documentation_html();
    let so = format!("{MODEL_IDENTIFIER}.so");
    let fmi3 = out.join(format!("{MODEL_IDENTIFIER}.fmu"));
    write_archive(
        &fmi3,
        &[
            ("modelDescription.xml", model_description::fmi3().into_bytes()),
            (&format!("binaries/x86_64-linux/{so}"), binary.clone()),
            ("documentation/index.html", documentation.clone().into_bytes()),
        ],
    )?;
    let fmi2 = out.join(format!("{MODEL_IDENTIFIER}_fmi2.fmu"));
    write_archive(
        &fmi2,
        &[
            ("modelDescription.xml", model_description::fmi2().into_bytes()),
            (&format!("binaries/linux64/{so}"), binary),
            ("documentation/index.html", documentation.into_bytes()),
        ],
    )?;
    println!("FMU ready: {} (FMI 3.0), {} (FMI 2.0)", fmi3.display(), fmi2.display());
    Ok(())
}

fn write_archive(path: &Path, entries: &[(&str, Vec<u8>)]) -> Result<()> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (name, data) in entries {
        zip.start_file(*name, options)?;
        zip.write_all(data)?;
    }
    let bytes = zip.finish()?.into_inner();
    // Write next to the target and rename: an importer never sees half an archive.
    let tmp = path.with_extension("fmu.part");
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}
