//! `cargo xtask <task>`: project tasks written as plain Rust (the cargo-xtask pattern).
fn main() {}
