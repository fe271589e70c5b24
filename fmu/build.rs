//! The sources', compiler's, target's and flags' hash, part of the fingerprint a serialized FMU state must carry (a state is
//! a byte image of the model: only the build that wrote it can read it back).

use std::path::Path;

fn hash_dir(dir: &Path, h: &mut u64) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).into_iter().flatten().flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            hash_dir(&p, h);
        } else if let Ok(bytes) = std::fs::read(&p) {
            // FNV-1a over the path's file name and the contents.
            for b in p.file_name().unwrap_or_default().as_encoded_bytes().iter().chain(bytes.iter()) {
                *h ^= *b as u64;
                *h = h.wrapping_mul(0x100_0000_01b3);
            }
        }
    }
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for dir in [root.join("src"), root.join("../control-core/src")] {
        println!("cargo:rerun-if-changed={}", dir.display());
        hash_dir(&dir, &mut h);
    }
    // The layout of the state also depends on the compiler, the target and the flags.
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let version = std::process::Command::new(rustc).arg("-vV").output().map(|o| o.stdout).unwrap_or_default();
    let mut extra = version;
    for var in ["TARGET", "PROFILE", "OPT_LEVEL", "CARGO_ENCODED_RUSTFLAGS"] {
        println!("cargo:rerun-if-env-changed={var}");
        extra.extend(std::env::var(var).unwrap_or_default().bytes());
        extra.push(0);
    }
    for b in extra {
        h ^= b as u64;
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    println!("cargo:rustc-env=SERVO_FMU_SOURCE_HASH={h:016x}");
}
