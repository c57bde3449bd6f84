//! The coverage-guided driver: `kodama-fuzz-afl TARGET`, run by AFL++ (`scripts/fuzz_afl.sh`)
//! in persistent mode, each input handed to the target's reader in one scratch folder.

fn main() {
    let name = std::env::args().nth(1).unwrap_or_default();
    let Some(target) = kodama_fuzz::target(&name) else {
        let names: Vec<&str> = kodama_fuzz::TARGETS.iter().map(|t| t.name).collect();
        eprintln!(
            "usage: kodama-fuzz-afl TARGET, one of: {}",
            names.join(", ")
        );
        std::process::exit(2);
    };
    let scratch = tempfile::tempdir().expect("a scratch folder");
    // No abort-on-panic hook: a reader that catches a third-party decoder's panic and reports it
    // as the file's error (gltf-json indexes unchecked, StageError::catch_decoder_panic) handles
    // that input; only a panic that escapes the target is a finding, and afl aborts on those.
    afl::fuzz_nohook!(|data: &[u8]| {
        let _ = (target.read)(scratch.path(), data);
    });
}
