//! The library's example (docs/library.md): match one rectified pair with the built-in defaults and one setting
//! changed in code, and write its disparity map. No file of jem's checkout is needed.
//!
//! ```sh
//! cargo run --release --example library -- examples/synth/im0.png examples/synth/im1.png disp.pfm
//! ```
use jem::{Matcher, NdispSource, Params};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [left, right, output] = &args[..] else {
        return Err("usage: library LEFT RIGHT OUTPUT.pfm".into());
    };
    // The built-in defaults, with `key=value` overrides as `jem --set` takes them (or a shipped config by name,
    // `Params::preset("fast")`, or `Params::from_toml_str`).
    let params = Params::load(None, &["meanfield.iterations=2".into()])?;
    let mut matcher = Matcher::new(params)?.with_ndisp(NdispSource::Given(64)).with_max_memory(4 << 30);
    let (left, right) = jem::io::read_image_pair(left.as_ref(), right.as_ref())?;
    let out = matcher.match_pair(&left, &right)?; // borrows the views; out.plan says how it ran
    jem::io::write_disparity(output.as_ref(), &out.disparity)?;
    Ok(())
}
