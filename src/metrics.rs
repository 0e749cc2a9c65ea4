//! Error metrics between a rendering and its reference: image error (RMSE, PSNR, SSIM),
//! silhouette disagreement (pixels where one representation hits a surface and the other
//! does not) and geometric error between two surfaces (symmetric Chamfer and Hausdorff
//! distances over points sampled on each surface, measured with the other surface's exact
//! distance query, [`crate::geometry::Geometry::surface_distance`]).
//!
//! Surfaces are sampled where the camera sees them: the first hits of the camera's primary
//! rays ([`probe`]). This is representation-agnostic (every geometry answers rays), covers
//! unbounded surfaces out to where the camera looks, and weights error by what is visible.

use glam::DVec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::geometry::{Geometry, RayStats};
use crate::scene::Camera;
use crate::scene::camera::RayGenerator;

/// Mean squared error of two equally sized RGB images on a [0, 1] scale, over all
/// channels.
///
/// # Panics
/// When the sizes differ.
pub fn mse(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions(), "images of different sizes");
    let n = a.as_raw().len().max(1) as f64;
    let sum: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| {
            let d = (x as f64 - y as f64) / 255.0;
            d * d
        })
        .sum();
    sum / n
}

/// Root mean squared error on a [0, 1] scale.
pub fn rmse(a: &RgbImage, b: &RgbImage) -> f64 {
    mse(a, b).sqrt()
}

/// Peak signal-to-noise ratio in dB for a peak of 1 (`+inf` for identical images).
pub fn psnr_db(a: &RgbImage, b: &RgbImage) -> f64 {
    let m = mse(a, b);
    if m == 0.0 { f64::INFINITY } else { -10.0 * m.log10() }
}

/// Luma (Rec. 601 weights) on a [0, 1] scale, row-major.
fn luma(img: &RgbImage) -> Vec<f64> {
    img.pixels().map(|p| (0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64) / 255.0).collect()
}

/// Structural similarity (Wang et al. 2004) of the images' luma: an 11x11 Gaussian window
/// of sigma 1.5 (truncated at the image border and renormalised), `C1 = (0.01)^2`,
/// `C2 = (0.03)^2` for a dynamic range of 1, averaged over all pixels. 1 for identical
/// images.
///
/// # Panics
/// When the sizes differ.
pub fn ssim(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions(), "images of different sizes");
    let (w, h) = (a.width() as usize, a.height() as usize);
    if w == 0 || h == 0 {
        return 1.0;
    }
    let (x, y) = (luma(a), luma(b));
    const R: isize = 5;
    let kernel: Vec<f64> = (-R..=R).map(|i| (-(i * i) as f64 / (2.0 * 1.5 * 1.5)).exp()).collect();
    // Separable weighted sums of x, y, x^2, y^2, xy: horizontal pass then vertical.
    let fields: [Vec<f64>; 5] = [
        x.clone(),
        y.clone(),
        x.iter().map(|v| v * v).collect(),
        y.iter().map(|v| v * v).collect(),
        x.iter().zip(&y).map(|(a, b)| a * b).collect(),
    ];
    let blur = |f: &[f64]| -> Vec<f64> {
        let mut tmp = vec![0.0; w * h];
        for r in 0..h {
            for c in 0..w {
                let (mut s, mut ws) = (0.0, 0.0);
                for (k, wk) in kernel.iter().enumerate() {
                    let cc = c as isize + k as isize - R;
                    if cc >= 0 && (cc as usize) < w {
                        s += wk * f[r * w + cc as usize];
                        ws += wk;
                    }
                }
                tmp[r * w + c] = s / ws;
            }
        }
        let mut out = vec![0.0; w * h];
        for r in 0..h {
            for c in 0..w {
                let (mut s, mut ws) = (0.0, 0.0);
                for (k, wk) in kernel.iter().enumerate() {
                    let rr = r as isize + k as isize - R;
                    if rr >= 0 && (rr as usize) < h {
                        s += wk * tmp[rr as usize * w + c];
                        ws += wk;
                    }
                }
                out[r * w + c] = s / ws;
            }
        }
        out
    };
    let [mx, my, mxx, myy, mxy] = fields.map(|f| blur(&f));
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let total: f64 = (0..w * h)
        .map(|i| {
            let (ux, uy) = (mx[i], my[i]);
            let vx = (mxx[i] - ux * ux).max(0.0);
            let vy = (myy[i] - uy * uy).max(0.0);
            let cxy = mxy[i] - ux * uy;
            ((2.0 * ux * uy + c1) * (2.0 * cxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2))
        })
        .sum();
    total / (w * h) as f64
}

