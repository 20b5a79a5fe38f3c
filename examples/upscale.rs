//! Makes "full-size" test scenes (enlargements without new detail) from quarter-size ones: every MiddEval3 scene
//! under SRC is written to OUT/<scene> enlarged K times — images bicubic (Catmull-Rom), ground truth and mask by pixel
//! replication with the disparities × K, and calib.txt's `ndisp`, `width`, `height`, `doffs`, `vmin`, `vmax` × K
//! (cam0/cam1 focal lengths and principal points too). OUT must not exist.
//!
//! ```sh
//! cargo run --release --example upscale -- ../shared/middlebury/MiddEval3/trainingQ /tmp/x4/trainingF 4 Adirondack Vintage
//! ```
use std::path::{Path, PathBuf};

use image::imageops::FilterType;

fn scale_calib(text: &str, k: f64) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let Some((key, value)) = line.split_once('=') else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let scaled = match key.trim() {
            "ndisp" | "width" | "height" => {
                let v: f64 = value.trim().parse().unwrap_or(0.0);
                format!("{}", (v * k).round() as i64)
            }
            "doffs" | "vmin" | "vmax" => {
                let v: f64 = value.trim().parse().unwrap_or(0.0);
                format!("{}", v * k)
            }
            "cam0" | "cam1" => {
                // [f 0 cx; 0 f cy; 0 0 1]: everything but the last row scales.
                let nums: Vec<f64> = value
                    .trim()
                    .trim_matches(['[', ']'])
                    .split([' ', ';'])
                    .filter(|s| !s.is_empty())
                    .filter_map(|s| s.parse().ok())
                    .collect();
                if nums.len() == 9 {
                    let s: Vec<String> =
                        nums.iter().enumerate().map(|(i, v)| format!("{}", if i < 6 { v * k } else { *v })).collect();
                    format!("[{} {} {}; {} {} {}; {} {} {}]", s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8])
                } else {
                    value.to_string()
                }
            }
            _ => value.to_string(),
        };
        out.push_str(&format!("{key}={scaled}\n"));
    }
    out
}

fn upscale_scene(src: &Path, dst: &Path, k: u32) -> Result<(), Box<dyn std::error::Error>> {
    std::fs::create_dir_all(dst)?;
    for name in ["im0.png", "im1.png"] {
        let img = image::open(src.join(name))?.to_rgb8();
        let big = image::imageops::resize(&img, img.width() * k, img.height() * k, FilterType::CatmullRom);
        big.save(dst.join(name))?;
    }
    let gt = jem::io::pfm::read_pfm(&src.join("disp0GT.pfm"))?;
    let (w, h) = (gt.width() * k as usize, gt.height() * k as usize);
    let data = (0..w * h).map(|i| gt.at(i % w / k as usize, i / w / k as usize) * k as f32).collect();
    jem::io::pfm::write_pfm(&dst.join("disp0GT.pfm"), &jem::Plane::from_vec(w, h, data).unwrap())?;
    let mask = image::open(src.join("mask0nocc.png"))?.to_luma8();
    image::imageops::resize(&mask, mask.width() * k, mask.height() * k, FilterType::Nearest)
        .save(dst.join("mask0nocc.png"))?;
    std::fs::write(dst.join("calib.txt"), scale_calib(&std::fs::read_to_string(src.join("calib.txt"))?, f64::from(k)))?;
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err("usage: upscale SRC OUT K [SCENE ...]".into());
    }
    let (src, out, k) = (PathBuf::from(&args[0]), PathBuf::from(&args[1]), args[2].parse::<u32>()?);
    if out.exists() {
        return Err(format!("{} exists", out.display()).into());
    }
    for scene in jem::dataset::walk::find_scenes(std::slice::from_ref(&src))? {
        let name = scene.file_name().unwrap().to_string_lossy().into_owned();
        if args.len() > 3 && !args[3..].contains(&name) {
            continue;
        }
        upscale_scene(&scene, &out.join(&name), k)?;
        eprintln!("{name}");
    }
    Ok(())
}
