//! Tuning aid for slanted-plane smoothing: applies only the `[post.sps]` stage to cached left-right-checked maps.
//!
//! With `post.fill = false` and `post.wmedian.enabled = false` (configs/jem-sps.toml) the planes' input is exactly
//! the LRC output (`inf` = inconsistent) and the trusted mask is its finite pixels, so running
//! `jem batch --alg IN -c configs/jem-sps.toml --set post.sps.enabled=false DIR` once and then this tool gives the
//! same `disp0OUT.pfm` as a full `jem batch` with the SPS stage on, without redoing the inference.
//!
//! ```sh
//! cargo run --release --example sps_sweep -- DIR IN OUT CONFIG [key=value ...]
//! ```
use std::path::{Path, PathBuf};

use jem::Plane;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err("usage: sps_sweep DIR IN OUT CONFIG [key=value ...]".into());
    }
    let (dir, input, output, config) = (PathBuf::from(&args[0]), &args[1], &args[2], Path::new(&args[3]));
    let params = jem::Params::load(Some(config), &args[4..])?;
    assert!(!params.post.fill && !params.post.wmedian.enabled, "the cached maps are only valid without fill/WMF");
    let scenes = jem::dataset::walk::find_scenes(std::slice::from_ref(&dir))?;
    for scene in scenes {
        let disp = jem::io::read_disparity(&scene.join(format!("disp0{input}.pfm")))?;
        let image = jem::io::read_image(&scene.join("im0.png"))?;
        let trusted =
            Plane::from_vec(disp.width(), disp.height(), disp.data().iter().map(|d| d.is_finite()).collect()).unwrap();
        let start = std::time::Instant::now();
        let out = jem::internals::post::planes::fit_slanted_planes(&image, &disp, &trusted, &params.post.sps);
        let secs = start.elapsed().as_secs_f64();
        jem::io::write_disparity(&scene.join(format!("disp0{output}.pfm")), &out)?;
        std::fs::write(scene.join(format!("time{output}.txt")), format!("{secs:.4}\n"))?;
    }
    Ok(())
}
