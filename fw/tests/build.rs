//! Linker scripts of the test binaries: cortex-m-rt's `link.x` (embassy-stm32's `memory.x`)
//! and defmt's.
fn main() {
    println!("cargo:rustc-link-arg-tests=--nmagic");
    println!("cargo:rustc-link-arg-tests=-Tlink.x");
    println!("cargo:rustc-link-arg-tests=-Tdefmt.x");
}
