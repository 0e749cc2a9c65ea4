//! Helpers shared by every module of the integration test binary, each defined once:
//! running the `toolkit` binary, per-test temporary folders and files, scenes built in
//! code, a tessellated sphere, mesh checks (manifoldness, enclosed volume), image
//! comparison, the exact box SDF and a small deterministic random generator.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::{DVec3, Vec3, Vec3A};
use image::RgbImage;
use sdfmesh::geometry::Aabb;
use sdfmesh::mesh::TriangleMesh;
use sdfmesh::scene::shape::{Object, ObjectKind, Primitive};
use sdfmesh::scene::transform::TransformDesc;
use sdfmesh::scene::{Camera, Light, Material, Scene, Settings};

// ---------------------------------------------------------------- processes and files

/// Runs the `toolkit` binary built with this crate on `args`, capturing its output.
pub fn toolkit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_toolkit")).args(args).output().expect("run toolkit")
}

/// A fresh, empty folder `sdfmesh-MODULE-NAME-PID` in the system temporary folder, where
/// MODULE is the calling test module's file stem: tests of different modules run in one
/// process and may reuse a `name`.
#[track_caller]
pub fn temp_dir(name: &str) -> PathBuf {
    let caller = std::panic::Location::caller().file();
    let module = Path::new(caller).file_stem().and_then(|s| s.to_str()).unwrap_or("test").replace('_', "-");
    let d = std::env::temp_dir().join(format!("sdfmesh-{module}-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `bytes` to `dir/name` and returns the path.
pub fn put(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write test file");
    p
}

// ---------------------------------------------------------------- meshes

/// A sphere of radius `r` around `c` tessellated at `6 << levels` segments, with normals.
pub fn icosphere(levels: u32, c: Vec3, r: f32) -> TriangleMesh {
    let sphere = Primitive::Sphere { radius: r };
    let mut m = sdfmesh::convert::tessellate::tessellate(&sphere, 6 << levels, None);
    if c != Vec3::ZERO {
        m.transform(&glam::Affine3A::from_translation(c));
    }
    assert!(m.normals.is_some());
    m
}

// ---------------------------------------------------------------- scenes

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
        settings: Settings {
            max_depth: 2,
            background: Vec3::new(0.1, 0.1, 0.15),
            max_distance: 1e5,
            ..Settings::default()
        },
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

// ---------------------------------------------------------------- mesh checks

/// The axis-aligned cube of half-side `r` around the origin.
pub fn cube(r: f32) -> Aabb {
    Aabb::new(Vec3A::splat(-r), Vec3A::splat(r))
}

/// Undirected edges not used by exactly two triangles, once in each direction.
pub fn non_manifold_edges(m: &TriangleMesh) -> usize {
    let mut uses: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let e = uses.entry((a.min(b), a.max(b))).or_default();
            if a < b {
                e.0 += 1;
            } else {
                e.1 += 1;
            }
        }
    }
    uses.values().filter(|&&u| u != (1, 1)).count()
}

/// Signed enclosed volume (positive for an outward-oriented closed mesh).
pub fn signed_volume(m: &TriangleMesh) -> f64 {
    m.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize].as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

// ---------------------------------------------------------------- random numbers

/// A tiny deterministic generator (64-bit linear congruential, Knuth's MMIX constants):
/// the same seed gives the same sequence on every machine.
pub struct Lcg(pub u64);

impl Lcg {
    /// Advances and returns the high 31 bits of the state.
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        self.0 >> 33
    }

    /// Uniform in `[0, 1)`, in steps of `2^-24`.
    pub fn unit(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A uniformly distributed unit vector (rejection sampling in the unit ball).
    pub fn dir(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.unit(), self.unit(), self.unit()) * 2.0 - 1.0;
            if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

/// Signed distance from `p` to the box of half-sides `h` around the origin (exact).
pub fn box_sdf(p: DVec3, h: DVec3) -> f64 {
    let q = p.abs() - h;
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
}

fn rust_files(dir: &std::path::Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Every file of `src/`, as its path relative to `src/` and its text, sorted (the source
/// rules and the layering check read them).
pub fn crate_sources() -> Vec<(String, String)> {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    assert!(files.len() > 20, "found only {} files under src/", files.len());
    files
        .into_iter()
        .map(|p| {
            let rel = p.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
            (rel, std::fs::read_to_string(&p).unwrap())
        })
        .collect()
}