/// What the camera's primary rays see of a geometry: per pixel whether a surface is hit,
/// and the hit points.
pub struct Probe {
    /// Per pixel (row-major), whether the primary ray hits a surface.
    pub hits: Vec<bool>,
    /// Hit points of the primary rays that hit, world space.
    pub points: Vec<DVec3>,
}

/// Casts one primary ray per pixel of `camera` into `geometry` (closest hits up to
/// `max_distance`).
pub fn probe(camera: &Camera, geometry: &dyn Geometry, max_distance: f32) -> Probe {
    let rays = RayGenerator::new(camera);
    let (w, h) = (camera.width, camera.height);
    let rows: Vec<(Vec<bool>, Vec<DVec3>)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut stats = RayStats::default();
            let mut hits = Vec::with_capacity(w as usize);
            let mut points = Vec::new();
            for x in 0..w {
                let hit = geometry.closest_hit(&rays.ray(x, y), 0.0, max_distance, &mut stats);
                hits.push(hit.is_some());
                if let Some(hit) = hit {
                    points.push(hit.point.as_dvec3());
                }
            }
            (hits, points)
        })
        .collect();
    let mut probe = Probe { hits: Vec::with_capacity((w * h) as usize), points: Vec::new() };
    for (hits, points) in rows {
        probe.hits.extend(hits);
        probe.points.extend(points);
    }
    probe
}

/// Percentage of pixels where exactly one of the two probes hits a surface.
///
/// # Panics
/// When the probes have different pixel counts.
pub fn hit_mismatch_pct(a: &Probe, b: &Probe) -> f64 {
    assert_eq!(a.hits.len(), b.hits.len(), "probes of different cameras");
    let n = a.hits.len().max(1) as f64;
    100.0 * a.hits.iter().zip(&b.hits).filter(|(x, y)| x != y).count() as f64 / n
}

/// Symmetric distances between two surfaces, in scene units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceDistance {
    /// Mean of the two one-sided mean distances.
    pub chamfer: f64,
    /// Largest distance from a sample of either surface to the other surface.
    pub hausdorff: f64,
    /// Bounding-box diagonal of the reference samples (the scale for relative errors).
    pub diagonal: f64,
}

impl SurfaceDistance {
    /// Chamfer distance relative to the reference's diagonal.
    pub fn chamfer_rel(&self) -> f64 {
        self.chamfer / self.diagonal.max(f64::MIN_POSITIVE)
    }

    /// Hausdorff distance relative to the reference's diagonal.
    pub fn hausdorff_rel(&self) -> f64 {
        self.hausdorff / self.diagonal.max(f64::MIN_POSITIVE)
    }
}

/// Every `k`-th point so that at most `max` remain (a deterministic subsample).
pub fn subsample(points: &[DVec3], max: usize) -> Vec<DVec3> {
    let k = points.len().div_ceil(max.max(1)).max(1);
    points.iter().step_by(k).copied().collect()
}

