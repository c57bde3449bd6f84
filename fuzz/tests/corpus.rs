//! Every committed corpus and crash input, replayed through its target: the seeds still read,
//! and no input the coverage-guided campaign kept or once failed on panics again.

use std::panic::{AssertUnwindSafe, catch_unwind};

use kodama_fuzz::{TARGETS, corpus_dir, crashes_dir, files_in};

/// The address space AFL++ gave each input (`-m 4096`): an input that makes a reader ask for more
/// (a size claimed by a header and allocated as stated) aborts the process, as it did the
/// fuzzer's, instead of passing on a machine with memory to spare.
fn limit_memory_as_the_fuzzer_did() {
    let limit = libc::rlimit {
        rlim_cur: 4 << 30,
        rlim_max: libc::RLIM_INFINITY,
    };
    // SAFETY: setrlimit reads the struct it is given and changes only this process's limit.
    let r = unsafe { libc::setrlimit(libc::RLIMIT_AS, &limit) };
    assert_eq!(r, 0, "setrlimit: {}", std::io::Error::last_os_error());
}

#[test]
fn every_corpus_and_crash_input_reads_without_panicking() {
    limit_memory_as_the_fuzzer_did();
    let mut failed = Vec::new();
    let mut count = 0;
    for t in TARGETS {
        let corpus = files_in(&corpus_dir(t.name));
        assert!(
            !corpus.is_empty(),
            "{}: no corpus (at least its seed)",
            corpus_dir(t.name).display()
        );
        for path in corpus.iter().chain(&files_in(&crashes_dir(t.name))) {
            let bytes = std::fs::read(path).unwrap();
            let dir = tempfile::tempdir().unwrap();
            count += 1;
            if catch_unwind(AssertUnwindSafe(|| (t.read)(dir.path(), &bytes))).is_err() {
                failed.push(path.display().to_string());
            }
        }
    }
    println!("{count} inputs replayed");
    assert!(failed.is_empty(), "these inputs panicked: {failed:#?}");
}

/// Each seed is a file its reader accepts, so the fuzzing starts from the format's inside.
#[test]
fn every_seed_is_read() {
    for t in TARGETS {
        let seed = kodama_fuzz::seed(t.name).unwrap();
        let dir = tempfile::tempdir().unwrap();
        if let Err(e) = (t.read)(dir.path(), &seed) {
            panic!("{}: its seed is refused: {e}", t.name);
        }
    }
}
