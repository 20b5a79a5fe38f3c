//! Parsers hammered with generated input: random bytes, truncations and mutations of valid files.
//! Each must return `Ok` or `Err`, never panic, and never allocate more than the input can describe (the PFM
//! reader checks the data length against the header before allocating; a header claiming 4·10⁹ × 4·10⁹ pixels
//! is among the mutations).

use std::path::Path;

use jem::internals::SplitMix64;
use jem::io::calib::Calib;
use jem::io::pfm::{decode_pfm, encode_pfm};
use jem::{Params, Plane};

/// Mutations of `valid`: truncations, bit flips, byte replacements with interesting values, insertions,
/// deletions, and pure random buffers.
fn mutants(valid: &[u8], seed: u64, count: usize) -> Vec<Vec<u8>> {
    let mut rng = SplitMix64::new(seed);
    let interesting: &[&[u8]] =
        &[b"0", b"-1", b"4294967296", b"99999999999", b"nan", b"inf", b"\n", b" ", b"=", b"[", b"\xff\xfe", b"\0"];
    let mut out = Vec::with_capacity(count);
    for k in 0..count {
        let mut m = valid.to_vec();
        match k % 6 {
            0 => m.truncate(rng.below(valid.len() + 1)),
            1 => {
                for _ in 0..1 + rng.below(4) {
                    let i = rng.below(m.len());
                    m[i] ^= 1 << rng.below(8);
                }
            }
            2 => {
                let i = rng.below(m.len());
                let ins = interesting[rng.below(interesting.len())];
                let end = (i + 1 + rng.below(3)).min(m.len());
                m.splice(i..end, ins.iter().copied());
            }
            3 => {
                let i = rng.below(m.len() + 1);
                let ins: Vec<u8> = (0..1 + rng.below(8)).map(|_| rng.next_u64() as u8).collect();
                m.splice(i..i, ins);
            }
            4 => {
                let i = rng.below(m.len());
                let end = (i + 1 + rng.below(16)).min(m.len());
                m.drain(i..end);
            }
            _ => m = (0..rng.below(64)).map(|_| rng.next_u64() as u8).collect(),
        }
        out.push(m);
    }
    out
}

#[test]
fn pfm_parser_survives_mutations() {
    let map =
        Plane::from_vec(4, 3, (0..12).map(|i| if i == 5 { f32::INFINITY } else { i as f32 * 0.5 }).collect()).unwrap();
    let valid = encode_pfm(&map);
    let (mut ok, mut err) = (0, 0);
    for m in mutants(&valid, 1, 6000) {
        match decode_pfm(&m) {
            Ok(p) => {
                ok += 1;
                // Whatever was accepted is self-consistent and fits in the input.
                assert_eq!(p.data().len(), p.width() * p.height());
                assert!(p.data().len() * 4 <= m.len());
            }
            Err(_) => err += 1,
        }
    }
    assert!(ok > 0 && err > 0, "mutations should produce both outcomes: {ok} ok, {err} errors");
    // Headers claiming huge sizes are rejected without allocating them.
    for header in ["Pf\n4000000000 4000000000\n-1\n", "PF\n65536 65536\n-1\n", "Pf\n18446744073709551615 2\n-1\n"] {
        assert!(decode_pfm(header.as_bytes()).is_err());
    }
}

#[test]
fn calib_parser_survives_mutations() {
    let valid = b"cam0=[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]\ncam1=[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]\n\
                  doffs=0\nbaseline=178.089\nwidth=450\nheight=375\nndisp=64\nisint=0\nvmin=13\nvmax=52\n";
    for m in mutants(valid, 2, 6000) {
        let text = String::from_utf8_lossy(&m);
        if let Ok(c) = Calib::parse(&text) {
            if let Ok(n) = c.ndisp() {
                assert!(n > 0);
            }
            let _ = c.float("vmin");
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("calib.txt");
    for m in mutants(valid, 3, 300) {
        std::fs::write(&p, &m).unwrap();
        let _ = jem::io::calib::read_ndisp(&p);
    }
}

#[test]
fn config_parser_survives_mutations() {
    let valid = Params::default().to_toml();
    let mut accepted = 0;
    for m in mutants(valid.as_bytes(), 4, 4000) {
        let text = String::from_utf8_lossy(&m);
        if let Ok(p) = Params::from_toml_str(&text, Path::new("mutant.toml")) {
            accepted += 1;
            p.validate().expect("an accepted config validates");
        }
    }
    assert!(accepted > 0, "some mutations (e.g. whitespace) must still parse");
    // Overrides too.
    let mut rng = SplitMix64::new(5);
    for _ in 0..2000 {
        let key = ["model", "meanfield.iterations", "cost.census_width", "post.sps.segments", "x.y", "", "a..b"]
            [rng.below(7)];
        let value = ["1", "-1", "nan", "inf", "\"s\"", "[1,2]", "{a=1}", "1e400", "", "=", "3.5"][rng.below(11)];
        let _ = Params::load(None, &[format!("{key}={value}")]);
    }
}
