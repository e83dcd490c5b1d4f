//! Case names as they appear in file names.

/// A case name as a file name: letters, digits, `-`, `_`, `.` kept, the rest `_`.
pub fn file_stem(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect()
}
