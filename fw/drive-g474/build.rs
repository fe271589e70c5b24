//! Linker scripts: cortex-m-rt's `link.x` (with embassy-stm32's `memory.x`) and defmt's.
fn main() {
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
