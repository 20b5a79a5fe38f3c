// temporary: print cost curves at given pixels
use jem::{Params, cost, io};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let dir = std::path::Path::new(&a[1]);
    let (l, r) = io::png::load_rgb_pair(&dir.join("im0.png"), &dir.join("im1.png")).unwrap();
    let nd = io::calib::read_ndisp(&dir.join("calib.txt")).unwrap();
    let p = Params::default();
    let v = cost::build_cost_volume(&l, &r, nd, &p.cost);
    let gt = io::pfm::read_pfm(&dir.join("disp0GT.pfm")).unwrap();
    for xy in a[2..].chunks(2) {
        let (x, y): (usize, usize) = (xy[0].parse().unwrap(), xy[1].parse().unwrap());
        let c = v.pixel(y * v.width + x);
        let g = gt.at(x, y);
        let s: Vec<String> = c.iter().map(|v| format!("{:.0}", v)).collect();
        println!("({x},{y}) gt {g:.1} argmin {}: {}", cost::argmin(c), s.join(" "));
    }
}
