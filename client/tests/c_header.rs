//! `include/hexacomp.h` is what cbindgen generates from `src/c_api.rs` today. After changing the
//! C API: `HEXACOMP_BLESS=1 cargo test -p hexacomp-client --test c_header` rewrites it.

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
        .expect("cbindgen parses src/c_api.rs")
        .write(&mut generated);
    let generated = String::from_utf8(generated).unwrap();
    let path = crate_dir.join("include/hexacomp.h");
    if std::env::var_os("HEXACOMP_BLESS").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} is out of date: run HEXACOMP_BLESS=1 cargo test -p hexacomp-client --test c_header",
        path.display()
    );
}
