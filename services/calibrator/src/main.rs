//! The live calibrator process: placeholder until its issue; the engine is the library.
fn main() {}
