//! Measuring aid for tiled inference (`jem::internals::run_tiled`): runs every scene under DIR in tiles and writes
//! `disp0<ALG>.pfm` and `time<ALG>.txt` like `jem batch`, so `jem eval DIR --alg ALG` scores it.
//!
//! ```sh
//! cargo run --release --example tiled -- DIR ALG COARSE_FACTOR CORE_PX [key=value ...]
//! ```
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err("usage: tiled DIR ALG COARSE_FACTOR CORE_PX [key=value ...]".into());
    }
    let (dir, alg) = (PathBuf::from(&args[0]), &args[1]);
    let plan = jem::internals::TilePlan {
        coarse_factor: args[2].parse()?,
        core_px: args[3].parse()?,
        tile_budget_bytes: u64::MAX,
        split_for_work: false,
    };
    let params = jem::Params::load(None, &args[4..])?;
    for scene in jem::dataset::walk::find_scenes(std::slice::from_ref(&dir))? {
        let ndisp = jem::io::calib::read_ndisp(&scene.join("calib.txt"))?;
        let (l, r) = jem::io::read_image_pair(&scene.join("im0.png"), &scene.join("im1.png"))?;
        let pair = jem::internals::StereoPair::new(l, r, ndisp)?;
        let start = std::time::Instant::now();
        let out = jem::internals::run_tiled(&params, &pair, &plan, &jem::internals::RunOptions::quiet())?;
        let secs = start.elapsed().as_secs_f64();
        jem::io::write_disparity(&scene.join(format!("disp0{alg}.pfm")), &out.disparity)?;
        jem::io::write_atomic(&scene.join(format!("time{alg}.txt")), format!("{secs:.6}\n").as_bytes())?;
        eprintln!("{}: {secs:.3} s", scene.display());
    }
    Ok(())
}
