//! `include/hexacomp.h` is what cbindgen generates from `src/lib.rs` today. After changing the
//! C API: `HEXACOMP_BLESS=1 cargo test -p hexacomp-client-c --test c_header` rewrites it (and fails,
//! so that the next run, without it, checks the result); where `CI` is set it is refused.

use std::path::Path;

#[test]
fn the_committed_c_header_is_the_generated_one() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen parses src/lib.rs")
        .write(&mut generated);
    let generated = String::from_utf8(generated).unwrap();
    let path = crate_dir.join("include/hexacomp.h");
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    if committed == generated {
        return;
    }
    // Blessing rewrites the header and still fails, so that a run with HEXACOMP_BLESS set can
    // never pass over an out-of-date header; under CI it is refused outright.
    let bless = std::env::var_os("HEXACOMP_BLESS").is_some();
    if bless && std::env::var_os("CI").is_none() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &generated).unwrap();
        panic!(
            "{} rewritten: review the change and run the test again without HEXACOMP_BLESS",
            path.display()
        );
    }
    panic!(
        "{} is out of date{}: run HEXACOMP_BLESS=1 cargo test -p hexacomp-client-c --test c_header \
         outside CI",
        path.display(),
        if bless {
            " (HEXACOMP_BLESS is refused where CI is set)"
        } else {
            ""
        }
    );
}