/// The Chamfer and Hausdorff distances between the surfaces of `candidate` and `reference`
/// from points sampled on each (`candidate_points` on the candidate, `reference_points` on
/// the reference), each measured with the other's exact distance query. `None` when
/// either sample set is empty (then the surfaces cannot be compared where the camera
/// looks).
pub fn surface_distance(
    candidate: &dyn Geometry,
    candidate_points: &[DVec3],
    reference: &dyn Geometry,
    reference_points: &[DVec3],
) -> Option<SurfaceDistance> {
    if candidate_points.is_empty() || reference_points.is_empty() {
        return None;
    }
    let one_sided = |points: &[DVec3], other: &dyn Geometry| -> (f64, f64) {
        let d: Vec<f64> = points.par_iter().map(|&p| other.surface_distance(p)).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        (mean, d.iter().copied().fold(0.0, f64::max))
    };
    let (mean_a, max_a) = one_sided(candidate_points, reference);
    let (mean_b, max_b) = one_sided(reference_points, candidate);
    let (lo, hi) = reference_points
        .iter()
        .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(l, h), &p| {
            (l.min(p), h.max(p))
        });
    Some(SurfaceDistance {
        chamfer: 0.5 * (mean_a + mean_b),
        hausdorff: max_a.max(max_b),
        diagonal: (hi - lo).length(),
    })
}

/// A camera of `width` x `height` pixels with `camera`'s pose (for probes at a resolution
/// other than the image's).
pub fn resized(camera: &Camera, width: u32, height: u32) -> Camera {
    Camera { width, height, ..*camera }
}

/// Per-pixel absolute difference scaled by `gain` (a heat map input for reports).
pub fn abs_difference(a: &RgbImage, b: &RgbImage, gain: f32) -> RgbImage {
    RgbImage::from_fn(a.width(), a.height(), |x, y| {
        let (p, q) = (a.get_pixel(x, y), b.get_pixel(x, y));
        let d = |i: usize| ((p[i] as f32 - q[i] as f32).abs() * gain).min(255.0) as u8;
        image::Rgb([d(0), d(1), d(2)])
    })
}

/// Mean of a slice (0 for an empty one).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 }
}

/// Median of a slice (NaN for an empty one).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(w: u32, h: u32, v: u8) -> RgbImage {
        RgbImage::from_pixel(w, h, image::Rgb([v, v, v]))
    }

    #[test]
    fn rmse_and_psnr_match_hand_computed_values() {
        // Every channel differs by 51/255 = 0.2: MSE 0.04, RMSE 0.2, PSNR 10 log10(25).
        let (a, b) = (constant(4, 3, 0), constant(4, 3, 51));
        assert!((rmse(&a, &b) - 0.2).abs() < 1e-12);
        assert!((psnr_db(&a, &b) - 10.0 * 25f64.log10()).abs() < 1e-9);
        assert_eq!(psnr_db(&a, &a), f64::INFINITY);
        // One pixel of four off by 1.0 in one channel: MSE = 1 / 12.
        let mut c = constant(2, 2, 0);
        c.put_pixel(1, 1, image::Rgb([255, 0, 0]));
        assert!((mse(&constant(2, 2, 0), &c) - 1.0 / 12.0).abs() < 1e-12);
    }

    #[test]
    fn ssim_of_constant_images_is_the_luminance_term() {
        // Constant images have no variance: SSIM = (2ab + C1) / (a^2 + b^2 + C1).
        let (a, b) = (constant(16, 16, 51), constant(16, 16, 153));
        let (x, y, c1) = (0.2, 0.6, 1e-4);
        let want = (2.0 * x * y + c1) / (x * x + y * y + c1);
        assert!((ssim(&a, &b) - want).abs() < 1e-9, "{} vs {want}", ssim(&a, &b));
        assert!((ssim(&a, &a) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ssim_falls_with_noise_and_is_symmetric() {
        let a = RgbImage::from_fn(32, 32, |x, y| {
            let v = ((x * 7 + y * 3) % 255) as u8;
            image::Rgb([v, v, v])
        });
        let mut b = a.clone();
        for (i, p) in b.pixels_mut().enumerate() {
            if i % 3 == 0 {
                p.0 = [255 - p[0]; 3];
            }
        }
        let s = ssim(&a, &b);
        assert!(s < 0.9 && s > -1.0, "{s}");
        assert!((s - ssim(&b, &a)).abs() < 1e-12);
    }

    #[test]
    fn median_and_subsample() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        let pts: Vec<DVec3> = (0..10).map(|i| DVec3::splat(i as f64)).collect();
        assert_eq!(subsample(&pts, 5).len(), 5);
        assert_eq!(subsample(&pts, 100).len(), 10);
    }
}
