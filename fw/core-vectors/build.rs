//! Puts the linker script where the linker finds it and makes the vector file a rebuild input.
fn main() {
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").unwrap());
    std::fs::copy("core-vectors.ld", out.join("core-vectors.ld")).unwrap();
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tcore-vectors.ld");
    println!("cargo:rerun-if-changed=core-vectors.ld");
    println!("cargo:rerun-if-env-changed=CORE_VECTORS_FILE");
    println!("cargo:rerun-if-env-changed=CORE_VECTORS_STREAM");
    if let Ok(f) = std::env::var("CORE_VECTORS_FILE") {
        println!("cargo:rerun-if-changed={f}");
    }
}
