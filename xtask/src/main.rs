//! `cargo run -p xtask -- bundle`: build the FMU with cargo-fmi, then add what rust-fmi's
//! derive cannot express (units, min and max) to its modelDescription.xml.

mod variable_units;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask lives in the workspace").to_path_buf()
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("bundle") => bundle(),
        _ => {
            eprintln!("usage: cargo run -p xtask -- bundle\n\n  bundle   build target/fmu/servo_axis.fmu (release) with units, min and max");
            std::process::exit(2);
        }
    }
}

fn bundle() -> Result<()> {
    let root = workspace_root();
    std::env::set_current_dir(&root)?;
    cargo_fmi::entrypoint_from(["cargo-fmi", "bundle", "-p", "servo-fmu", "--release"])
        .context("cargo-fmi bundle failed")?;
    let fmu = root.join("target/fmu/servo_axis.fmu");
    complete_model_description(&fmu)?;
    println!("FMU ready: {}", fmu.display());
    Ok(())
}

/// Rewrite the archive with an amended modelDescription.xml, every other entry unchanged.
fn complete_model_description(fmu: &Path) -> Result<()> {
    let bytes = std::fs::read(fmu).with_context(|| format!("reading {}", fmu.display()))?;
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes))?;
    let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i)?;
        let name = entry.name().to_string();
        if entry.is_dir() {
            out.add_directory(name, options)?;
            continue;
        }
        let mut data = Vec::new();
        entry.read_to_end(&mut data)?;
        if name == "modelDescription.xml" {
            let xml = String::from_utf8(data).context("modelDescription.xml is not UTF-8")?;
            data = variable_units::annotate(&xml)?.into_bytes();
        }
        out.start_file(name, options)?;
        out.write_all(&data)?;
    }
    let data = out.finish()?.into_inner();
    if data.is_empty() {
        bail!("empty archive");
    }
    std::fs::write(fmu, data)?;
    Ok(())
}
