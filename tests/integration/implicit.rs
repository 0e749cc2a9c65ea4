//! `.vm` implicit models: the 2D image against a brute-force f64 evaluation of every pixel
//! on the models of `../shared/implicit` (skipped with a message where that folder is
//! missing), and `toolkit render MODEL.vm` end to end, bad files included.

use std::path::{Path, PathBuf};
use std::process::Command;

use sdfmesh::implicit::image2d::{render_2d, render_2d_reference};
use sdfmesh::implicit::load_vm;

fn shared(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/implicit").join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("skipped: {} is missing", p.display());
        None
    }
}

fn differing(name: &str, w: usize, h: usize) -> Option<(usize, usize)> {
    let path = shared(name)?;
    let ssa = load_vm(&path).unwrap();
    let (fast, census) = render_2d(&ssa, w, h);
    assert_eq!(census.filled + census.evaluated, (w * h) as u64);
    let slow = render_2d_reference(&ssa, w, h);
    let d = fast.inside.iter().zip(&slow.inside).filter(|(a, b)| a != b).count();
    let inside = slow.inside.iter().filter(|&&v| v == 1).count();
    Some((d, inside))
}

#[test]
fn two_d_images_agree_with_brute_force_f64() {
    for (name, w, h) in [("hi.vm", 512, 512), ("quarter.vm", 512, 384), ("prospero.vm", 256, 256)] {
        let Some((d, inside)) = differing(name, w, h) else { continue };
        // Not a blank image, and at most 0.01% of pixels differ.
        assert!(inside > 100 && inside < w * h - 100, "{name}: {inside} inside");
        assert!(d * 10_000 <= w * h, "{name}: {d} of {} pixels differ", w * h);
    }
}

#[test]
fn render_writes_the_prospero_image_and_refuses_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_toolkit");
    let model = dir.path().join("disc.vm");
    std::fs::write(&model, "x var-x\ny var-y\na square x\nb square y\nc add a b\nr const 0.25\no sub c r\n")
        .unwrap();
    let png = dir.path().join("d.png");
    let out = Command::new(exe)
        .args([
            "render",
            model.to_str().unwrap(),
            "--width",
            "40",
            "--height",
            "20",
            "-o",
            png.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (40, 20));
    assert_eq!(img.get_pixel(20, 10).0, [255; 3]);
    assert_eq!(img.get_pixel(0, 0).0, [0; 3]);

    let bad = dir.path().join("bad.vm");
    std::fs::write(&bad, "x var-x\ny frob x\n").unwrap();
    let png2 = dir.path().join("bad.png");
    let out = Command::new(exe)
        .args(["render", bad.to_str().unwrap(), "-o", png2.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.vm:2:3: unknown opcode `frob`"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!png2.exists());
}
