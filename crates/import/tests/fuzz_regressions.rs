//! Inputs the fuzzers (fuzz/) found crashing a reader, kept as they were found: each must now
//! load or give one line of error naming the file, never a panic. `data/fuzz/<target>/`.

mod common;

use std::path::Path;

#[test]
fn every_input_the_fuzzers_found_loads_or_is_one_line_of_error() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut seen = 0;
    let (mut ok, mut errors) = (0, 0);
    for target in std::fs::read_dir(&root).unwrap() {
        for f in std::fs::read_dir(target.unwrap().path()).unwrap() {
            let path = f.unwrap().path();
            seen += 1;
            match common::collect(&path) {
                Ok(_) => ok += 1,
                Err(e) => {
                    let msg = e.to_string();
                    assert_eq!(msg.lines().count(), 1, "{}: {msg}", path.display());
                    assert!(msg.contains(&*path.to_string_lossy()), "the error does not name the file: {msg}");
                    errors += 1;
                }
            }
        }
    }
    assert!(seen >= 58, "only {seen} inputs");
    eprintln!("{seen} inputs: {ok} load, {errors} are errors");
}
