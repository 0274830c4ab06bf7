//! Random edits of valid inputs for the fuzz tests: most edited inputs get past a reader's first
//! check and reach its deeper ones. Shared with `hexacomp-formats`' CSV fuzz test (included there
//! by path), so both crates mutate their inputs the same way.

use proptest::prelude::*;

/// One edit of a text or byte string: where (as a fraction of its length) and what.
#[derive(Debug, Clone)]
pub enum Edit {
    Delete(f64, usize),
    Insert(f64, Vec<u8>),
    Replace(f64, u8),
    Truncate(f64),
}

/// Fragments that readers find hard: separators, comments, non-numbers, huge and tiny numbers,
/// multi-byte characters, NUL.
const FRAGMENTS: &[&str] = &[
    ",",
    "\n",
    "\r\n",
    "#",
    " ",
    "NaN",
    "inf",
    "-inf",
    "1e999",
    "-0",
    "1e-320",
    "\u{feff}",
    "é",
    "\0",
    "\"",
    "=",
    "[",
    "]",
    "{",
    "id",
    "q1",
    "x",
    "0x10",
    "",
    "9999999999999999999999",
];

pub fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (0.0..1.0f64, 1..8usize).prop_map(|(at, n)| Edit::Delete(at, n)),
        (0.0..1.0f64, prop::sample::select(FRAGMENTS))
            .prop_map(|(at, f)| Edit::Insert(at, f.as_bytes().to_vec())),
        (0.0..1.0f64, any::<u8>()).prop_map(|(at, b)| Edit::Replace(at, b)),
        (0.0..1.0f64).prop_map(Edit::Truncate),
    ]
}

pub fn apply(bytes: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for edit in edits {
        let at = |f: f64, len: usize| ((f * len as f64) as usize).min(len);
        match edit {
            Edit::Delete(f, n) => {
                let start = at(*f, out.len());
                let end = (start + n).min(out.len());
                out.drain(start..end);
            }
            Edit::Insert(f, fragment) => {
                let i = at(*f, out.len());
                out.splice(i..i, fragment.iter().copied());
            }
            Edit::Replace(f, b) => {
                if !out.is_empty() {
                    let i = at(*f, out.len() - 1);
                    out[i] = *b;
                }
            }
            Edit::Truncate(f) => out.truncate(at(*f, out.len())),
        }
    }
    out
}
