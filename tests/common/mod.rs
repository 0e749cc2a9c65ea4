//! Shared helpers for integration tests: scenes built in code and image comparison.
#![allow(dead_code)]

use glam::Vec3;
use image::RgbImage;
use sdfmesh::scene::shape::{Object, ObjectKind, Primitive};
use sdfmesh::scene::transform::TransformDesc;
use sdfmesh::scene::{Camera, Light, Material, Scene, Settings};

/// A primitive object with a transform and material 1 (material 0 is the grey default).
pub fn object(prim: Primitive, translate: Vec3, rotate_deg: Vec3, scale: Vec3) -> Object {
    Object {
        kind: ObjectKind::Primitive(prim),
        transform: TransformDesc { translate, rotate_deg, scale },
        material: 1,
        label: prim.kind_name().into(),
    }
}

/// A lit scene around `objects`: camera at (0, 1.5, -6) looking at the origin, ambient,
/// a point light and a directional light, two materials (grey default, shiny red).
pub fn lit_scene(objects: Vec<Object>, size: u32) -> Scene {
    Scene {
        camera: Camera {
            position: Vec3::new(0.0, 1.5, -6.0),
            forward: (-Vec3::new(0.0, 1.5, -6.0)).normalize(),
            up: Vec3::Y,
            fov_y_deg: 40.0,
            width: size,
            height: size,
        },
        settings: Settings { max_depth: 2, background: Vec3::new(0.1, 0.1, 0.15), max_distance: 1e5 },
        lights: vec![
            Light::Ambient { intensity: 0.2 },
            Light::Point { position: Vec3::new(3.0, 4.0, -4.0), intensity: 0.6, color: Vec3::ONE },
            Light::Directional {
                direction: Vec3::new(-1.0, -4.0, 2.0).normalize(),
                intensity: 0.3,
                color: Vec3::new(1.0, 0.9, 0.8),
            },
        ],
        materials: vec![
            Material::default(),
            Material {
                name: "red".into(),
                color: Vec3::new(0.9, 0.2, 0.15),
                ks: 0.6,
                shininess: Some(50.0),
                ..Material::default()
            },
        ],
        objects,
    }
}

/// Fraction of pixels whose every channel differs by at most `tol` (0..255).
pub fn fraction_within(a: &RgbImage, b: &RgbImage, tol: u8) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let ok = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| p.0.iter().zip(q.0.iter()).all(|(x, y)| x.abs_diff(*y) <= tol))
        .count();
    ok as f64 / (a.width() * a.height()) as f64
}

/// Pixels that differ from the background colour.
pub fn covered(img: &RgbImage, background: [u8; 3]) -> usize {
    img.pixels().filter(|p| p.0 != background).count()
}

/// With `SDFMESH_DUMP=DIR` set, saves the images side by side plus a difference image
/// (white where any channel differs by more than 2) as `DIR/NAME.png`, for debugging.
pub fn dump(name: &str, images: &[&RgbImage]) {
    let Ok(dir) = std::env::var("SDFMESH_DUMP") else {
        return;
    };
    let (w, h) = images[0].dimensions();
    let mut out = RgbImage::new(w * (images.len() as u32 + 1), h);
    for (i, img) in images.iter().enumerate() {
        for (x, y, p) in img.enumerate_pixels() {
            out.put_pixel(x + i as u32 * w, y, *p);
        }
    }
    for (x, y, p) in images[0].enumerate_pixels() {
        let q = images[images.len() - 1].get_pixel(x, y);
        let bad = p.0.iter().zip(q.0.iter()).any(|(a, b)| a.abs_diff(*b) > 2);
        let v = if bad { 255 } else { 0 };
        out.put_pixel(x + images.len() as u32 * w, y, image::Rgb([v, v, v]));
    }
    std::fs::create_dir_all(&dir).unwrap();
    out.save(std::path::Path::new(&dir).join(format!("{name}.png"))).unwrap();
}
